"""Sensitivities of critical points to scene parameters, from the null vector: no re-tracing.

At a limit point (x*, lam*) of R(x, lam; theta) = 0, K phi = 0, and the fold persists as theta
moves: differentiating R = 0 and projecting on phi (phi . K = 0) gives

    d lam* / d theta = - (phi . dR/dtheta) / (phi . dR/dlam)

with the partial derivatives at fixed x (MODEL.md section 7). dR/dtheta is a central difference
of the residual of the scene rebuilt at theta +- h (its builder, so any numeric scene parameter
works: a law constant, E_hat, the thickness, ...), at the same unknowns x.
"""

from __future__ import annotations

from typing import Callable, Sequence

import numpy as np
import pandas as pd

from snapmem.continuation.branch import Branch, PointKind
from snapmem.continuation.folds import null_vector
from snapmem.continuation.problems import make_problem
from snapmem.errors import SnapmemError
from snapmem.model.scene import Scene

#: relative step of the central difference in theta (absolute where theta = 0)
RELATIVE_STEP = 1e-6


def critical_sensitivity(scene_with: Callable[[float], Scene], theta: float, control: str, x: np.ndarray,
                         lam: float, phi: np.ndarray | None = None) -> float:
    """d(control at the limit point)/d(theta) at the limit point (x, lam) of ``scene_with(theta)``.

    Parameters
    ----------
    scene_with : callable
        theta -> Scene, the same degrees of freedom for every theta.
    theta : float
        The parameter's value at the limit point (in its own unit).
    control : str
        The continuation parameter ('pressure', 'voltage' or 'E_hat').
    x, lam : the limit point's unknowns and control value.
    phi : ndarray, optional
        The null vector of K there (computed by inverse iteration if not given).

    Returns
    -------
    float
        [control unit / theta unit].
    """
    if control == "volume":
        raise SnapmemError("sensitivity under volume control: the volume has no limit points; trace in a load")
    scene = scene_with(theta)
    pb = make_problem(scene, control)
    if phi is None:
        phi = null_vector(pb.evaluate(x, lam)[1])
    h = RELATIVE_STEP * (abs(theta) if theta != 0 else 1.0)
    plus, minus = (make_problem(scene_with(theta + s), control) for s in (h, -h))
    if plus.n != pb.n or minus.n != pb.n:
        raise SnapmemError("sensitivity: the parameter changes the scene's degrees of freedom (e.g. nodes); "
                           "only parameters that keep the mesh can be differentiated")
    R_theta = (plus.evaluate(x, lam, order=1)[0] - minus.evaluate(x, lam, order=1)[0]) / (2 * h)
    return float(-(phi @ R_theta) / (phi @ pb.dF_dlam(x, lam)))


def branch_sensitivities(branch: Branch, scene_with: Callable[[str, float], Scene], names: Sequence[str]) -> pd.DataFrame:
    """The branch's points table with a column ``d<control>_d<name>`` per parameter name.

    Filled at the limit points (kind LP); NaN at other points (a bifurcation point's null
    vector is orthogonal to dR/dlam, so this formula does not apply there).

    Parameters
    ----------
    branch : Branch
    scene_with : callable
        (name, value) -> the branch's scene with parameter ``name`` set to ``value``.
    names : sequence of str
        Numeric scene parameters (``branch.scene.parameters``).
    """
    table = branch.points.copy()
    control = branch.control
    for name in names:
        value = branch.scene.parameters.get(name)
        if name not in branch.scene.parameters:
            raise SnapmemError(f"sensitivity {name!r}: scene {branch.scene.name!r} has no such parameter; "
                               f"it has {', '.join(sorted(branch.scene.parameters))}")
        if isinstance(value, bool) or not isinstance(value, float):            # counts (nodes), names, unset
            raise SnapmemError(f"sensitivity {name!r} = {value!r}: not a real-valued parameter")
        column = []
        for _, row in table.iterrows():
            point = _state_of(branch, row)
            if row["kind"] != PointKind.LP.value or point is None:
                column.append(float("nan"))
                continue
            phi = None
            if point.vectors is not None and point.eigs is not None:
                phi = point.vectors[:, int(np.argmin(np.abs(point.eigs)))]
            column.append(critical_sensitivity(lambda v: scene_with(name, v), float(value), control,
                                               point.x, point.lam, phi))
        table[f"d{control}_d{name}"] = column
    return table


def _state_of(branch: Branch, row):
    """The located point of a points-table row (matched by arclength and kind)."""
    for p in branch.states:
        if PointKind(p.kind).value == row["kind"] and p.s == row["s"]:
            return p
    return None
