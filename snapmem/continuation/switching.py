"""Branch switching at a simple bifurcation point: the new branch's direction and its trace.

At a simple BP (x_c, lambda_c) of F(x, lambda) = R = 0 the Jacobian [K, dR/dlambda] has a
two-dimensional null space, spanned by the known branch's tangent t and u = (phi, 0) made
orthogonal to it (phi the null vector of K; the adjoint null vector is phi too, K symmetric).
The tangents of the branches through the point are alpha u + beta t with (Keller's algebraic
bifurcation equation, the Lyapunov-Schmidt reduction to second order)

    a alpha^2 + 2 b alpha beta + c beta^2 = 0,
    a = phi . D2F[u, u],  b = phi . D2F[u, t],  c = phi . D2F[t, t],

whose roots are the known branch (alpha = 0 when c = 0) and the new one: a pitchfork (a = 0)
leaves along u, a transcritical point along a mix. The second derivatives are central
differences of the Jacobian-vector product along each direction: four evaluations, banded,
O(N). Where the mesh breaks the BP's symmetry (``symmetry_broken``) the bifurcation is imperfect:
the point is reported at the perfect problem's BP (snapmem.continuation.unfold.unfold_bifurcation),
near which the mesh's branches are the two halves of a hyperbola; the branch is traced along phi
(the mesh's fold direction) both ways from there.
"""

from __future__ import annotations

import logging
import math

import numpy as np


from snapmem.continuation.branch import BRANCH_SWITCHING, Branch, Point, PointKind
from snapmem.continuation.diagram import Diagram
from snapmem.continuation.locate import SYMMETRY_COUPLING
from snapmem.continuation.options import ContinuationOptions
from snapmem.continuation.problems import make_problem
from snapmem.continuation.tracer import Tracer, trace
from snapmem.errors import SnapmemError, SolverError
from snapmem.kernels.banded import BorderedMatrix

log = logging.getLogger(__name__)


def _jacobian_times(pb, x, lam, v):
    """[K, dR/dlambda] (x, lam) applied to v = (v_x, v_lambda)."""
    _, J = pb.evaluate(x, lam)
    return J.matvec(v[:-1]) + pb.dF_dlam(x, lam) * v[-1]


def second_derivative(pb, x, lam, u, v, scale: float) -> np.ndarray:
    """D2F[u, v] at (x, lam) by central differences of J u along v (step ``scale`` / |v|_inf)."""
    eps = scale / max(np.max(np.abs(v)), 1e-300)
    plus = _jacobian_times(pb, x + eps * v[:-1], lam + eps * v[-1], u)
    minus = _jacobian_times(pb, x - eps * v[:-1], lam - eps * v[-1], u)
    return (plus - minus) / (2 * eps)


def bifurcation_direction(tracer: Tracer, c: Point, phi: np.ndarray, imperfect: bool = False,
                          exchange: np.ndarray | None = None):
    """(the unit direction (x, lambda) of the branch bifurcating at c, the coefficients (a, b, c)
    of the algebraic bifurcation equation, whether c was taken as a fold of the mesh).

    ``imperfect``: the mesh breaks the BP's symmetry (c is a fold of the discrete problem); the
    direction is then the null vector itself, oriented along c's tangent. Else the known branch's
    tangent is recomputed orthogonal to phi (at the BP the bordered tangent solve is singular):
    t = (w, 1) normalised, [K phi; phi^T 0] [w; mu] = [-dR/dlambda; 0].

    ``exchange``: the exchange permutation of two identical membranes (:func:`_exchange_breaking`)
    when c is a symmetric state and phi the antisymmetric mode that breaks it; w, which solves a
    system commuting with the exchange with a symmetric right-hand side, is then made exactly
    symmetric, so that a and c are zero to rounding by symmetry, whatever the rounding of the solves.
    """
    pb = tracer.pb
    n = c.tangent.size
    u = np.zeros(n)
    u[: phi.size] = phi                     # (under volume control phi has no pressure part)
    u /= math.sqrt(tracer.inner(u, u))
    if imperfect:
        return u * (np.sign(tracer.inner(u, c.tangent)) or 1.0), (math.nan, math.nan, math.nan), True
    _, J = pb.evaluate(c.x, c.lam)
    lu = BorderedMatrix(J, u[:-1], u[:-1], [[0.0]]).factor()
    if lu.singular:
        raise SolverError("switching: the BP's bordered stiffness is singular (not a simple BP)")
    w = lu.solve(np.append(-pb.dF_dlam(c.x, c.lam), 0.0))[:-1]
    if exchange is not None:
        w = 0.5 * (w + w[exchange])
    t = np.append(w, 1.0)
    t *= np.sign(c.tangent[-1]) or 1.0
    t /= math.sqrt(tracer.inner(t, t))
    overlap = tracer.inner(u, t)
    u = u - overlap * t
    u /= math.sqrt(tracer.inner(u, u))
    scale = 1e-5 * tracer.scene.meridian.size
    psi = u[:-1] / np.linalg.norm(u[:-1])
    a = float(psi @ second_derivative(pb, c.x, c.lam, u, u, scale))
    b = float(psi @ second_derivative(pb, c.x, c.lam, u, t, scale))
    cc = float(psi @ second_derivative(pb, c.x, c.lam, t, t, scale))
    # roots alpha/beta = r of a r^2 + 2 b r + cc = 0; the known branch is the root nearest r = 0
    size = abs(a) + abs(b) + abs(cc)
    if abs(a) <= 1e-8 * size:
        alpha, beta = 1.0, 0.0              # pitchfork: along u
    else:
        disc = max(b * b - a * cc, 0.0)
        roots = [(-b + math.sqrt(disc)) / a, (-b - math.sqrt(disc)) / a]
        r = max(roots, key=abs)
        alpha, beta = r, 1.0
    d = alpha * u + beta * t
    return d / math.sqrt(tracer.inner(d, d)), (a, b, cc), False


