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
from scipy.optimize import brentq

from snapmem.continuation.branch import Point, PointKind
from snapmem.continuation.modes import legendre_mode
from snapmem.continuation.options import FoldOptions
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
            located = locate_value(tracer, base, p, crossing, PointKind.CRITICAL)
        if located is None:
            located = _polish_critical(tracer, base, p, base.vectors[:, i_base] + p.vectors[:, i_p] * np.sign(base.vectors[:, i_base] @ p.vectors[:, i_p]))
    if located is None:       # bracketed only: report the nearer end
        located = Point(p.x, p.lam, p.tangent, p.eigs, p.negative, p.s, p.ds, 0)
    located.kind = _classify(tracer, located, base, p)
    located.negative = max(base.negative, p.negative)
    return located


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

    An imperfect BP is moved to the bifurcation of the perfect problem
    (:func:`unfold_bifurcation`). Where the mesh's branch turned back at one (an imperfect
    transcritical point has no path through: the mesh's branch follows the bifurcating one),
    and the unfolding finds a BP beside it with an imperfection below
    :data:`IMPERFECTION_LIMIT`, the point is that BP and the trace continues on the branch of the
    perfect problem: ``p`` is replaced, in place, by the point of the mesh's branch beyond the BP
    along the perfect branch's tangent (:func:`_through_imperfect`).
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
        phi = _move_to_unfolded(tracer, c, phi)
    elif unfold and kind == PointKind.LP and c.crossed == 1:
        moved = _through_imperfect(tracer, c, phi, base, p)
        if moved is not None:
            kind, phi, c.symmetry_broken = PointKind.BP, moved, True
    c.mode = legendre_mode(tracer.scene, phi) if kind == PointKind.BP else -1
    return kind


#: The largest imperfection (the force making a bifurcation perfect, relative to the load's
#: force) for which a fold of the mesh's branch is taken as an imperfect BP and passed through.
IMPERFECTION_LIMIT = 1e-2


def _imperfection(pb, found) -> float:
    """|sigma| / |lambda dR/dlambda| of an unfolded point (x, lam, sigma, v)."""
    x, lam, sigma, _ = found
    load = np.linalg.norm(lam * pb.dF_dlam(x, lam))
    return abs(sigma) / load if load > 0 else float("inf")


def _record_unfolded(tracer, c: Point, found) -> np.ndarray:
    """Put c at the unfolded point ``found`` = (x, lam, sigma, v), with the measure
    ``imperfection`` (:func:`_imperfection`); returns v."""
    pb = tracer.pb
    x, lam, sigma, v = found
    log.info("imperfect BP: mesh critical point at %s = %.8g, perfect BP at %.8g", pb.control, c.lam, lam)
    c.x, c.lam = x, lam
    _, J = pb.evaluate(x, lam)
    c.eigs, c.vectors, c.subspace = np.array([float(v @ pb.stiffness(J).matvec(v))]), v[:, None], None
    c.measured = {**pb.measures(x, lam), "imperfection": _imperfection(pb, found)}
    return v


def _move_to_unfolded(tracer, c: Point, phi: np.ndarray) -> np.ndarray:
    """Put the symmetry-broken BP ``c`` (a fold of the mesh problem) at the bifurcation of the
    perfect problem (:func:`unfold_bifurcation`); returns the null vector there (phi itself if
    unfolding fails, and c stays the mesh's critical point)."""
    found = unfold_bifurcation(tracer.pb, tracer.scene, c.x, c.lam, phi)
    if found is None:
        log.warning("could not unfold the imperfect BP at %s = %.6g: reported at the mesh's critical point",
                    tracer.pb.control, c.lam)
        return phi
    return _record_unfolded(tracer, c, found)


