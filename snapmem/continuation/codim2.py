"""Curves of singular points in two parameters, by pseudo-arclength, and their codimension-2 points.

A limit point (LP) or a bifurcation point (BP) of R(x, lam; v) = 0 is a solution of the minimally
extended system [R = 0, g = 0] (g the bordered test function of snapmem.continuation.locate,
zero exactly where K is singular). With the second parameter v an unknown too, its solutions
form a curve in (x, lam, v), traced here by pseudo-arclength like a branch: the Jacobian

    [[K,     R_lam, R_v],
     [g_x^T, g_lam, g_v],
     [t_x^T, t_lam, t_v]]

is K bordered by two columns and two rows, solved by block elimination with banded solves, so
each step stays O(N). R_v and g_v are central differences of the scene rebuilt at v +- h (any
numeric scene parameter). Following the curve through turning points of v is what fixed-v
stepping (:func:`snapmem.continuation.folds.fold_curve`) cannot do; on the way two kinds of
special points are located:

- ``CP``, a cusp: the fold's normal-form coefficient a = phi . D3Pi[phi, phi, phi] changes sign,
  where two limit points (a pressure maximum and minimum) merge and the snap disappears;
- ``TP``, a turning point of the curve in v (the tangent's v component changes sign) that is not
  a cusp.

The curve of a BP whose mode breaks no symmetry of the energy to third order (a transcritical
one, e.g. the inflated sphere's P2 mode) is a regular solution of the same system, so BP curves
are traced by the same function from a located BP.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass, field, replace
from typing import Callable

import numpy as np
import pandas as pd
from scipy.optimize import brentq

from snapmem.continuation.problems import make_problem
from snapmem.errors import SnapmemError, SolverError
from snapmem.kernels.banded import BorderedMatrix
from snapmem.model.scene import Scene

log = logging.getLogger(__name__)

#: smallest |phi_new . phi_old| of the unit null vectors at the two ends of an accepted step:
#: below it the corrector has landed on another curve (two singular curves passing close)
MODE_OVERLAP = 0.9


@dataclass
class SingularPoint:
    """A point of a curve of singular points: unknowns x, control lam, second parameter v, the
    null vector phi, the unit tangent (x, lam, v parts), the normal-form coefficient a."""

    x: np.ndarray
    lam: float
    v: float
    phi: np.ndarray
    tangent: np.ndarray | None = None
    a: float = float("nan")
    s: float = 0.0
    iterations: int = 0
    kind: str = ""


@dataclass
class SingularCurve:
    """A traced curve of singular points: ``table`` (one row per point: v, lam, a, s, kind,
    and the measures), ``special`` (the located CP and TP rows), ``status`` and Newton counts."""

    table: pd.DataFrame
    special: pd.DataFrame
    status: str
    newton_iterations: int
    points: list = field(repr=False, default_factory=list)


class _System:
    """The extended system of one curve: evaluation, derivatives and the corrector."""

    def __init__(self, scene_at: Callable[[float], Scene], control: str, v0: float, v_scale: float):
        self.scene_at, self.control = scene_at, control
        self._problems: dict = {}
        pb = self.problem(v0)
        self.tol = 1e-10 * pb.scene.force_scale
        self.L = pb.scene.meridian.size
        self.wx, self.wl, self.wv = pb.x_weight, 1.0 / pb.lam_scale ** 2, 1.0 / v_scale ** 2
        self.lam_scale, self.v_scale = pb.lam_scale, v_scale
        self.iterations = 0

    def problem(self, v):
        """The problem at v (the last few cached: each Newton iteration asks for v and v +- h)."""
        if v not in self._problems:
            if len(self._problems) > 16:
                self._problems.clear()
            self._problems[v] = make_problem(self.scene_at(v), self.control)
        return self._problems[v]

    def g_of(self, pb, x, lam, phi):
        """(g, v, K, R): the bordered test function and its vector at (x, lam) of problem pb."""
        F, K = pb.evaluate(x, lam)
        lu = BorderedMatrix(K, phi, phi, [[0.0]]).factor()
        if lu.singular:
            raise SolverError("singular bordered matrix of the test function")
        rhs = np.zeros(K.n + 1)
        rhs[-1] = 1.0
        sol = lu.solve(rhs)
        return sol[-1], sol[:-1], K, F

    def linearise(self, x, lam, v, phi):
        """(F, J, w, K): the residual [R; g], the Jacobian's blocks, the test function's vector."""
        pb = self.problem(v)
        g, w, K, R = self.g_of(pb, x, lam, phi)
        eps = 1e-6 * self.L / max(np.max(np.abs(w)), 1e-300)
        g_x = -(pb.evaluate(x + eps * w, lam)[1].matvec(w) - pb.evaluate(x - eps * w, lam)[1].matvec(w)) / (2 * eps)
        dl = 1e-6 * max(abs(lam), pb.lam_scale)
        g_l = -(pb.evaluate(x, lam + dl)[1].matvec(w) - pb.evaluate(x, lam - dl)[1].matvec(w)) @ w / (2 * dl)
        h = 1e-6 * max(abs(v), self.v_scale)
        plus, minus = self.problem(v + h), self.problem(v - h)
        R_v = (plus.evaluate(x, lam, order=1)[0] - minus.evaluate(x, lam, order=1)[0]) / (2 * h)
        g_v = (self.g_of(plus, x, lam, phi)[0] - self.g_of(minus, x, lam, phi)[0]) / (2 * h)
        return np.append(R, g), (K, np.column_stack([pb.dF_dlam(x, lam), R_v]), g_x, g_l, g_v), w

    def solve(self, blocks, row, rhs):
        K, B, g_x, g_l, g_v = blocks
        C = np.column_stack([g_x, self.wx * row[:-2]])
        D = [[g_l, g_v], [self.wl * row[-2], self.wv * row[-1]]]
        lu = BorderedMatrix(K, B, C, D).factor()
        if lu.singular:
            raise SolverError("singular extended Jacobian of the singular-point curve")
        return lu.solve(rhs)

    def inner(self, a, b):
        return float(a[:-2] @ (self.wx * b[:-2]) + self.wl * a[-2] * b[-2] + self.wv * a[-1] * b[-1])

    def tangent(self, blocks, previous):
        rhs = np.zeros(blocks[0].n + 2)
        rhs[-1] = 1.0
        t = self.solve(blocks, previous, rhs)
        t /= math.sqrt(self.inner(t, t))
        return t if self.inner(t, previous) > 0 else -t

    def correct(self, base: SingularPoint, ds: float, max_iterations: int = 10) -> SingularPoint:
        """Newton on [R; g; <t, y - y0> - ds] from base + ds t."""
        t = base.tangent
        y0 = np.concatenate([base.x, [base.lam, base.v]])
        y = y0 + ds * t
        phi = base.phi
        for it in range(max_iterations):
            x, lam, v = y[:-2], y[-2], y[-1]
            pb = self.problem(v)
            if pb.inadmissible(x, lam) is not None:
                raise SolverError("left the model's domain")
            F, blocks, w = self.linearise(x, lam, v, phi)
            arc = self.inner(t, y - y0) - ds
            if np.max(np.abs(F[:-1])) <= self.tol and abs(arc) <= 1e-12 and it > 0:
                phi = w / np.linalg.norm(w)
                if abs(phi @ base.phi) < MODE_OVERLAP:
                    raise SolverError(f"the null vector turned (overlap {abs(phi @ base.phi):.2f}): "
                                      "another singular curve")
                point = SingularPoint(x, lam, v, phi, iterations=it)
                point.tangent = self.tangent(blocks, t)
                point.a = -float(blocks[2] @ phi) / np.linalg.norm(w) ** 2
                return point
            d = self.solve(blocks, t, -np.append(F, arc))
            self.iterations += 1
            y = y + d
            phi = w / np.linalg.norm(w)
            if not np.all(np.isfinite(y)):
                raise SolverError("corrector diverged")
        raise SolverError(f"corrector did not converge in {max_iterations} iterations")


def singular_curve(scene_at: Callable[[float], Scene], v0: float, x0: np.ndarray, lam0: float, phi0: np.ndarray,
                   control: str = "pressure", v_range: tuple | None = None, direction: int = 1,
                   ds: float = 0.05, ds_max: float = 0.1, max_steps: int = 400, v_scale: float | None = None,
                   lam_range: tuple | None = None,
                   stop_when: Callable[[Scene, np.ndarray], str | None] | None = None,
                   cusps: bool = True) -> SingularCurve:
    """Trace the curve of singular points (LPs or BPs) through (x0, lam0) at v0 in (x, lam, v).

    Parameters
    ----------
    scene_at : callable
        v -> Scene (the same degrees of freedom for every v).
    v0, x0, lam0, phi0 : a singular point and its (approximate) null vector, e.g. a located LP
        or BP of a traced branch.
    control : str
        The branch's control parameter ('pressure', 'voltage', 'E_hat').
    v_range : (v_min, v_max), optional
        The curve stops where v leaves it.
    direction : int
        +1 to start with v increasing, -1 decreasing.
    ds, ds_max : float
        First and largest step (scaled arclength).
    max_steps : int
    v_scale : float, optional
        Scale of v in the arclength (default |v0|, or 1).
    lam_range : (lam_min, lam_max), optional
        The curve stops where the control leaves it.
    stop_when : callable, optional
        (scene, q) -> None to go on, or why the curve stops at state q [m] of ``scene`` (e.g.
        where the membrane loses ellipticity); the point is kept.
    cusps : bool
        Look for cusps (a curve of limit points); False for a curve of bifurcation points, whose
        coefficient a need not mean a cusp (it vanishes by symmetry for a pitchfork).

    Returns
    -------
    SingularCurve
    """
    if control == "volume":
        raise SnapmemError("control = 'volume': follow limit points in a load control")
    v_scale = v_scale or (abs(v0) if v0 != 0 else 1.0)
    system = _System(scene_at, control, v0, v_scale)
    F, blocks, w = system.linearise(x0, lam0, v0, phi0 / np.linalg.norm(phi0))
    first = SingularPoint(x0, lam0, v0, w / np.linalg.norm(w))
    row = np.zeros(x0.size + 2)
    row[-1] = direction
    first.tangent = system.tangent(blocks, row)
    first.a = -float(blocks[2] @ first.phi) / np.linalg.norm(w) ** 2
    if np.max(np.abs(F[:-1])) > 1e3 * system.tol:
        raise SolverError(f"start is not an equilibrium (max |R| = {np.max(np.abs(F[:-1])):.3e})")
    points, special = [first], []
    status = f"max_steps ({max_steps}) reached"
    for _ in range(max_steps):
        base = points[-1]
        try:
            p = system.correct(base, ds, max_iterations=6)     # more: the step may land on a nearby curve
        except SolverError as exc:
            if ds <= 1e-6:
                status = f"step too small after: {exc}"
                break
            ds *= 0.5
            continue
        p.s = base.s + ds
        special.extend(_specials(system, base, p, cusps))
        points.append(p)
        if v_range is not None and not min(v_range) <= p.v <= max(v_range):
            status = "left the range of v"
            break
        if lam_range is not None and not min(lam_range) <= p.lam <= max(lam_range):
            status = "left the range of the control"
            break
        why = None if stop_when is None else stop_when(system.problem(p.v).scene,
                                                       system.problem(p.v).state(p.x, p.lam)[0])
        if why is not None:
            status = why
            break
        ds = min(ds_max, ds * (1.5 if p.iterations <= 3 else 0.7))
    return _assemble(system, points, special, status)


def _specials(system: _System, base: SingularPoint, p: SingularPoint, cusps: bool) -> list:
    """The cusps and turning points in v located between two points of the curve."""
    found = []
    cusp = cusps and base.a * p.a < 0
    turn = base.tangent[-1] * p.tangent[-1] < 0
    if cusp:
        found.append(_locate(system, base, p, lambda q: q.a, "CP"))
    if turn and not cusp:
        found.append(_locate(system, base, p, lambda q: q.tangent[-1], "TP"))
    return [q for q in found if q is not None]


def _locate(system, base, p, f, kind):
    cache = {0.0: base, p.s - base.s: p}

    def value(s):
        if s not in cache:
            cache[s] = system.correct(base, s)
        return f(cache[s])

    try:
        s = brentq(value, 0.0, p.s - base.s, xtol=1e-12 * (p.s - base.s), maxiter=50)
    except (SolverError, ValueError, RuntimeError) as exc:
        log.warning("could not locate %s point: %s", kind, exc)
        return None
    q = cache.get(s) or system.correct(base, s)
    return replace(q, s=base.s + s, kind=kind)          # a copy: q may be one of the curve's points


def _distinct(special: list) -> list:
    """The special points without repeats (one turning point can be bracketed on consecutive
    steps where the curve runs nearly parallel to the v = const planes)."""
    kept = []
    for q in sorted(special, key=lambda q: q.s):
        if not any(k.kind == q.kind and abs(k.v - q.v) <= 1e-4 * max(abs(q.v), 1.0)
                   and abs(k.lam - q.lam) <= 1e-3 * max(abs(q.lam), 1e-300) for k in kept):
            kept.append(q)
    return kept


def _assemble(system, points, special, status) -> SingularCurve:
    special = _distinct(special)
    def row(q):
        pb = system.problem(q.v)
        return {"v": q.v, "lam": q.lam, "a": q.a, "s": q.s, "kind": q.kind, "iterations": q.iterations,
                **pb.measures(q.x, q.lam)}

    table = pd.DataFrame([row(q) for q in sorted(points + special, key=lambda q: q.s)])
    special_table = pd.DataFrame([row(q) for q in special],
                                 columns=None if special else list(table.columns))
    return SingularCurve(table, special_table, status, system.iterations, points)
