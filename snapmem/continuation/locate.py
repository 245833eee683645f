"""Locating points between two accepted points of a branch, and classifying critical points.

A point where a function of the branch vanishes (a parameter value, an output, the crossing
eigenvalue, the tangent's parameter component) is found by Brent's method on the arclength
between two accepted points; every point on the way is converged by the tracer's corrector.
Where following the crossing eigenvalue fails, a critical point is polished by Newton on the
minimally extended system [R = 0, g = 0] (:func:`fold_newton`, which fold curves use too). Its
tangent classifies it (MODEL.md section 3): a limit point (LP) is where the parameter turns back
(the tangent's parameter component changes sign), a bifurcation point (BP) is where the inertia
changes and the parameter keeps its direction. The coupling phi0 . dR/dlambda is reported, not
used to classify: modes the continuum separates from the load by symmetry couple to it on a mesh
at discretisation order.

The functions take the tracer (snapmem.continuation.tracer) as their first argument: its problem
``pb``, options ``opt``, arclength inner product ``inner`` and ``point_at`` / ``finish``.
"""

from __future__ import annotations

import logging
import math

import numpy as np

from snapmem.kernels.roots import brentq     # scipy.optimize.brentq bit for bit, without importing scipy.optimize

from snapmem.continuation.branch import Point, PointKind
from snapmem.continuation.modes import legendre_mode
from snapmem.continuation.options import FoldOptions
from snapmem.continuation.unfold import move_to_unfolded, through_imperfect
from snapmem.errors import SolverError
from snapmem.kernels.banded import BorderedMatrix, scale_of

log = logging.getLogger(__name__)


class _Found(Exception):
    """f is within its tolerance of zero at arclength offset ``s``."""

    def __init__(self, s: float):
        super().__init__(s)
        self.s = s


def locate_value(tracer, base: Point, p: Point, f, kind: PointKind, needs_eigenvalues: bool = True,
                 ftol: float = 0.0):
    """The point between base and p where f(point, s) = 0, by Brent's method on the arclength s
    from base (p is at s = ds; f is evaluated there and at base from the points themselves),
    stopping at s to 1e-13 ds or where |f| <= ``ftol`` (the rounding of f: Brent's method would
    go on bisecting noise there).

    Every point computed on the way gets its tangent, and the next one starts its corrector from
    the nearest point along that tangent (one or two iterations instead of three from base).
    Each starts its eigenvalue iteration (where ``needs_eigenvalues``) from the subspace of the
    last point computed, so it converges in a sweep or two. The located point is the one Brent's
    method evaluated last if that is where it stopped, else computed anew.
    """
    ds = p.s - base.s
    cache = {0.0: (base, None), ds: (p, None)}
    last = [base]

    def g(s):
        if s not in cache:
            cache[s] = tracer.point_at(_with_vectors(base, last[0]), s, stability=needs_eigenvalues,
                                       guess=_guess(tracer, base, cache, s))
            last[0] = cache[s][0]
        value = f(cache[s][0], s)
        if abs(value) <= ftol and 0.0 < s < ds:
            raise _Found(s)
        return value

    try:
        try:
            s = brentq(g, 0.0, ds, xtol=1e-13 * ds, rtol=4 * np.finfo(float).eps, maxiter=60)
        except _Found as found:
            s = found.s
        pt, J = cache.get(s, (None, None))
        if J is None:
            pt = tracer.point_at(_with_vectors(base, last[0]), s, guess=_guess(tracer, base, cache, s))[0]
        elif not needs_eigenvalues and tracer.opt.stability:
            tracer.finish(pt, J, _with_vectors(base, last[0]), tangent=False, precise=True)
    except (SolverError, ValueError, RuntimeError) as exc:      # RuntimeError: Brent's iteration limit
        log.warning("could not locate %s point: %s", kind.value, exc)
        return None
    pt.kind, pt.located = kind, True
    return pt


def _guess(tracer, base: Point, computed: dict, s: float):
    """Start of the corrector for the point at arclength s from base: along the tangent of the
    nearest point computed ({offset: (point, J)}), onto the arclength hyperplane of s."""
    near = min(computed, key=lambda t: abs(t - s))
    q = computed[near][0]
    step = (s - near) / tracer.inner(base.tangent, q.tangent)
    return q.x + step * q.tangent[:-1], q.lam + step * q.tangent[-1]