def _through_imperfect(tracer, c: Point, phi: np.ndarray, base: Point, p: Point):
    """If the fold c of the mesh's branch is an imperfect BP (the unfolding converges beside it
    with an imperfection below IMPERFECTION_LIMIT), put c at the perfect BP and p, in place, on
    the mesh's branch beyond it; returns the null vector there, or None (c is an LP)."""
    pb = tracer.pb
    found = unfold_bifurcation(pb, tracer.scene, c.x, c.lam, phi)
    if found is None or _imperfection(pb, found) > IMPERFECTION_LIMIT:
        return None
    x, lam, _, v = found
    offset = np.append(c.x - x, c.lam - lam)
    length = max(p.ds, 3.0 * math.sqrt(tracer.inner(offset, offset)))
    beyond = None
    for d in _branch_directions(tracer, x, lam, v):
        d = d * (np.sign(d[-1] * base.tangent[-1]) or 1.0)   # the parameter keeps its direction
        guide = Point(x, lam, tangent=d, s=c.s)
        guide.subspace = base.subspace
        candidate, J1 = tracer.correct(guide, length)
        if candidate is None:
            continue
        candidate.s, candidate.ds = c.s + length, length
        try:
            tracer.finish(candidate, J1, guide)
        except SolverError:
            continue
        # the branch continued beyond a BP keeps the parameter's direction and has one more (or
        # one fewer) negative eigenvalue than before it: the bifurcating branch there has not
        if candidate.tangent[-1] * base.tangent[-1] > 0 and abs(candidate.negative - base.negative) == 1:
            beyond = candidate
            break
    if beyond is None:
        return None
    log.info("passed through the imperfect BP at %s = %.8g onto the branch beyond it", pb.control, lam)
    for name in ("x", "lam", "tangent", "eigs", "negative", "vectors", "subspace", "s", "ds", "iterations"):
        setattr(p, name, getattr(beyond, name))
    p.measured = None
    _record_unfolded(tracer, c, found)
    return v


def _branch_directions(tracer, x, lam, v) -> list:
    """The unit directions (x, lambda) of the two branches through the simple BP (x, lam) with
    null vector v: the roots of Keller's algebraic bifurcation equation a r^2 + 2 b r + c = 0
    (snapmem.continuation.switching), directions r u + t with t = (w, 1) orthogonal to u = (v, 0)."""
    pb = tracer.pb
    _, J = pb.evaluate(x, lam)
    u = np.append(v, 0.0)
    u /= math.sqrt(tracer.inner(u, u))
    lu = BorderedMatrix(J, u[:-1], u[:-1], [[0.0]]).factor()
    if lu.singular:
        return []
    t = np.append(lu.solve(np.append(-pb.dF_dlam(x, lam), 0.0))[:-1], 1.0)
    t /= math.sqrt(tracer.inner(t, t))
    u = u - tracer.inner(u, t) * t
    u /= math.sqrt(tracer.inner(u, u))
    h = 1e-5 * tracer.scene.meridian.size
    psi = v / np.linalg.norm(v)

    def d2(a_, b_):                                   # psi . D2F[a_, b_], central differences of J a_ along b_
        e = h / max(np.max(np.abs(b_)), 1e-300)
        plus = pb.evaluate(x + e * b_[:-1], lam + e * b_[-1])[1].matvec(a_[:-1]) \
            + pb.dF_dlam(x + e * b_[:-1], lam + e * b_[-1]) * a_[-1]
        minus = pb.evaluate(x - e * b_[:-1], lam - e * b_[-1])[1].matvec(a_[:-1]) \
            + pb.dF_dlam(x - e * b_[:-1], lam - e * b_[-1]) * a_[-1]
        return float(psi @ (plus - minus)) / (2 * e)

    a, b, cc = d2(u, u), d2(u, t), d2(t, t)
    if abs(a) <= 1e-8 * (abs(a) + abs(b) + abs(cc)):
        roots = [-cc / (2 * b)] if b != 0 else []
        directions = [u]
    else:
        disc = max(b * b - a * cc, 0.0)
        roots, directions = [(-b + math.sqrt(disc)) / a, (-b - math.sqrt(disc)) / a], []
    for r in roots:
        d = r * u + t
        directions.append(d / math.sqrt(tracer.inner(d, d)))
    return directions


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


# ----------------------------------------------------------------------------------------------
# the bifurcation of the perfect problem behind an imperfect one
def _singularity_function(K, psi):
    """(v, g) of the bordered system [K psi; psi^T 0] [v; g] = [0; 1]: g = 0 exactly where K is
    singular, and then v is its null vector (psi . v = 1). One banded solve, O(N)."""
    lu = BorderedMatrix(K, psi, psi, [[0.0]]).factor()
    if lu.singular:
        return None, None
    rhs = np.zeros(K.n + 1)
    rhs[-1] = 1.0
    sol = lu.solve(rhs)
    return sol[:-1], float(sol[-1])


