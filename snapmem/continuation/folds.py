"""Two-parameter continuation of a limit point: the fold curve of a control against a second parameter."""

from __future__ import annotations

from dataclasses import asdict
from typing import Callable

import logging

import numpy as np
import snapmem._lazy as _lazy

pd = _lazy.module("pandas")  # imported at first use (start-up)

from snapmem.continuation.branch import PointKind
from snapmem.continuation.locate import fold_newton
from snapmem.continuation.options import ContinuationOptions, FoldOptions
from snapmem.continuation.problems import make_problem
from snapmem.continuation.tracer import trace
from snapmem.errors import SnapmemError, SolverError, check_real
from snapmem.model.scene import Scene
from snapmem.threads import single_threaded

#: the branch measures of a fold curve's rows (NaN where no limit point exists)
MEASURES = ("pressure", "voltage", "E_hat", "volume", "u_max", "stretch_max", "min_tension")


@single_threaded
def fold_curve(scene_at: Callable[[float], Scene], values, control: str = "pressure",
               options: FoldOptions = FoldOptions(), trace_options: ContinuationOptions = ContinuationOptions(),
               progress: Callable[[int, int], None] | None = None, start: tuple | None = None,
               return_folds: bool = False):
    """The curve of limit points of ``control`` as a second parameter runs through ``values``.

    The first limit point is found by tracing a branch; every next one by Newton on the
    minimally extended system [R(x, lam) = 0, g(x, lam) = 0] from the previous one, where g is
    the bordered test function ([[K, phi], [phi^T, 0]] [v; g] = [0; 1], zero exactly where K is
    singular) and dg/dx = -D3Pi[v, v, .] comes from a central difference of K(x + e v) v. So a
    limit-point map costs a few Newton steps per value, not a traced branch per value.

    Parameters
    ----------
    scene_at : callable
        value -> Scene (the same meridian node count for every value).
    values : sequence of float
        Values of the second parameter, in order.
    control : str
        The continuation parameter whose limit is followed ('pressure', 'voltage', 'E_hat').
    start : (value, x, lam, phi), optional
        A limit point already known at ``value`` of ``scene_at`` (from another fold curve's
        folds): the curve continues from it instead of tracing a first branch.
    return_folds : bool
        Also return the limit points found, {value: (value, x, lam, phi)}, to start other curves.

    Returns
    -------
    pandas.DataFrame
        One row per value: ``value``, ``limit`` (the control at the limit point), ``exists``,
        ``method`` ('fold' or 'trace'), ``iterations``, ``status``, and the branch measures at the
        limit point (pressure, voltage, E_hat, volume, u_max, stretch_max, min_tension, ...).
        With ``return_folds``: (table, folds).
    """
    if control == "volume":
        raise SnapmemError("control = 'volume': volume control has no limit points to follow")
    values = [check_real("value", v) for v in values]
    if not values:
        raise SnapmemError("values: need at least one value of the second parameter")
    rows, previous = [], ([start] if start is not None else [])   # previous: [(value, x, lam, phi)]
    references: dict = {}
    folds: dict = {}
    for i, value in enumerate(values):
        row = None
        if previous:
            row = _continue_fold(scene_at, previous, value, control, options, references)
        if row is None:
            row = _fold_by_trace(scene_at(value), control, options, trace_options)
        row["value"] = value
        rows.append(row)
        if row.pop("_fold", None) is not None and row["exists"]:
            previous.append((value, row.pop("_x"), row["limit"], row.pop("_phi")))
            folds[value] = previous[-1]
        else:
            row.pop("_x", None), row.pop("_phi", None)
        if progress is not None:
            progress(i + 1, len(values))
    table = pd.DataFrame(rows)
    for column in MEASURES:                     # where no value has a limit point, no row has them
        if column not in table:
            table[column] = np.nan
    table = table[["value", "limit", "exists", "method", "iterations", "status"]
                  + [c for c in table.columns if c not in ("value", "limit", "exists", "method", "iterations", "status")]]
    return (table, folds) if return_folds else table


def _fold_by_trace(scene, control, options, trace_options):
    opts = ContinuationOptions(**{**asdict(trace_options), "stop_at_first_limit": True, "save_at": ()})
    try:
        br = trace(scene, control, until=dict(options.trace_until), options=opts)
    except (SolverError, SnapmemError) as exc:
        return {"limit": float("nan"), "exists": False, "method": "trace", "iterations": 0,
                "status": f"trace failed: {exc}"}
    lps = br.limit_points()
    iterations = br.stats["newton_iterations"]
    if lps.empty:
        return {"limit": float("nan"), "exists": False, "method": "trace", "iterations": iterations,
                "status": f"no limit point ({br.status})"}
    pb = make_problem(scene, control)
    lp = next(p for p in br.states if p.kind == PointKind.LP)
    _, K = pb.evaluate(lp.x, lp.lam)
    phi = null_vector(K)
    return {"limit": lp.lam, "exists": True, "method": "trace", "iterations": iterations,
            "status": "located", **pb.measures(lp.x, lp.lam), "_fold": True, "_x": lp.x, "_phi": phi}