def _with_vectors(base: Point, donor: Point) -> Point:
    """``base`` with the eigenvectors of ``donor`` (a warm start for the eigenvalue iteration)."""
    if donor is base or donor.vectors is None:
        return base
    clone = Point(base.x, base.lam, base.tangent, base.eigs, base.negative, base.s, base.ds)
    clone.vectors, clone.subspace = donor.vectors, donor.subspace
    return clone


def _crossing_index(pt: Point, rising_side_positive: bool):
    """Index in pt.eigs of the eigenvalue nearest zero on one side (None if the set has none)."""
    pick = np.flatnonzero(pt.eigs >= 0) if rising_side_positive else np.flatnonzero(pt.eigs < 0)
    if pick.size == 0:
        return None
    return pick[np.argmin(pt.eigs[pick])] if rising_side_positive else pick[np.argmax(pt.eigs[pick])]


def locate_critical(tracer, base: Point, p: Point):
    """Locate the critical point where an eigenvalue's sign change altered the inertia between base and p.

    Where the parameter turns back between them, it is the zero of the tangent's parameter
    component. Otherwise it is the zero of the eigenvalue that crossed: at the two ends the
    inertia says which one (the smallest non-negative one on the side with fewer negative
    eigenvalues, the largest negative one on the other); inside the bracket it is followed by
    continuity of its eigenvector from the nearest point already computed: there the inertia
    count is unreliable within rounding of a singular K.
    """
    located = None
    rising = p.negative > base.negative
    i_base, i_p = _crossing_index(base, rising), _crossing_index(p, not rising)
    if tracer.opt.locate and i_base is not None and i_p is not None and base.vectors is not None:
        ds = p.s - base.s
        tracked = {0.0: base.vectors[:, i_base], ds: p.vectors[:, i_p]}
        ends = {0.0: float(base.eigs[i_base]), ds: float(p.eigs[i_p])}

        def crossing(pt, s):
            if s in ends:
                return ends[s]
            nearest = min(tracked, key=lambda t: abs(t - s))
            i = int(np.argmax(np.abs(pt.vectors.T @ tracked[nearest])))
            tracked[s] = pt.vectors[:, i]
            return float(pt.eigs[i])

        if base.tangent[-1] * p.tangent[-1] < 0 and tracer.pb.jacobian_is_stiffness:
            # a limit point of the parameter: there K is singular and the tangent's parameter
            # component vanishes, a simple zero that needs no eigenvalues on the way
            scale = math.sqrt(tracer.wl)                # the parameter component of the unit tangent
            located = locate_value(tracer, base, p, lambda pt, s: scale * pt.tangent[-1], PointKind.CRITICAL,
                                    needs_eigenvalues=False, ftol=1e-12)
        else:
            located = locate_value(tracer, base, p, crossing, PointKind.CRITICAL, ftol=_crossing_ftol(tracer, p))
        if located is None:
            located = _polish_critical(tracer, base, p, base.vectors[:, i_base] + p.vectors[:, i_p] * np.sign(base.vectors[:, i_base] @ p.vectors[:, i_p]))
    if located is None:       # bracketed only: report the nearer end
        located = Point(p.x, p.lam, p.tangent, p.eigs, p.negative, p.s, p.ds, 0)
    located.kind = _classify(tracer, located, base, p)
    located.negative = max(base.negative, p.negative)
    return located


def _crossing_ftol(tracer, p: Point) -> float:
    """Where the search for a crossing eigenvalue's zero stops: |eigenvalue| at most the problem's
    ``crossing_rounding`` (relative to |K|, the largest diagonal entry, at p), 0 (Brent's xtol
    alone) for a problem without one. Below that the eigenvalue iteration's value is rounding and
    Brent's method bisects noise: at the two-balloon BPs (|K| ~ 60) the values below 1e-14 change
    sign at random over the last 1e-12 of arclength, which cost 8 of a BP's 14 evaluations."""
    rounding = getattr(tracer.pb, "crossing_rounding", 0.0)
    if not rounding:
        return 0.0
    return rounding * scale_of(tracer.pb.stiffness(tracer.pb.evaluate(p.x, p.lam)[1]))