def switch_branch(parent: Branch, k: int, ds: float = 0.02, until=None,
                  options: ContinuationOptions | None = None) -> Diagram:
    """Trace the branch bifurcating at row ``k`` of ``parent.points`` both ways.

    Parameters
    ----------
    parent : Branch
    k : int
        Row of the points table (a BP; an LP has no other branch).
    ds : float
        The first step from the BP along the bifurcating direction (scaled arclength).
    until : mapping, optional
        Where the new branches stop (default: as trace's default, none; ``options.max_steps``).
    options : ContinuationOptions, optional
        Options of the new traces (default: the defaults).

    Returns
    -------
    Diagram
        Branch 0 is ``parent``; branches 1 and 2 leave it at row k along +d and -d. Each new
        branch starts at its first point off the BP (ds away) and carries the BP's coefficients
        in ``stats['switch']``.
    """
    kind = parent.points["kind"].iloc[k]
    if kind != PointKind.BP.value:
        raise SnapmemError(f"--switch row {k}: the point is {str(kind)!r}, not a BP (rows with BP: "
                           f"{list(np.flatnonzero(parent.points['kind'] == PointKind.BP.value))})")
    c = parent.critical_state(k)
    imperfect = bool(parent.points["symmetry_broken"].iloc[k]) if "symmetry_broken" in parent.points else None
    diagram = Diagram()
    diagram.add(parent)
    for sign, child in switch_at(parent.scene, parent.control, c, ds, until, options, imperfect):
        diagram.add(child, parent=0, row=k, sign=sign)
    return diagram


def switch_at(scene, control: str, c: Point, ds: float = 0.02, until=None,
              options: ContinuationOptions | None = None, imperfect: bool | None = None) -> list:
    """The two halves [(+1, Branch), (-1, Branch)] of the branch bifurcating at the BP ``c`` (a
    Point with its state, parameter and tangent) of ``scene`` traced in ``control``.
    ``imperfect``: whether the mesh breaks the BP's symmetry (None: from the coupling of its
    null vector, above 1e-6)."""
    options = options or ContinuationOptions()
    pb = make_problem(scene, control)
    tracer = Tracer(pb, options, scene)
    _, J = pb.evaluate(c.x, c.lam)
    if c.tangent is None:
        raise SnapmemError("the BP has no tangent: cannot switch there")
    phi = _null_vector(pb, J, c)
    exchange = _exchange_breaking(pb, c, phi)
    if exchange is not None:
        phi = 0.5 * (phi - phi[exchange])      # the exchange-breaking mode, antisymmetric exactly
    if imperfect is None:
        Fl = pb.dF_dlam(c.x, c.lam)[: phi.size]
        imperfect = abs(phi @ Fl) / (np.linalg.norm(phi) * np.linalg.norm(Fl)) > SYMMETRY_COUPLING
    d, coefficients, fold = bifurcation_direction(tracer, c, phi, imperfect, exchange)
    perm = _mirror_permutation(pb, c, d)
    halves = []
    for sign in (1, -1):
        if sign == -1 and perm is not None and halves:
            halves.append((-1, mirror_branch(halves[0][1], pb, perm)))
            break
        base = Point(c.x, c.lam, tangent=sign * d)
        first, J1 = tracer.correct(base, ds)
        if first is None:
            log.warning("switching (%+d): the first step failed: %s", sign, J1)
            continue
        q, loads = pb.state(first.x, first.lam)
        toward = np.append(first.x - c.x, first.lam - c.lam)
        try:
            child = trace(scene, control, until=until, options=options, start=(q, loads), toward=toward)
        except (SnapmemError, SolverError) as exc:
            log.warning("switching (%+d): %s", sign, exc)
            continue
        child.stats["switch"] = {"a": coefficients[0], "b": coefficients[1], "c": coefficients[2],
                                 "fold_of_mesh": fold, "sign": sign}
        if perm is not None:
            child.table["mirrored"] = False
            child.points["mirrored"] = False
        halves.append((sign, child))
    return halves


