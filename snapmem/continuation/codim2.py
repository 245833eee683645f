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

A BP the mesh makes imperfect (its mode couples to the load at discretisation order) is
reported at the perfect problem's BP (snapmem.continuation.unfold), a state with the residual
R = -sigma psi. From such a start the curve is that of the unfolding system in (x, lam, sigma, v):

    R(x, lam; v) + sigma psi = 0,   g = 0,   h = w . R_lam / |R_lam|_0 = 0,

psi = -R / |R| fixed at the start, w the bordered null vector; the Jacobian is K bordered by the
columns R_lam, psi, R_v and the rows g_x, h_x (h_x = (D_w R_lam) - (D_w K) z with
[[K, phi], [phi^T, 0]] [z; .] = [R_lam; 0], central differences along w) and the arclength's, so
each step stays O(N), and the curve converges at the discretisation order, as the unfolded BP
does, not at half of it as the mesh's singular points near it (discrete folds) do.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass, field, replace
from typing import Callable

import numpy as np
import pandas as pd
from scipy.optimize import brentq

from snapmem.continuation.problems import ProblemsByValue, make_problem
from snapmem.continuation.unfold import IMPERFECTION_LIMIT
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
    null vector phi, the unit tangent (x, lam, (sigma,) v parts), the normal-form coefficient a;
    on the curve of an unfolded BP, sigma [N] is the size of the imperfection force sigma psi
    that makes its bifurcation perfect (R(x, lam; v) = -sigma psi)."""

    x: np.ndarray
    lam: float
    v: float
    phi: np.ndarray
    tangent: np.ndarray | None = None
    a: float = float("nan")
    s: float = 0.0
    iterations: int = 0
    kind: str = ""
    sigma: float | None = None

    def unknowns(self) -> np.ndarray:
        """y = (x, lam, v), or (x, lam, sigma, v) on the curve of an unfolded BP."""
        extra = [self.lam, self.v] if self.sigma is None else [self.lam, self.sigma, self.v]
        return np.concatenate([self.x, extra])


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
    """The extended system of one curve: evaluation, derivatives and the corrector.

    The unknowns are y = (x, lam, v), or y = (x, lam, sigma, v) for an unfolded BP (``psi``
    given: the mesh's imperfect BP moved to the perfect problem's, snapmem.continuation.unfold),
    whose equations are R + sigma psi = 0, g = 0 and h = w . R_lam / |R_lam|_0 = 0 (w the
    bordered null vector). Either way the Jacobian is K bordered by a few columns and rows."""

    def __init__(self, scene_at: Callable[[float], Scene], control: str, v0: float, v_scale: float,
                 psi: np.ndarray | None = None, x0: np.ndarray | None = None, lam0: float = 0.0):
        self.scene_at, self.control = scene_at, control
        self.problem = ProblemsByValue(scene_at, control)
        pb = self.problem(v0)
        self.tol = 1e-10 * pb.scene.force_scale
        self.L = pb.scene.meridian.size
        self.wx, self.wl, self.wv = pb.x_weight, 1.0 / pb.lam_scale ** 2, 1.0 / v_scale ** 2
        self.lam_scale, self.v_scale = pb.lam_scale, v_scale
        self.psi = psi
        if psi is None:
            self.w_extra = np.array([self.wl, self.wv])
        else:                                     # one fixed scale of h and of sigma: the load's force at the start
            load = pb.dF_dlam(x0, lam0)
            self.load_scale = float(np.linalg.norm(load)) or 1.0
            sigma_scale = float(np.linalg.norm(lam0 * load)) or 1.0
            self.w_extra = np.array([self.wl, 1.0 / sigma_scale ** 2, self.wv])
        self.iterations = 0

    @property
    def extra(self) -> int:
        """Unknowns beside x: (lam, v), or (lam, sigma, v) for an unfolded BP."""
        return self.w_extra.size

    def g_of(self, pb, x, lam, phi):
        """(g, w, K, R, lu): the bordered test function and its vector at (x, lam) of problem pb,
        and the factorisation of the bordered matrix [[K, phi], [phi^T, 0]]."""
        F, K = pb.evaluate(x, lam)
        lu = BorderedMatrix(K, phi, phi, [[0.0]]).factor()
        if lu.singular:
            raise SolverError("singular bordered matrix of the test function")
        rhs = np.zeros(K.n + 1)
        rhs[-1] = 1.0
        sol = lu.solve(rhs)
        return sol[-1], sol[:-1], K, F, lu

    def h_of(self, pb, x, lam, w):
        """The unfolded BP condition h = w . R_lam / |R_lam|_0 (zero where the null vector does
        not couple to the load: a bifurcation, not a fold)."""
        return float(w @ pb.dF_dlam(x, lam)) / self.load_scale

    def linearise(self, y, phi):
        """(F, blocks, w): the residual [R (+ sigma psi); g (; h)], the Jacobian's blocks
        (K, B, C, D: columns B of the extra unknowns, rows C^T | D of the extra equations) and
        the test function's vector w, at y with the border phi."""
        n = y.size - self.extra
        x, lam, v = y[:n], y[n], y[-1]
        pb = self.problem(v)
        g, w, K, R, lu = self.g_of(pb, x, lam, phi)
        eps = 1e-6 * self.L / max(np.max(np.abs(w)), 1e-300)
        K_plus, K_minus = pb.evaluate(x + eps * w, lam)[1], pb.evaluate(x - eps * w, lam)[1]
        g_x = -(K_plus.matvec(w) - K_minus.matvec(w)) / (2 * eps)
        dl = 1e-6 * max(abs(lam), pb.lam_scale)
        Kl_plus, Kl_minus = pb.evaluate(x, lam + dl)[1], pb.evaluate(x, lam - dl)[1]
        g_l = -(Kl_plus.matvec(w) - Kl_minus.matvec(w)) @ w / (2 * dl)
        h = 1e-6 * max(abs(v), self.v_scale)
        plus, minus = self.problem(v + h), self.problem(v - h)
        R_v = (plus.evaluate(x, lam, order=1)[0] - minus.evaluate(x, lam, order=1)[0]) / (2 * h)
        at_plus, at_minus = self.g_of(plus, x, lam, phi), self.g_of(minus, x, lam, phi)
        g_v = (at_plus[0] - at_minus[0]) / (2 * h)
        R_lam = pb.dF_dlam(x, lam)
        if self.psi is None:
            return (np.append(R, g), (K, np.column_stack([R_lam, R_v]), g_x[:, None], np.array([[g_l, g_v]])), w)
        # h = w . R_lam: d(w . R_lam) = w . dR_lam - z . (dK w), z = [[K, phi], [phi^T, 0]]^-1 [R_lam; 0]
        z = lu.solve(np.append(R_lam, 0.0))[:-1]
        h_x = ((pb.dF_dlam(x + eps * w, lam) - pb.dF_dlam(x - eps * w, lam))
               - (K_plus.matvec(z) - K_minus.matvec(z))) / (2 * eps * self.load_scale)
        h_l = (w @ (pb.dF_dlam(x, lam + dl) - pb.dF_dlam(x, lam - dl))
               - z @ (Kl_plus.matvec(w) - Kl_minus.matvec(w))) / (2 * dl * self.load_scale)
        h_v = (self.h_of(plus, x, lam, at_plus[1]) - self.h_of(minus, x, lam, at_minus[1])) / (2 * h)
        sigma = y[n + 1]
        F = np.concatenate([R + sigma * self.psi, [g, self.h_of(pb, x, lam, w)]])
        return F, (K, np.column_stack([R_lam, self.psi, R_v]), np.column_stack([g_x, h_x]),
                   np.array([[g_l, 0.0, g_v], [h_l, 0.0, h_v]])), w

    def solve(self, blocks, row, rhs):
        """The extended Jacobian (the arclength row ``row`` appended) solved for rhs: O(N)."""
        K, B, C, D = blocks
        m = self.extra
        C = np.column_stack([C, self.wx * row[:-m]])
        D = np.vstack([D, self.w_extra * row[-m:]])
        lu = BorderedMatrix(K, B, C, D).factor()
        if lu.singular:
            raise SolverError("singular extended Jacobian of the singular-point curve")
        return lu.solve(rhs)

    def inner(self, a, b):
        m = self.extra
        return float(a[:-m] @ (self.wx * b[:-m]) + np.sum(self.w_extra * a[-m:] * b[-m:]))

    def tangent(self, blocks, previous):
        rhs = np.zeros(blocks[0].n + self.extra)
        rhs[-1] = 1.0
        t = self.solve(blocks, previous, rhs)
        t /= math.sqrt(self.inner(t, t))
        return t if self.inner(t, previous) > 0 else -t

    def converged(self, F, n) -> bool:
        """R (+ sigma psi) within tol, and for an unfolded BP h too (g needs no test of its own:
        the Newton step that brought R there was quadratic in it)."""
        return np.max(np.abs(F[:n])) <= self.tol and (self.psi is None or abs(F[-1]) <= 1e-9)

    def point(self, y, phi, w, blocks, iterations=0) -> SingularPoint:
        """The SingularPoint at y (its null vector w / |w|, normal-form coefficient a)."""
        n = y.size - self.extra
        p = SingularPoint(y[:n], y[n], y[-1], phi, iterations=iterations,
                          sigma=float(y[n + 1]) if self.psi is not None else None)
        p.a = -float(blocks[2][:, 0] @ phi) / np.linalg.norm(w) ** 2
        return p

    def correct(self, base: SingularPoint, ds: float, max_iterations: int = 10) -> SingularPoint:
        """Newton on [R (+ sigma psi); g (; h); <t, y - y0> - ds] from base + ds t."""
        t = base.tangent
        y0 = base.unknowns()
        y = y0 + ds * t
        n = base.x.size
        phi = base.phi
        for it in range(max_iterations):
            pb = self.problem(y[-1])
            if pb.inadmissible(y[:n], y[n]) is not None:
                raise SolverError("left the model's domain")
            F, blocks, w = self.linearise(y, phi)
            arc = self.inner(t, y - y0) - ds
            if self.converged(F, n) and abs(arc) <= 1e-12 and it > 0:
                phi = w / np.linalg.norm(w)
                if abs(phi @ base.phi) < MODE_OVERLAP:
                    raise SolverError(f"the null vector turned (overlap {abs(phi @ base.phi):.2f}): "
                                      "another singular curve")
                point = self.point(y, phi, w, blocks, it)
                point.tangent = self.tangent(blocks, t)
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
        or BP of a traced branch. If (x0, lam0) is not an equilibrium but an unfolded BP (its
        residual R = -sigma psi within unfold.IMPERFECTION_LIMIT of the load's force, its null
        vector orthogonal to R_lam), the curve is that of the unfolding system (module docstring)
        and its table has the columns ``sigma`` [N] and ``imperfection`` (|sigma| / |lam R_lam|).
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
    system = _start_system(scene_at, control, v0, v_scale, x0, lam0)
    phi0 = phi0 / np.linalg.norm(phi0)
    y0 = np.concatenate([x0, [lam0], [] if system.psi is None else [_sigma_at(system, v0, x0, lam0)], [v0]])
    F, blocks, w = system.linearise(y0, phi0)
    first = system.point(y0, w / np.linalg.norm(w), w, blocks)
    row = np.zeros(y0.size)
    row[-1] = direction
    first.tangent = system.tangent(blocks, row)
    if system.psi is not None and abs(F[-1]) > 1e-6:
        raise SolverError(f"start is not an equilibrium (max |R| = {np.max(np.abs(F[:x0.size])):.3e}) nor a BP "
                          f"of the unfolding (its null vector couples to the load: h = {F[-1]:.2e})")
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