def _polish_critical(tracer, base: Point, p: Point, phi: np.ndarray):
    """Where following the crossing eigenvalue fails (modes crowding near a bifurcation), locate
    the singular point by Newton on the minimally extended system [R = 0, g = 0] from the
    bracket, as fold curves do. Accepted if it lands within the bracket."""
    if not tracer.pb.jacobian_is_stiffness:
        return None
    result = fold_newton(tracer.pb, tracer.scene, 0.5 * (base.x + p.x), 0.5 * (base.lam + p.lam),
                          phi / np.linalg.norm(phi), FoldOptions())
    if result is None:
        return None
    x, lam, _, _ = result
    span = np.append(p.x - base.x, p.lam - base.lam)
    where = tracer.inner(span, np.append(x - base.x, lam - base.lam)) / tracer.inner(span, span)
    if not -0.25 <= where <= 1.25:
        log.warning("critical point polished outside its bracket (at %.3g of it): not used", where)
        return None
    _, J = tracer.pb.evaluate(x, lam)
    pt = Point(x, lam, s=base.s + where * (p.s - base.s))
    tracer.finish(pt, J, _with_vectors(base, p), tangent=True, precise=True)
    pt.kind, pt.located = PointKind.CRITICAL, True
    return pt


def _classify(tracer, c: Point, base: Point, p: Point) -> PointKind:
    """LP if the parameter turned back between base and p (the tangent's parameter component
    changed sign), else BP (the inertia changed while the parameter kept its direction).

    Also records on ``c``: ``coupling`` (|phi0 . dR/dlambda| normalised), ``crossed`` (how many
    eigenvalues crossed zero), ``symmetry_broken`` (a BP whose null vector couples to the load
    above :data:`SYMMETRY_COUPLING`: the mesh breaks the symmetry that separates the mode from
    the load in the continuum, so on the mesh the bifurcation is imperfect) and ``mode`` (the
    Legendre mode of the null vector on a spherical reference, else -1;
    :func:`snapmem.continuation.modes.legendre_mode`).

    An imperfect BP is moved to the bifurcation of the perfect problem (snapmem.continuation.unfold).
    Where the mesh's branch turned back at one (an imperfect transcritical point has no path
    through: the mesh's branch follows the bifurcating one) and the unfolding finds a BP beside
    it with an imperfection below ``unfold.IMPERFECTION_LIMIT``, the point is that BP and the
    trace continues on the perfect problem's branch: ``p`` is replaced, in place, by the point of
    the mesh's branch beyond the BP (``unfold.through_imperfect``).
    """
    pb = tracer.pb
    phi = null_vector(tracer, c)
    Fl = pb.dF_dlam(c.x, c.lam)[: phi.size]
    c.coupling = abs(float(phi @ Fl)) / (np.linalg.norm(phi) * np.linalg.norm(Fl) + 1e-300)
    c.crossed = abs(int(p.negative) - int(base.negative)) if None not in (p.negative, base.negative) else -1
    turned = base.tangent[-1] * p.tangent[-1] < 0
    kind = PointKind.LP if pb.is_limit_point(c.coupling, turned) else PointKind.BP
    c.symmetry_broken = bool(kind == PointKind.BP and c.coupling > SYMMETRY_COUPLING)
    unfold = c.located and pb.jacobian_is_stiffness and tracer.opt.locate
    if unfold and c.symmetry_broken:
        phi = move_to_unfolded(tracer, c, phi)
    elif unfold and kind == PointKind.LP and c.crossed == 1:
        moved = through_imperfect(tracer, c, phi, base, p)
        if moved is not None:
            kind, phi, c.symmetry_broken = PointKind.BP, moved, True
    c.mode = legendre_mode(tracer.scene, phi) if kind == PointKind.BP else -1
    return kind


#: The normalised coupling |phi0 . dR/dlambda| above which a BP's symmetry is broken by the mesh
#: (exact BPs of a symmetric mesh are located with couplings below 1e-8).
SYMMETRY_COUPLING = 1e-6