def _exchange_breaking(pb, c: Point, phi: np.ndarray):
    """The exchange permutation of the problem's unknowns (its ``exchange``: two identical
    membranes) if the BP ``c`` is a symmetric state (to 1e-8) and its null vector ``phi``
    antisymmetric up to a symmetric part below 1e-6 of it (the mode breaks the exchange), else None.
    By symmetry that null vector is antisymmetric exactly; the located one is, to the rounding of
    the eigenvalue iteration, which the bifurcation coefficients would otherwise magnify."""
    exchange = getattr(pb, "exchange", None)
    perm = None if exchange is None else exchange()
    if perm is None or c.x.size != perm.size or phi.size != perm.size:
        return None
    if np.max(np.abs(c.x[perm] - c.x)) > 1e-8 * max(np.max(np.abs(c.x)), 1e-300):
        return None
    anti, sym = np.linalg.norm(phi - phi[perm]), np.linalg.norm(phi + phi[perm])
    return perm if sym <= 1e-6 * anti else None


def _mirror_permutation(pb, c: Point, d: np.ndarray):
    """The exchange permutation of the problem's unknowns (its ``exchange``: two identical
    membranes) if the BP ``c`` is a symmetric state and the direction ``d`` antisymmetric (to
    1e-8): then the half along -d is the mirror image of the half along +d. Else None."""
    exchange = getattr(pb, "exchange", None)
    perm = None if exchange is None else exchange()
    if perm is None:
        return None
    n = c.x.size
    symmetric = np.max(np.abs(c.x[perm] - c.x)) <= 1e-8 * max(np.max(np.abs(c.x)), 1e-300)
    antisymmetric = (np.max(np.abs(d[:n][perm] + d[:n])) <= 1e-8 * np.max(np.abs(d[:n]))
                     and abs(d[-1]) <= 1e-8 * np.max(np.abs(d)))
    return perm if symmetric and antisymmetric else None


def mirror_branch(child: Branch, pb, perm: np.ndarray) -> Branch:
    """The exchange image of a switched half (two identical membranes): its states permuted by
    ``perm``, the per-membrane columns ``NAME_1`` and ``NAME_2`` of its tables swapped, everything
    else (the parameter, the chambers' totals, pressures, eigenvalues, inertia, kinds) equal.

    Not computed: its tables carry ``mirrored`` = True, its ``stats['mirror_of']`` is the sign of
    the half it is the image of, and its Newton counts are zero."""
    def swapped(table):
        names = {}
        for col in table.columns:
            if col.endswith("_1") and col[:-2] + "_2" in table.columns:
                names[col], names[col[:-2] + "_2"] = col[:-2] + "_2", col
        out = table.rename(columns=names)[list(table.columns)]       # one relabelling, columns in place
        out["mirrored"] = True
        return out

    stats = {**child.stats, "newton_iterations": 0, "evaluations": 0, "mirror_of": child.stats["switch"]["sign"],
             "switch": {**child.stats["switch"], "sign": -child.stats["switch"]["sign"]}}
    return Branch(child.scene, child.control, swapped(child.table), swapped(child.points), child.rejections.copy(),
                  child.status, child.outcome, [pb.mirrored_point(p, perm) for p in child.states], stats)


def _null_vector(pb, J, c: Point) -> np.ndarray:
    """The null vector of K at c: its located eigenvector, else inverse iteration (banded)."""
    if c.vectors is not None and c.eigs is not None:
        return c.vectors[:, int(np.argmin(np.abs(c.eigs)))]
    K = pb.stiffness(J)
    lu = K.factor()
    phi = np.random.default_rng(0).normal(size=K.n)
    for _ in range(4):
        phi = lu.solve(phi)
        phi /= np.linalg.norm(phi)
    return phi


BRANCH_SWITCHING[:] = [switch_branch]
