"""Bifurcation points of the perfect problem behind the imperfect ones a mesh has.

Where a mesh breaks the symmetry that separates a mode from the load in the continuum (the
sphere's even Legendre modes on a 1D meridian), R(x, lambda) = 0 has no bifurcation point: near
the continuum's BP its branches are the two halves of a hyperbola (an imperfect transcritical
bifurcation, imperfection O(h^2)), whose folds lie O(sqrt(imperfection)) = O(h) from the BP, so
the mesh's critical point converges at half the discretisation order. :func:`unfold_bifurcation`
finds the BP of the symmetric problem the mesh's is a perturbation of (the unfolding system
R + sigma psi = 0, K v = 0, v . dR/dlambda = 0), which converges at the discretisation order;
:func:`move_to_unfolded` and :func:`through_imperfect` put a located critical point there (the
second also carries the trace through it where the mesh's branch turned back). Every solve is
banded and bordered: O(N).

The functions that take the tracer (snapmem.continuation.tracer) use its problem ``pb``, options,
arclength inner product and ``correct`` / ``finish``.
"""

from __future__ import annotations

import logging
import math

import numpy as np

from snapmem.continuation.branch import Point
from snapmem.errors import SolverError
from snapmem.kernels.banded import BorderedMatrix, scale_of

log = logging.getLogger(__name__)


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


def move_to_unfolded(tracer, c: Point, phi: np.ndarray) -> np.ndarray:
    """Put the symmetry-broken BP ``c`` (a fold of the mesh problem) at the bifurcation of the
    perfect problem (:func:`unfold_bifurcation`); returns the null vector there (phi itself if
    unfolding fails, and c stays the mesh's critical point)."""
    found = unfold_bifurcation(tracer.pb, tracer.scene, c.x, c.lam, phi)
    if found is None:
        log.warning("could not unfold the imperfect BP at %s = %.6g: reported at the mesh's critical point",
                    tracer.pb.control, c.lam)
        return phi
    return _record_unfolded(tracer, c, found)


def through_imperfect(tracer, c: Point, phi: np.ndarray, base: Point, p: Point):
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
    for d in branch_directions(tracer, x, lam, v):
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


def branch_directions(tracer, x, lam, v) -> list:
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