def null_vector(tracer, c: Point) -> np.ndarray:
    """The null vector phi0 of K at the critical point c (over the problem's state unknowns):
    K's eigenvector nearest zero if converged there, else by three inverse iterations (O(N))."""
    pb = tracer.pb
    if c.located and c.vectors is not None:      # K's vector nearest zero, converged at the point
        return c.vectors[:, np.argmin(np.abs(c.eigs))]
    _, J = pb.evaluate(c.x, c.lam)
    K = pb.stiffness(J)
    lu = K.factor()
    phi = np.random.default_rng(0).normal(size=K.n)
    if not lu.singular:
        for _ in range(3):                       # inverse iteration: K is (nearly) singular here
            phi = lu.solve(phi)
            phi /= np.linalg.norm(phi)
    return phi


def touching(tracer, a: Point, b: Point, c: Point):
    """Catch an eigenvalue that dips to zero and back between a and c without changing the count."""
    fa, fb, fc = a.test_value, b.test_value, c.test_value
    if not (b.negative == a.negative == c.negative and fb < fa and fb < fc):
        return []
    if b.negative > 0:                     # watch the lowest non-negative eigenvalue
        return []
    sa, sb, sc = a.s, b.s, c.s
    # parabola through the three points; its minimum
    A = np.array([[sa * sa, sa, 1], [sb * sb, sb, 1], [sc * sc, sc, 1]])
    try:
        qa, qb, qc = np.linalg.solve(A, [fa, fb, fc])
    except np.linalg.LinAlgError:
        return []
    if qa <= 0:
        return []
    s_min = -qb / (2 * qa)
    f_min = qc - qb * qb / (4 * qa)
    if f_min > 0 or not (sa < s_min < sc):
        return []
    log.info("an eigenvalue may touch zero near s = %.6g: checking", s_min)
    try:
        mid = tracer.point_at(b, s_min - sb)[0] if s_min > sb else tracer.point_at(a, s_min - sa)[0]   # its tangent classifies
    except SolverError:
        return []
    if mid.negative == b.negative:
        return []
    base = b if s_min > sb else a
    first = locate_critical(tracer, base, mid)
    second = locate_critical(tracer, mid, c) if s_min > sb else locate_critical(tracer, mid, b)
    return [first, second]



def fold_newton(pb, scene, x, lam, phi, options):
    """Newton on [R; g] for the limit point near (x, lam); returns (x, lam, phi, iterations) or None."""
    tol = options.tol * scene.force_scale
    L = scene.meridian.size
    for it in range(options.max_iterations):
        if pb.inadmissible(x, lam) is not None:
            return None
        F, K = pb.evaluate(x, lam)
        border = BorderedMatrix(K, phi, phi, [[0.0]])
        lu = border.factor()
        if lu.singular:
            return None
        rhs = np.zeros(K.n + 1)
        rhs[-1] = 1.0
        sol = lu.solve(rhs)
        v, g = sol[:-1], sol[-1]
        eps = 1e-6 * L / max(np.max(np.abs(v)), 1e-300)
        Kv_plus = pb.evaluate(x + eps * v, lam)[1].matvec(v)
        Kv_minus = pb.evaluate(x - eps * v, lam)[1].matvec(v)
        g_x = -(Kv_plus - Kv_minus) / (2 * eps)                       # -D3Pi[v, v, .]
        dl = 1e-6 * max(abs(lam), pb.lam_scale)
        g_l = -(pb.evaluate(x, lam + dl)[1].matvec(v) - pb.evaluate(x, lam - dl)[1].matvec(v)) @ v / (2 * dl)
        Fl = pb.dF_dlam(x, lam)
        if not np.all(np.isfinite(F)):
            return None
        converged = np.max(np.abs(F)) <= tol
        J = BorderedMatrix(K, Fl, g_x, [[g_l]])
        lu = J.factor()
        if lu.singular:
            return None
        d = lu.solve(-np.append(F, g))
        if converged and abs(d[-1]) <= 1e-12 * max(abs(lam), pb.lam_scale):
            return x, lam, v / np.linalg.norm(v), it
        x, lam = x + d[:-1], lam + d[-1]
        if abs(d[-1]) > 0.5 * max(abs(lam), pb.lam_scale) or np.max(np.abs(d[:-1])) > 0.5 * L:
            return None                               # wandering off: refine the increment instead
    return None