def _fold_of_unfolding(pb, scene, x, lam, sigma, psi, tol, max_iterations=12):
    """At fixed parameter lam, Newton on (x, sigma) for R(x, lam) + sigma psi = 0, g(x, lam) = 0
    (a singular point of the problem perturbed by the force sigma psi): (x, sigma, v) or None.

    The Jacobian is K bordered by psi and g_x = -D3Pi[v, v, .] (central differences of K v along
    v, as :func:`fold_newton`); it is regular where the reduced equation's quadratic coefficient
    phi . D2R[phi, phi] is not zero (a transcritical point: the sphere's even modes)."""
    L = scene.meridian.size
    for _ in range(max_iterations):
        if pb.inadmissible(x, lam) is not None:
            return None
        F, K = pb.evaluate(x, lam)
        v, g = _singularity_function(K, psi)
        if v is None or not np.all(np.isfinite(F)):
            return None
        residual = F + sigma * psi
        if np.max(np.abs(residual)) <= tol and abs(g) <= 1e-12 * scale_of(K):
            return x, sigma, v
        eps = 1e-6 * L / max(np.max(np.abs(v)), 1e-300)
        g_x = -(pb.evaluate(x + eps * v, lam)[1].matvec(v) - pb.evaluate(x - eps * v, lam)[1].matvec(v)) / (2 * eps)
        lu = BorderedMatrix(K, psi, g_x, [[0.0]]).factor()
        if lu.singular:
            return None
        d = lu.solve(-np.append(residual, g))
        x, sigma = x + d[:-1], sigma + d[-1]
        if np.max(np.abs(d[:-1])) > 0.1 * L:
            return None
    return None


def unfold_bifurcation(pb, scene, x, lam, phi, tol_factor: float = 1e-10, max_iterations: int = 30):
    """The bifurcation point of the perfect problem that an imperfect (mesh) bifurcation at the
    discrete critical point (x, lam) with null vector ``phi`` is a perturbation of.

    On a mesh that breaks the symmetry separating a mode from the load, R(x, lam) = 0 has no BP
    there: its singular point is a fold at distance O(sqrt(imperfection)) from the BP of the
    symmetric problem, so it converges at half the discretisation order. The unfolding system

        R(x, lam) + sigma psi = 0,   K(x, lam) v = 0 (g = 0),   v . dR/dlambda = 0,

    with psi = phi (fixed, unit), finds the force sigma psi that makes the bifurcation perfect
    and the point where it is: a regular system at a simple transcritical BP. Solved nested, each
    part O(N): at fixed lam, Newton on (x, sigma) puts the perturbed problem at a singular point
    (:func:`_fold_of_unfolding`); on lam, the secant method on h(lam) = v . dR/dlambda, which is
    -(d sigma / d lam) v . psi along those singular points, so its zero is where the imperfection
    needed is extremal, the perfect BP. The discrete critical point itself is the start
    (sigma = 0 there).

    Returns
    -------
    (x, lam, sigma, v) or None
        The unfolded point, the imperfection force's size sigma [N] along the unit psi, and the
        null vector v of K there (psi . v = 1); None if an iteration fails.
    """
    tol = tol_factor * scene.force_scale
    psi = np.asarray(phi, float) / np.linalg.norm(phi)
    scale = max(abs(lam), pb.lam_scale)
    load_scale = np.linalg.norm(pb.dF_dlam(x, lam)) + 1e-300       # one fixed scale: h must stay smooth

    def h_of(x0, lam0, sigma0):
        found = _fold_of_unfolding(pb, scene, x0, lam0, sigma0, psi, tol)
        if found is None:
            return None
        xs, sigma, v = found
        return xs, sigma, v, float(v @ pb.dF_dlam(xs, lam0)) / (np.linalg.norm(v) * load_scale)

    first = h_of(x, lam, 0.0)
    if first is None:
        return None
    history = [(lam, *first)]
    lam_next = lam + 1e-4 * scale
    for _ in range(max_iterations):
        lam_prev, x_prev, sigma_prev = history[-1][:3]
        guess = (x_prev, sigma_prev)
        if len(history) >= 2:                         # predict x and sigma linearly in lam
            lam_pp, x_pp, sigma_pp = history[-2][:3]
            w = (lam_next - lam_prev) / (lam_prev - lam_pp)
            guess = (x_prev + w * (x_prev - x_pp), sigma_prev + w * (sigma_prev - sigma_pp))
        found = h_of(guess[0], lam_next, guess[1])
        if found is None:
            return None
        history.append((lam_next, *found))
        (lam_a, *_, h_a), (lam_b, x_b, sigma_b, v_b, h_b) = history[-2], history[-1]
        if h_b == 0.0 or abs(lam_b - lam_a) <= 1e-12 * scale:
            return x_b, lam_b, sigma_b, v_b / np.linalg.norm(v_b)
        if h_b == h_a:
            return None
        step = -h_b * (lam_b - lam_a) / (h_b - h_a)
        if abs(step) > 0.2 * scale:
            return None                               # wandering off
        lam_next = lam_b + step
    return None
