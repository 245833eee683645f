"""Curves of failure events in two parameters, by pseudo-arclength (issue 15's actuation windows).

A failure event of a branch (EB, RU, LT, LE: :mod:`snapmem.model.local_checks`) is where an
output m(x, lam; v), the minimum over the edges of a per-edge check
(:func:`~snapmem.model.local_checks.edge_values`), reaches its level c. With a second parameter v
(e.g. the pressure while the branch is traced in voltage) the solutions of

    R(x, lam; v) = 0,   m(x, lam; v) = c

form a curve in (x, lam, v), the boundary of the actuation window that event draws. It is traced
like :func:`snapmem.continuation.codim2.singular_curve` traces limit points: pseudo-arclength,
the Jacobian K bordered by the columns [R_lam, R_v] and the rows [m_x; t_x] and solved by
block elimination (stays regular where K is singular, at the EMI). m is the check of one edge
(the smallest) near a point, so m_x has at most four nonzeros, taken by central differences
on that edge's coordinates: each iteration stays O(N). Where the smallest edge changes, m has a
kink; Newton lands on the new piece.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass, field
from typing import Callable

import numpy as np
import pandas as pd

from snapmem.continuation.branch import PointKind
from snapmem.continuation.codim2 import singular_curve
from snapmem.continuation.problems import ProblemsByValue
from snapmem.continuation.tracer import trace
from snapmem.errors import SnapmemError, SolverError
from snapmem.kernels.banded import BorderedMatrix
from snapmem.model.local_checks import EDGE_MEASURES, edge_values
from snapmem.model.scene import Scene

log = logging.getLogger(__name__)


@dataclass
class EventCurve:
    """A traced curve of failure events: ``table`` (one row per point: v, lam, s, stable, iterations
    and the problem's measures), ``status`` (why it stopped), ``newton_iterations``."""

    table: pd.DataFrame
    status: str
    newton_iterations: int
    points: list = field(repr=False, default_factory=list)


class _EventSystem:
    """[R; m - c] in (x, lam, v) with its bordered Jacobian."""

    def __init__(self, scene_at, control, measure, level, v0, v_scale):
        self.scene_at, self.control, self.measure, self.level = scene_at, control, measure, level
        self.problem = ProblemsByValue(scene_at, control)
        pb = self.problem(v0)
        self.tol = 1e-10 * pb.scene.force_scale
        self.wx, self.wl, self.wv = pb.x_weight, 1.0 / pb.lam_scale ** 2, 1.0 / v_scale ** 2
        self.v_scale = v_scale
        self.iterations = 0

    def values(self, pb, x, lam) -> np.ndarray:
        q, loads = pb.state(x, lam)
        return edge_values(pb.scene, q, loads, self.measure)

    def linearise(self, x, lam, v):
        """(F, blocks): the residual [R; m - c] and (K, [R_lam, R_v], m_x, m_lam, m_v)."""
        pb = self.problem(v)
        R, K = pb.evaluate(x, lam)
        values = self.values(pb, x, lam)
        edge = int(np.argmin(values))
        m = float(values[edge])
        m_x = np.zeros(x.size)
        free_of = np.full(pb.scene.reference_state().size, -1)
        free_of[pb.scene.free] = np.arange(pb.scene.n_free)
        h = 1e-7 * pb.scene.meridian.size
        for dof in pb.scene.edge_dofs[edge]:
            i = free_of[dof]
            if i < 0:
                continue
            e = np.zeros(x.size)
            e[i] = h
            m_x[i] = (self.values(pb, x + e, lam)[edge] - self.values(pb, x - e, lam)[edge]) / (2 * h)
        dl = 1e-7 * max(abs(lam), pb.lam_scale)
        m_l = (self.values(pb, x, lam + dl)[edge] - self.values(pb, x, lam - dl)[edge]) / (2 * dl)
        dv = 1e-7 * max(abs(v), self.v_scale)
        plus, minus = self.problem(v + dv), self.problem(v - dv)
        R_v = (plus.evaluate(x, lam, order=1)[0] - minus.evaluate(x, lam, order=1)[0]) / (2 * dv)
        m_v = (self.values(plus, x, lam)[edge] - self.values(minus, x, lam)[edge]) / (2 * dv)
        return np.append(R, m - self.level), (K, np.column_stack([pb.dF_dlam(x, lam), R_v]), m_x, m_l, m_v)

    def solve(self, blocks, row, rhs):
        K, B, m_x, m_l, m_v = blocks
        C = np.column_stack([m_x, self.wx * row[:-2]])
        D = [[m_l, m_v], [self.wl * row[-2], self.wv * row[-1]]]
        lu = BorderedMatrix(K, B, C, D).factor()
        if lu.singular:
            raise SolverError("singular extended Jacobian of the event curve")
        return lu.solve(rhs)

    def inner(self, a, b):
        return float(a[:-2] @ (self.wx * b[:-2]) + self.wl * a[-2] * b[-2] + self.wv * a[-1] * b[-1])

    def tangent(self, blocks, previous):
        rhs = np.zeros(blocks[0].n + 2)
        rhs[-1] = 1.0
        t = self.solve(blocks, previous, rhs)
        t /= math.sqrt(self.inner(t, t))
        return t if self.inner(t, previous) > 0 else -t

    def correct(self, y0, t, ds, max_iterations=8):
        """Newton on [R; m - c; <t, y - y0> - ds] from y0 + ds t: (y, blocks, iterations)."""
        y = y0 + ds * t
        for it in range(max_iterations):
            x, lam, v = y[:-2], y[-2], y[-1]
            pb = self.problem(v)
            if pb.inadmissible(x, lam) is not None:
                raise SolverError("left the model's domain")
            F, blocks = self.linearise(x, lam, v)
            arc = self.inner(t, y - y0) - ds
            if np.max(np.abs(F[:-1])) <= self.tol and abs(F[-1]) <= 1e-10 * max(abs(self.level), 1.0) \
                    and abs(arc) <= 1e-12 and it > 0:
                return y, blocks, it
            y = y + self.solve(blocks, t, -np.append(F, arc))
            self.iterations += 1
            if not np.all(np.isfinite(y)):
                raise SolverError("corrector diverged")
        raise SolverError(f"corrector did not converge in {max_iterations} iterations")


def event_curve(scene_at: Callable[[float], Scene], v0: float, x0: np.ndarray, lam0: float, measure: str,
                control: str = "voltage", v_range: tuple | None = None, lam_range: tuple | None = None,
                direction: int = 1, ds: float = 0.02, ds_max: float = 0.1, max_steps: int = 200,
                v_scale: float | None = None, stretch_max: float | None = None) -> EventCurve:
    """Trace the curve of the failure event ``measure`` through (x0, lam0) at v0 in (x, lam, v).

    Parameters
    ----------
    scene_at : callable
        v -> Scene (the same degrees of freedom for every v).
    v0, x0, lam0 : a point of the event, e.g. one located on a traced branch (kind EB, RU, LT, LE).
    measure : str
        The output whose level the curve keeps: 'breakdown_margin' (EB) or 'rupture_margin' (RU)
        at 1, 'min_tension' (LT) or 'ellipticity' (LE) at 0.
    control : str
        The branch's control parameter ('pressure', 'voltage', 'E_hat').
    v_range, lam_range : (min, max), optional
        The curve stops where v or the control leaves them.
    direction : int
        +1 to start with v increasing, -1 decreasing.
    ds, ds_max : float
        First and largest step (scaled arclength: x by the problem's weights, lam by its scale,
        v by ``v_scale``, default |v0| or 1).
    stretch_max : float, optional
        The curve stops past this largest principal stretch (from the mounted state).

    Returns
    -------
    EventCurve
    """
    if measure not in EDGE_MEASURES:
        raise SnapmemError(f"measure = {measure!r}: must be one of {', '.join(EDGE_MEASURES)}")
    if control == "volume":
        raise SnapmemError("control = 'volume': follow failure events in a load control")
    v_scale = v_scale or (abs(v0) if v0 != 0 else 1.0)
    system = _EventSystem(scene_at, control, measure, EDGE_MEASURES[measure], v0, v_scale)
    y = np.concatenate([x0, [lam0, v0]])
    start = np.zeros(y.size)
    start[-1] = direction
    y, blocks, _ = system.correct(y, start, 0.0)          # polish the start onto the curve (ds = 0)
    t = system.tangent(blocks, start)
    points, s = [(y, 0.0, 0)], 0.0
    status = f"max_steps ({max_steps}) reached"
    for _ in range(max_steps):
        try:
            y_new, blocks, iterations = system.correct(y, t, ds)
        except SolverError as exc:
            if ds <= 1e-6:
                status = f"step too small after: {exc}"
                break
            ds *= 0.5
            continue
        t = system.tangent(blocks, t)
        y, s = y_new, s + ds
        points.append((y, s, iterations))
        pb = system.problem(y[-1])
        if v_range is not None and not min(v_range) <= y[-1] <= max(v_range):
            status = "left the range of v"
            break
        if lam_range is not None and not min(lam_range) <= y[-2] <= max(lam_range):
            status = "left the range of the control"
            break
        if stretch_max is not None and pb.measures(y[:-2], y[-2])["stretch_max"] > stretch_max:
            status = f"stretch passed {stretch_max:g}"
            break
        ds = min(ds_max, ds * (1.5 if iterations <= 3 else 0.7))
    rows = []
    for y, s, iterations in points:
        pb = system.problem(y[-1])
        negative = getattr(pb.evaluate(y[:-2], y[-2])[1].factor(), "negative", None)
        rows.append({"v": y[-1], "lam": y[-2], "s": s, "iterations": iterations,
                     "stable": None if negative is None else bool(negative == 0), **pb.measures(y[:-2], y[-2])})
    return EventCurve(pd.DataFrame(rows), status, system.iterations, points)


#: the event kinds whose curves bound a window, with the output each keeps at its level
EVENT_MEASURES = {PointKind.EB: "breakdown_margin", PointKind.RU: "rupture_margin", PointKind.LT: "min_tension",
                  PointKind.LE: "ellipticity"}


def failure_window(scene_at: Callable[[float], Scene], v0: float, v_range: tuple, control: str = "voltage",
                   until: dict | None = None, stretch_max: float | None = None, ds_max: float = 0.1,
                   max_steps: int = 200, kinds: tuple | None = None,
                   lam_range: tuple | None = None) -> tuple[pd.DataFrame, pd.DataFrame]:
    """The boundaries of an actuation window: the first event of each kind on the branch traced
    in ``control`` at v0, continued in v both ways over ``v_range``.

    ``kinds``: the event words to continue (e.g. ('EB', 'RU'); default all: EMI or LP, EB, RU,
    LT, LE); ``lam_range``: the curves stop where the control leaves it. A curve of limit points is the same in the (pressure, voltage) plane whichever of
    the two is the control, so seeds traced in voltage and in pressure draw one window.

    Limit points (named EMI under voltage control) are followed by
    :func:`snapmem.continuation.codim2.singular_curve`, the events EB, RU, LT and LE by
    :func:`event_curve`.

    Returns
    -------
    (curves, first) : (pandas.DataFrame, pandas.DataFrame)
        ``curves``: rows of every boundary (``curve`` its event's name, ``direction``, ``v``,
        ``lam``, ``stable`` and the measures) after the seed branch itself (``curve`` = 'branch').
        ``first``: the seed branch's events in the order met (``kind``, ``control``, measures):
        its first row is the failure that bounds this design first.
    """
    branch = trace(scene_at(v0), control, until=until)
    name_lp = "EMI" if control == "voltage" else "LP"
    tables = [branch.table.assign(curve="branch", v=v0, direction=0, lam=branch.table["control"])]
    v_scale = (max(v_range) - min(v_range)) or 1.0
    seen = set()
    for point in branch.states:
        word = name_lp if point.kind == PointKind.LP else point.kind.value
        if (not point.located or point.kind not in (PointKind.LP, *EVENT_MEASURES) or word in seen
                or (kinds is not None and word not in kinds)):
            continue
        seen.add(word)
        for direction in (1, -1):
            try:
                if point.kind == PointKind.LP:
                    if point.vectors is None:
                        continue
                    phi = point.vectors[:, int(np.argmin(np.abs(point.eigs)))]
                    curve = singular_curve(scene_at, v0, point.x, point.lam, phi, control, v_range=v_range,
                                           direction=direction, v_scale=v_scale, ds_max=ds_max, max_steps=max_steps,
                                           lam_range=lam_range)
                    name = name_lp
                else:
                    curve = event_curve(scene_at, v0, point.x, point.lam, EVENT_MEASURES[point.kind], control,
                                        v_range=v_range, lam_range=lam_range, direction=direction, v_scale=v_scale,
                                        ds_max=ds_max, max_steps=max_steps, stretch_max=stretch_max)
                    name = point.kind.value
            except SolverError as exc:
                log.warning("%s curve from %s = %g: %s", point.kind.value, control, point.lam, exc)
                continue
            t = curve.table.assign(curve=name, direction=direction, status=curve.status)
            tables.append(t if direction == 1 else t.iloc[::-1])
    events = branch.points.sort_values("s")
    first = events[events["kind"].isin([name_lp, *(k.value for k in EVENT_MEASURES)])].reset_index(drop=True)
    return pd.concat(tables, ignore_index=True), first