def null_vector(K):
    """A unit null vector of the (nearly) singular K: three inverse iterations from a fixed random start."""
    lu = K.factor()
    phi = np.random.default_rng(1).normal(size=K.n)
    if not lu.singular:
        for _ in range(3):
            phi = lu.solve(phi)
            phi /= np.linalg.norm(phi)
    return phi / np.linalg.norm(phi)


def _continue_fold(scene_at, previous, value, control, options, references, depth=0):
    v0, x0, lam0, phi = previous[-1]
    scene = scene_at(value)
    pb = make_problem(scene, control)
    ref_new = scene.reference_state()[scene.free]
    references[value] = ref_new
    if v0 not in references:
        old = scene_at(v0)
        references[v0] = old.reference_state()[old.free]
    ref_old = references[v0]
    x, lam = x0 - ref_old + ref_new, lam0
    if len(previous) >= 2:                        # secant predictor along the fold curve
        v1, x1, lam1, _ = previous[-2]
        f = (value - v0) / (v0 - v1)
        x, lam = x + f * (x0 - x1), lam + f * (lam0 - lam1)
    result = fold_newton(pb, scene, x, lam, phi, options)
    if result is None:
        if depth >= options.max_refinements:
            return None
        mid = 0.5 * (v0 + value)
        row = _continue_fold(scene_at, previous, mid, control, options, references, depth + 1)
        if row is None or not row.get("exists"):
            return None
        extended = previous + [(mid, row["_x"], row["limit"], row["_phi"])]
        return _continue_fold(scene_at, extended, value, control, options, references, depth + 1)
    x, lam, phi_new, iterations = result
    return {"limit": lam, "exists": True, "method": "fold", "iterations": iterations, "status": "located",
            **pb.measures(x, lam), "_fold": True, "_x": x, "_phi": phi_new}


@single_threaded
def fold_special_points(scene_at: Callable[[float], Scene], values, folds: dict, control: str = "pressure",
                        max_steps: int = 200) -> tuple[pd.DataFrame, int]:
    """The codimension-2 points on the fold curve within the range of ``values``: cusps (kind
    ``CP``) and turning points of the curve in the second parameter (``TP``).

    From the first limit point :func:`fold_curve` found (``folds``, as its ``return_folds``
    gives them) the curve of limit points is traced by pseudo-arclength in (x, lam, value) both
    ways (:func:`snapmem.continuation.codim2.singular_curve`), so it passes the turning points
    where fixed-value stepping ends.

    Returns
    -------
    (pandas.DataFrame, int)
        One row per special point: ``kind``, ``value``, ``limit`` (the control there), ``a``
        (the normal-form coefficient phi . D3Pi[phi, phi, phi], zero at a cusp) and the measures;
        and the Newton iterations it took.
    """
    from snapmem.continuation.codim2 import singular_curve
    columns = ["kind", "value", "limit", "a"] + list(MEASURES)
    if not folds:
        return pd.DataFrame(columns=columns), 0
    low, high = min(values), max(values)
    v0, x0, lam0, phi0 = next(iter(folds.values()))          # the first one found
    found, iterations = [], 0
    for direction in (1, -1):
        try:
            curve = singular_curve(scene_at, v0, x0, lam0, phi0, control, v_range=(low, high),
                                   direction=direction, max_steps=max_steps, v_scale=(high - low) or abs(v0) or 1.0)
        except (SolverError, SnapmemError) as exc:
            logging.getLogger(__name__).warning("fold curve from %g: %s", v0, exc)
            continue
        iterations += curve.newton_iterations
        found.append(curve.special)
    table = pd.concat([f for f in found if not f.empty], ignore_index=True) if any(not f.empty for f in found) \
        else pd.DataFrame(columns=["kind", "v", "lam", "a"] + list(MEASURES))
    table = table[(table["v"] >= low) & (table["v"] <= high)] if len(table) else table
    table = table.drop_duplicates(subset=["kind", "v"]).rename(columns={"v": "value", "lam": "limit"})
    return table[[c for c in columns if c in table.columns]].reset_index(drop=True), iterations