def _start_system(scene_at, control, v0, v_scale, x0, lam0) -> _System:
    """The curve's system: that of exact singular points where the start is an equilibrium, else
    that of the unfolded BP whose imperfection is the start's residual (psi = -R / |R|, the
    state of a BP reported by snapmem.continuation.unfold carries R = -sigma psi); a residual
    beyond unfold.IMPERFECTION_LIMIT of the load's force is no such BP, and an error."""
    pb = make_problem(scene_at(v0), control)
    R = pb.evaluate(x0, lam0, order=1)[0]
    size = float(np.linalg.norm(R))
    tol = 1e-10 * pb.scene.force_scale
    if np.max(np.abs(R)) <= 1e3 * tol:
        return _System(scene_at, control, v0, v_scale)
    load = float(np.linalg.norm(lam0 * pb.dF_dlam(x0, lam0)))
    if size > IMPERFECTION_LIMIT * load:
        raise SolverError(f"start is not an equilibrium (max |R| = {np.max(np.abs(R)):.3e}) nor an unfolded BP "
                          f"(|R| / |lam dR/dlam| = {size / load:.2e} > {IMPERFECTION_LIMIT:g})")
    return _System(scene_at, control, v0, v_scale, psi=-R / size, x0=x0, lam0=lam0)


def _sigma_at(system: _System, v, x, lam) -> float:
    """sigma of R(x, lam; v) + sigma psi = 0 (least squares; exact at the curve's start)."""
    return -float(system.psi @ system.problem(v).evaluate(x, lam, order=1)[0])


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
        unfolded = {} if q.sigma is None else {   # as the points table's: |sigma| / |lam dR/dlam|
            "sigma": q.sigma, "imperfection": abs(q.sigma) / np.linalg.norm(q.lam * pb.dF_dlam(q.x, q.lam))}
        return {"v": q.v, "lam": q.lam, "a": q.a, "s": q.s, "kind": q.kind, "iterations": q.iterations,
                **unfolded, **pb.measures(q.x, q.lam)}

    table = pd.DataFrame([row(q) for q in sorted(points + special, key=lambda q: q.s)])
    special_table = pd.DataFrame([row(q) for q in special],
                                 columns=None if special else list(table.columns))
    return SingularCurve(table, special_table, status, system.iterations, points)
