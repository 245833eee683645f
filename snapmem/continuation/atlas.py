"""A stability atlas in two parameters: the curves of limit and bifurcation points, their
codimension-2 points and where the membrane model stops being valid, all by continuation.

Each curve starts from a critical point located on a traced branch (a *seed*) and is followed
in the second parameter by pseudo-arclength (:func:`snapmem.continuation.codim2.singular_curve`),
both ways, until it leaves the parameter range, passes a stretch bound or loses ellipticity.
A seed that is an unfolded BP (the mesh breaks its symmetry) is followed on the unfolding system
(its rows carry ``sigma`` and ``imperfection``), so its curve converges at second order.
Loss-of-ellipticity points are the ends of branches traced at given values (each located by the
trace's LE event).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Sequence

import numpy as np
import pandas as pd

from snapmem.continuation.branch import Outcome, PointKind
from snapmem.continuation.codim2 import singular_curve
from snapmem.continuation.problems import make_problem
from snapmem.continuation.tracer import trace
from snapmem.errors import SnapmemError
from snapmem.model.local_checks import local_state
from snapmem.model.scene import Scene


@dataclass(frozen=True)
class Seed:
    """Where a curve of the atlas starts: the critical point of the branch traced at ``value``
    whose output ``near[0]`` is nearest ``near[1]`` (whatever kind the branch gave it), named
    ``name``; ``kind`` 'LP' (a curve of limit points: cusps are looked for) or 'BP'."""

    name: str
    value: float
    near: tuple
    kind: str = "LP"


def stability_atlas(scene_at: Callable[[float], Scene], seeds: Sequence[Seed], v_range: tuple,
                    control: str = "pressure", until: dict | None = None, stretch_max: float = 5.0,
                    le_values: Sequence[float] = (), ds_max: float = 0.05) -> tuple[pd.DataFrame, dict]:
    """The atlas's curves as one table.

    Parameters
    ----------
    scene_at : callable
        v -> Scene, v the second parameter (e.g. E_hat).
    seeds : sequence of Seed
    v_range : (v_min, v_max)
    control : str
        The branch parameter ('pressure', 'voltage', 'E_hat').
    until : mapping, optional
        Where the seed branches stop (default stretch_max = 3.2).
    stretch_max : float
        The curves stop past this largest principal stretch.
    le_values : sequence of float
        Values of v at which a branch is traced to its loss of ellipticity.
    ds_max : float
        Largest step along a curve (scaled arclength; v is scaled by the width of ``v_range``):
        small enough not to jump between singular curves that pass close.

    Returns
    -------
    (pandas.DataFrame, dict)
        Rows: ``curve`` (a seed's name, or 'LE'), ``v``, ``lam`` (the control), ``kind`` ('' on
        the curve, CP, TP, LE), ``a`` and the measures; and the work: Newton iterations, curves.
    """
    until = dict(until or {"stretch_max": 3.2})
    branches: dict = {}
    tables, iterations = [], 0

    def invalid(scene, q):
        state = local_state(scene, q, with_tension=False)
        if state is not None and not state.elliptic:
            return "loss of ellipticity"
        if scene.measures(q)["stretch_max"] > stretch_max:
            return f"stretch beyond {stretch_max:g}"
        return None

    for seed in seeds:
        if seed.value not in branches:
            branches[seed.value] = trace(scene_at(seed.value), control, until=until)
            iterations += branches[seed.value].stats["newton_iterations"]
        branch = branches[seed.value]
        pb = make_problem(branch.scene, control)
        critical = [p for p in branch.states if p.kind in (PointKind.LP, PointKind.BP) and p.vectors is not None]
        if not critical:
            raise SnapmemError(f"seed {seed.name!r}: no critical point on the branch at {seed.value:g}")
        output, target = seed.near
        start = min(critical, key=lambda p: abs(pb.output(p, output) - target))
        phi = start.vectors[:, int(np.argmin(np.abs(start.eigs)))]
        for direction in (1, -1):
            curve = singular_curve(scene_at, seed.value, start.x, start.lam, phi, control, v_range=v_range,
                                   direction=direction, v_scale=(max(v_range) - min(v_range)) or 1.0,
                                   stop_when=invalid, cusps=seed.kind == "LP", ds_max=ds_max)
            iterations += curve.newton_iterations
            t = curve.table.assign(curve=seed.name, direction=direction, status=curve.status)
            tables.append(t if direction == 1 else t.iloc[::-1])
    for value in le_values:
        branch = trace(scene_at(value), control, until={"stretch_max": 2 * stretch_max})
        iterations += branch.stats["newton_iterations"]
        if branch.outcome is Outcome.ELLIPTICITY_LOST:
            row = branch.points.iloc[[-1]].rename(columns={"control": "lam"})
            tables.append(row.assign(curve="LE", v=value, status=branch.status))
    table = pd.concat(tables, ignore_index=True)
    first = ["curve", "v", "lam", "kind"]
    return table[first + [c for c in table.columns if c not in first]], {"newton_iterations": iterations,
                                                                         "curves": len(seeds)}
