"""A time step's whole Newton solve in one compiled call, for the scenes whose terms it knows.

Why it exists: a time step of a small scene (a ball on a 61-node balloon) is ~5 Newton
iterations of ~20 us of compiled arithmetic each, and the general path (``Scene.evaluate`` with
its node terms, ``snapmem.solvers.newton.newton``, the bordered solve, the domain checks) spends ~230 us
more per iteration in Python calls around it. The profile of ``ball_drop`` showed that glue as
the whole cost. Here the same arithmetic runs in one numba kernel per time step, built from the
same building blocks (``snapmem.kernels``, ``snapmem.kernels.contact``): the stretches, the
law's density, the fused membrane assembly, the contact barriers, the band LDL^T with the
bodies' Schur complement, the step limits and domain checks, and Newton's line search on the
step's incremental potential as ``newton(..., merit='energy')`` does it. An iteration costs
about 14 us (assembly 6, bordered solve 5, step limit 2, measured on ``ball_throw``), and the
ball scenes run at 126-141x real time instead of 13-15x; every robot's steps, iteration counts
and events are those of the general path.

What it covers (:meth:`CompiledStep.of` returns None otherwise, and the general path runs):

* the stretching term of a law in :data:`LAW_KINDS` (neo-Hookean, Mooney-Rivlin, Gent), the
  electric term, the pressure work;
* contact barriers with a linear gap (rod, shell, plane) and balls in edge mode (with or without
  a body of their own);
* the 'energy' line search of :class:`snapmem.dynamics.driver.DynamicsOptions`.

A step whose tangent the LDL^T cannot factor stably (a zero pivot or large growth: rare, the
inertia M / h^2 makes K positive definite but for very large steps) is handed back, and the
general Newton (with its pivoted LU) takes it. The scene's numpy and general paths stay the
reference: the tests compare this step's solution and iteration count with them.

Adding a term here is optional: a scene with a term this module does not know simply runs the
general path.
"""

from __future__ import annotations

from collections import namedtuple

import numpy as np
from numba import njit

from snapmem.kernels.banded import LDLT_GROWTH_LIMIT
from snapmem.model.contact import FRACTION_TO_BOUNDARY, Ball, Contact, contact_names
from snapmem.kernels.contact import (ball_edge_barrier, ball_edge_gaps, ball_min_gap, ball_node_max_step, linear_barrier,
                              linear_max_step, linear_min_gap)
from snapmem.kernels.linalg import _ldlt_solve_vector, band_ldlt, band_ldlt_solve, band_matvec
from snapmem.kernels.assembly import edge_assembly, edge_stretches, invariant_chain, linear_law_density, radius_max_step, state_check
from snapmem.model.materials import Gent, InvariantLaw
from snapmem.solvers.newton import NewtonReport
from snapmem.model.terms import Electric, PressureWork, Stretching

#: Use the compiled step where it applies; False runs every step by the general path (the
#: reference the tests compare with).
enabled = True

#: How a compiled solve ends (``status`` of :func:`step_newton`) and the report's reason for it.
REASONS = ("converged", "max iterations", "line search failed: no step lowers the energy",
           "left the model's domain: every trial step was outside it", "singular tangent stiffness",
           "residual is not finite", "left the model's domain: the starting state is outside it")
#: Status of a step handed back to the general path (an LDL^T it cannot trust).
HANDED_BACK = -1

#: Laws the kernel evaluates itself: law class (or "linear": any law linear in the invariants,
#: neo-Hookean and Mooney-Rivlin) -> a function of the law giving (kind, parameters). A law not
#: here (Yeoh, a new one) runs the general path; adding one is an entry here and a branch of
#: :func:`_law_density` (and of :func:`_state_ok` if it locks).
LINEAR, GENT = 0, 1
LAW_KINDS = {
    "linear": lambda law: (LINEAR, law.invariant_derivatives(3.0, 3.0)[1:3]),   # W1 (I1 - 3) + W2 (I2 - 3)
    Gent: lambda law: (GENT, (law.mu, law.Jlim)),
}


def _law_kind(law):
    """(kind, parameters) of a law the kernel covers, else None."""
    if isinstance(law, InvariantLaw) and law.linear:
        return LAW_KINDS["linear"](law)
    make = LAW_KINDS.get(type(law))
    return None if make is None else make(law)


# Everything the kernel needs of a scene, packed once (numba takes named tuples of arrays).
Plan = namedtuple("Plan", [
    "edges", "inv_length", "inv_mid_radius", "weight", "law", "law_params",   # membrane; law: LAW_KINDS
    "hess_index", "band_size", "n_band", "bandwidth", "free", "radius_dofs", "n_node_dofs", "n_bodies",
    "edge_dofs", "edge_pos", "node_hess",                                 # scatter maps of node and edge terms
    "lin_nodes", "lin_ptr", "lin_axis", "lin_sign", "lin_offset", "lin_dhat", "lin_coef",   # rod, shell, plane
    "ball_radius", "ball_dhat", "ball_coef", "ball_z0", "ball_dof", "ball_col", "ball_weight",  # balls
])


class CompiledStep:
    """The compiled Newton solve of a time step's incremental potential for one scene.

    Build with :meth:`of` (None when the scene has a term this module does not cover); then
    :meth:`solve` takes the place of ``newton(assemble, guess, ...)`` in the stepper.
    """

    def __init__(self, scene, plan: Plan, electric: tuple, pressure: bool, contact_slots: list):
        self.scene, self.plan = scene, plan
        self._electric = electric            # (eps / (2 H^2)) of each electric term
        self._pressure = pressure
        # (output name, index in the kernel's contact arrays) of every contact, in the scene's order
        self._contacts = list(zip(contact_names(scene), contact_slots))

    @classmethod
    def of(cls, scene) -> "CompiledStep | None":
        """The compiled step of ``scene``, or None if one of its terms is not covered (or not ``enabled``)."""
        if not enabled:
            return None
        laws = [t for t in scene.density_terms if isinstance(t, Stretching)]
        electric = [t for t in scene.density_terms if type(t) is Electric]
        law = _law_kind(laws[0].law) if len(laws) == 1 else None
        if law is None or len(laws) + len(electric) != len(scene.density_terms):
            return None
        if not all(type(t) is PressureWork for t in scene.edge_terms) or len(scene.edge_terms) > 1:
            return None
        m = scene.meridian
        n_nodes = m.nodes
        linear, balls, kinds = [], [], []
        for term, s in zip(scene.node_terms, scene._body_slices):
            if isinstance(term, Contact) and term.linear is not None and not term.bodies:
                kinds.append((False, len(linear)))
                linear.append(term)
            elif type(term) is Ball and term.meridian is not None and term.nodes is None and len(term.bodies) <= 1:
                kinds.append((True, len(balls)))
                balls.append((term, s))
            else:
                return None
        lin_nodes = [t._node_index(n_nodes) for t in linear]
        plan = Plan(
            edges=np.ascontiguousarray(m.edges, dtype=np.int64),
            inv_length=m.inverse_length, inv_mid_radius=m.inverse_mid_radius, weight=scene.weight,
            law=law[0], law_params=np.array(law[1], dtype=float),
            hess_index=np.ascontiguousarray(scene._hess_index, dtype=np.int64), band_size=int(scene._band_size),
            n_band=int(scene.n_band), bandwidth=int(scene.bandwidth),
            free=np.ascontiguousarray(scene.free, dtype=np.int64),
            radius_dofs=np.ascontiguousarray(scene._free_radius_dofs, dtype=np.int64),
            n_node_dofs=int(scene.n_node_dofs), n_bodies=len(scene.bodies),
            edge_dofs=np.ascontiguousarray(scene.edge_dofs, dtype=np.int64),
            edge_pos=np.ascontiguousarray(scene._edge_pos, dtype=np.int64),
            node_hess=np.ascontiguousarray(scene._node_hess_full, dtype=np.int64),
            lin_nodes=np.concatenate([np.asarray(i, dtype=np.int64) for i in lin_nodes] or [np.zeros(0, np.int64)]),
            lin_ptr=np.cumsum([0] + [i.size for i in lin_nodes]).astype(np.int64),
            lin_axis=np.array([t.linear[0] for t in linear], dtype=np.int64),
            lin_sign=np.array([t.linear[1] for t in linear], dtype=float),
            lin_offset=np.array([t.linear[2] for t in linear], dtype=float),
            lin_dhat=np.array([t.dhat for t in linear], dtype=float),
            lin_coef=np.array([t._coef(scene.node_area) for t in linear], dtype=float).reshape(len(linear), n_nodes),
            ball_radius=np.array([b.radius for b, _ in balls], dtype=float),
            ball_dhat=np.array([b.dhat for b, _ in balls], dtype=float),
            ball_coef=np.array([b._edge_coef for b, _ in balls], dtype=float).reshape(len(balls), m.edges.shape[0]),
            ball_z0=np.array([b.z0 for b, _ in balls], dtype=float),
            ball_dof=np.array([s.start if b.bodies else -1 for b, s in balls], dtype=np.int64),
            ball_col=np.array([s.start - scene.n_node_dofs if b.bodies else -1 for b, s in balls], dtype=np.int64),
            ball_weight=np.array([-b.mass * b.gravity if b.bodies else 0.0 for b, _ in balls], dtype=float),
        )
        slots = [len(linear) + i if ball else i for ball, i in kinds]      # every node term is a contact here
        return cls(scene, plan, tuple(0.5 * t.permittivity / t.thickness ** 2 for t in electric),
                   bool(scene.edge_terms), slots)

    def _loads(self, loads) -> tuple:
        pressure = float(loads["pressure"]) if self._pressure else 0.0
        a_el = sum(c * float(loads["voltage"]) ** 2 for c in self._electric)
        return pressure, a_el

    def assemble(self, q, loads, inertia=None, anchor=None, momentum=None):
        """Energy, residual (n_free,), lower band (b + 1, n_band), border (k, n_band), corner (k, k)
        and rounding floor of the incremental potential at q (the scene's own without ``inertia``):
        the kernel's assembly, exposed for the tests that compare it with ``Scene.evaluate``."""
        n_free = self.plan.free.size
        inertia = np.zeros(n_free) if inertia is None else inertia
        anchor = q if anchor is None else anchor
        momentum = np.zeros(n_free) if momentum is None else momentum
        return assemble(q, self.plan, *self._loads(loads), inertia, anchor, momentum, 2)

    def measures_many(self, Q, loads: list) -> tuple:
        """Potential energy [J], volume [m^3] and smallest contact gap [m] of every state (rows of Q,
        each with its loads), each (T,), and the contact report's columns ``<name>_force`` [N] and
        ``<name>_gap`` [m]: what ``Scene.energy``, ``Scene.volume``, :meth:`min_gap` and
        :func:`snapmem.model.contact.contact_report` give, in one compiled call."""
        coefficients = np.array([self._loads(each) for each in loads], dtype=float).reshape(-1, 2)   # (pressure, a_el)
        energy, volume, forces, gaps = frames_measures(np.ascontiguousarray(Q, dtype=float), self.plan,
                                                       coefficients[:, 0].copy(), coefficients[:, 1].copy())
        columns = {}
        for name, i in self._contacts:
            columns[f"{name}_force"] = forces[:, i]
            columns[f"{name}_gap"] = gaps[:, i]
        smallest = gaps.min(axis=1) if gaps.shape[1] else np.full(len(Q), np.inf)
        return energy, volume, smallest, columns

    def min_gap(self, q) -> float:
        """Smallest gap of all contacts at q [m] (inf without contact)."""
        gaps = contact_gaps(q, self.plan)
        return float(gaps.min()) if gaps.size else np.inf

    def solve(self, anchor, velocity, h, loads, fallback, mass, damping, tol, size, options):
        """The time step of ``snapmem.dynamics.driver._Stepper.solve`` (which documents it): Newton on the
        incremental potential of step h from (anchor, velocity), with ``mass`` and ``damping`` on
        the free degrees of freedom, from the guess anchor + h velocity (``fallback``, the present
        state, if the guess is outside the domain). (y, NewtonReport), or None to hand the step
        back to the general path."""
        pressure, a_el = self._loads(loads)
        y, status, iterations, cuts, norm = time_step(
            anchor, velocity, h, mass, damping, fallback, self.plan, pressure, a_el, tol, size,
            options.max_iterations, options.max_cuts)
        if status == HANDED_BACK:
            return None
        return y, NewtonReport(status == 0, int(iterations), float(norm), REASONS[status], int(cuts))


# ----------------------------------------------------------------------------------------------
# kernels
@njit(cache=True, nogil=True)
def _law_density(lam1, lam2, kind, params):
    """The law's (w, w1, w2, w11, w12, w22), each (E,): snapmem.model.materials' laws (which document them)."""
    if kind == LINEAR:
        return linear_law_density(lam1, lam2, params[0], params[1])
    mu, jlim = params[0], params[1]                     # Gent: W = -(mu Jlim / 2) ln(1 - (I1 - 3) / Jlim)
    n = lam1.size
    w, W1, W11, zero = np.empty(n), np.empty(n), np.empty(n), np.zeros(n)
    for e in range(n):
        a2, b2 = lam1[e] * lam1[e], lam2[e] * lam2[e]
        s = 1.0 - (a2 + b2 + 1.0 / (a2 * b2) - 3.0) / jlim
        w[e] = -0.5 * mu * jlim * np.log(s)
        W1[e] = 0.5 * mu / s
        W11[e] = W1[e] / (s * jlim)
    w1, w2, w11, w12, w22 = invariant_chain(lam1, lam2, W1, zero, W11, zero, zero)
    return w, w1, w2, w11, w12, w22


@njit(cache=True, nogil=True)
def assemble(q, P, pressure, a_el, inertia, anchor, momentum, order):
    """The step's incremental potential Pi(q) + (1/2) d^T diag(inertia) d - momentum . d, d = (q -
    anchor) on the free degrees of freedom: (energy, residual, lower, border, corner, floor); the
    band, border and corner only at ``order`` 2 (zeros below). Energy inf if a contact gap is not positive.

    The same terms as ``Scene.evaluate`` (which documents them) for the covered term types.
    """
    lam1, lam2 = edge_stretches(q, P.edges, P.inv_length, P.inv_mid_radius)
    w, w1, w2, w11, w12, w22 = _law_density(lam1, lam2, P.law, P.law_params)
    if a_el != 0.0:                       # -a lam1^2 lam2^2 (snapmem.model.terms.Electric)
        for e in range(w.size):
            l1, l2 = lam1[e], lam2[e]
            w[e] -= a_el * l1 * l1 * l2 * l2
            w1[e] -= 2.0 * a_el * l1 * l2 * l2
            w2[e] -= 2.0 * a_el * l1 * l1 * l2
            w11[e] -= 2.0 * a_el * l2 * l2
            w12[e] -= 4.0 * a_el * l1 * l2
            w22[e] -= 2.0 * a_el * l1 * l1
    energy = 0.0
    for e in range(w.size):
        energy += P.weight[e] * w[e]
    gradient, band, volume, force = edge_assembly(q, P.edges, P.inv_length, P.inv_mid_radius, P.weight, w1, w2, w11,
                                                  w12, w22, pressure, P.hess_index, P.band_size, order)
    energy -= pressure * volume
    k, nb = P.n_bodies, P.n_band
    border = np.zeros((k, nb))
    corner = np.zeros((k, k))
    x = q[: P.n_node_dofs].reshape(-1, 2)
    for c in range(P.lin_axis.size):                   # rod, shell, plane: node barriers
        nodes = P.lin_nodes[P.lin_ptr[c]: P.lin_ptr[c + 1]]
        e_c, near, g, h = linear_barrier(x, nodes, P.lin_axis[c], P.lin_sign[c], P.lin_offset[c], P.lin_coef[c],
                                         P.lin_dhat[c], order)
        energy += e_c
        for m in range(near.size):
            i = near[m]
            gradient[2 * i] += g[m, 0]
            gradient[2 * i + 1] += g[m, 1]
            for a in range(2 if order >= 2 else 0):
                for b in range(2):
                    band[P.node_hess[i, a, b]] += h[m, a, b]
    n_edges = P.edges.shape[0]
    for c in range(P.ball_radius.size):                # balls: edge barriers, weight, border
        dof, col = P.ball_dof[c], P.ball_col[c]
        body = dof >= 0
        zc = q[dof] if body else P.ball_z0[c]
        e_c, which, g, h = ball_edge_barrier(x, P.edges, zc, P.ball_radius[c], P.ball_dhat[c], P.ball_coef[c], body,
                                             order)
        energy += e_c
        if body:
            energy += P.ball_weight[c] * zc
            gradient[dof] += P.ball_weight[c]
        for m in range(which.size):
            ed = which[m]
            for a in range(4):
                gradient[P.edge_dofs[ed, a]] += g[m, a]
            if body:
                gradient[dof] += g[m, 4]
            if order < 2:
                continue
            for a in range(4):
                for b in range(4):
                    band[P.hess_index[(4 * a + b) * n_edges + ed]] += h[a, b, m]
            if body:
                for a in range(4):
                    p = P.edge_pos[ed, a]
                    if p >= 0:
                        border[col, p] += h[a, 4, m]
                corner[col, col] += h[4, 4, m]
    free = P.free
    n_free = free.size
    residual = np.empty(n_free)
    for i in range(n_free):
        d = q[free[i]] - anchor[free[i]]
        residual[i] = gradient[free[i]] + inertia[i] * d - momentum[i]
        energy += 0.5 * inertia[i] * d * d - momentum[i] * d
    if order < 2:
        return energy, residual, np.zeros((nb, P.bandwidth + 1)).T, border, corner, 0.0
    lower = band[: P.band_size].reshape(nb, P.bandwidth + 1).T
    for i in range(nb):
        lower[0, i] += inertia[i]
    for i in range(k):
        corner[i, i] += inertia[nb + i]
    return energy, residual, lower, border, corner, 64.0 * np.finfo(np.float64).eps * (P.n_node_dofs // 2) * force


@njit(cache=True, nogil=True)
def _small_solve(S, g):
    """S^-1 g for the bodies' small k x k Schur complement: Gaussian elimination with partial
    pivoting (numba's np.linalg.solve costs 4 s of compilation for what is a 2 x 2 at most)."""
    k = g.size
    A, x = S.copy(), g.copy()
    for c in range(k):
        p = c
        for i in range(c + 1, k):
            if abs(A[i, c]) > abs(A[p, c]):
                p = i
        for j in range(k):
            A[c, j], A[p, j] = A[p, j], A[c, j]
        x[c], x[p] = x[p], x[c]
        for i in range(c + 1, k):
            f = A[i, c] / A[c, c]
            for j in range(c, k):
                A[i, j] -= f * A[c, j]
            x[i] -= f * x[c]
    for c in range(k - 1, -1, -1):
        for j in range(c + 1, k):
            x[c] -= A[c, j] * x[j]
        x[c] /= A[c, c]
    return x


@njit(cache=True, nogil=True)
def _eliminate(F, border, Z, S, rhs):
    """Block elimination of [[A, B], [B^T, C]] x = rhs with A = L D L^T (factors F), Z = A^-1 B, S the Schur."""
    nb, k = F.shape[0], border.shape[0]
    x = rhs.copy()
    _ldlt_solve_vector(F, x[:nb])
    if k == 0:
        return x
    g = np.empty(k)
    for a in range(k):
        g[a] = rhs[nb + a]
        for i in range(nb):
            g[a] -= border[a, i] * x[i]
    mu = g / S[0, 0] if k == 1 else _small_solve(S, g)
    for a in range(k):
        for i in range(nb):
            x[i] -= Z[i, a] * mu[a]
        x[nb + a] = mu[a]
    return x


@njit(cache=True, nogil=True)
def bordered_solve(lower, border, corner, rhs):
    """Solve [[A, B], [B^T, C]] x = rhs (A the band ``lower``, B = border^T): (x, ok), ok False for a
    tangent the LDL^T cannot take (zero pivot, growth beyond the limit of snapmem.kernels.banded) or a
    singular Schur complement.

    Block elimination, with A^-1 B and A^-1 rhs in one pass over the factors. The general path
    (snapmem.kernels.banded.BorderedLU) always adds a step of iterative refinement, which continuation
    needs at a fold, where A is singular and S = C - B^T A^-1 B is a small difference of large
    terms. Here it is added only where S shows that cancellation (|S| below 1e-6 of its terms):
    in a time step A includes M / h^2 and the LDL^T's growth is bounded, and without cancellation
    block elimination is as accurate as the factors. The profile put the refinement at a third of
    the solve.
    """
    nb, k = lower.shape[1], border.shape[0]
    F, negative, zero, growth = band_ldlt(lower, lower.shape[0] - 1)
    if zero > 0 or growth > LDLT_GROWTH_LIMIT:
        return rhs, False
    W = np.empty((nb, k + 1))
    for i in range(nb):
        for a in range(k):
            W[i, a] = border[a, i]
        W[i, k] = rhs[i]
    band_ldlt_solve(F, W)                             # [Z | y] = A^-1 [B | rhs_band]
    x = np.empty(nb + k)
    if k == 0:
        x[:] = W[:, 0]
        return x, True
    Z = np.ascontiguousarray(W[:, :k])
    S = corner.copy()
    terms = np.abs(corner)
    g = rhs[nb:].copy()
    for a in range(k):
        for i in range(nb):
            g[a] -= border[a, i] * W[i, k]
        for b in range(k):
            t = 0.0
            for i in range(nb):
                t += border[a, i] * Z[i, b]
            S[a, b] -= t
            terms[a, b] += abs(t)
            if not np.isfinite(S[a, b]):
                return rhs, False
    if k == 1 and S[0, 0] == 0.0:
        return rhs, False
    mu = g / S[0, 0] if k == 1 else _small_solve(S, g)
    for i in range(nb):
        t = W[i, k]
        for a in range(k):
            t -= Z[i, a] * mu[a]
        x[i] = t
    x[nb:] = mu
    refine = False
    for a in range(k):
        refine |= abs(S[a, a]) < 1e-6 * terms[a, a]
    if not refine:
        return x, True
    r = rhs.copy()                                    # cancellation: one refinement step, r = rhs - M x
    Ax = band_matvec(lower, np.ascontiguousarray(x[:nb]).reshape(nb, 1))
    for i in range(nb):
        r[i] -= Ax[i, 0]
        for a in range(k):
            r[i] -= border[a, i] * x[nb + a]
    for a in range(k):
        for i in range(nb):
            r[nb + a] -= border[a, i] * x[i]
        for b in range(k):
            r[nb + a] -= corner[a, b] * x[nb + b]
    return x + _eliminate(F, border, Z, S, r), True


@njit(cache=True, nogil=True)
def contact_gaps(q, P):
    """Smallest gap of every contact, linear ones first, then balls, shape (L + B,) [m]."""
    x = q[: P.n_node_dofs].reshape(-1, 2)
    n_lin = P.lin_axis.size
    gaps = np.empty(n_lin + P.ball_radius.size)
    for c in range(n_lin):
        nodes = P.lin_nodes[P.lin_ptr[c]: P.lin_ptr[c + 1]]
        gaps[c] = linear_min_gap(x, nodes, P.lin_axis[c], P.lin_sign[c], P.lin_offset[c])
    for c in range(P.ball_radius.size):
        zc = q[P.ball_dof[c]] if P.ball_dof[c] >= 0 else P.ball_z0[c]
        gaps[n_lin + c] = np.min(ball_edge_gaps(x, P.edges, zc, P.ball_radius[c]))
    return gaps


@njit(cache=True, nogil=True)
def _state_ok(q, P):
    """q finite, free radii positive, no edge collapsed, inside the law's domain (Gent's lock):
    the domain apart from the contacts."""
    if state_check(q, P.radius_dofs) != -1:
        return False
    for e in range(P.edges.shape[0]):
        a, b = P.edges[e, 0], P.edges[e, 1]
        if q[2 * a] == q[2 * b] and q[2 * a + 1] == q[2 * b + 1]:
            return False
    if P.law == GENT:
        lam1, lam2 = edge_stretches(q, P.edges, P.inv_length, P.inv_mid_radius)
        for e in range(lam1.size):
            a2, b2 = lam1[e] * lam1[e], lam2[e] * lam2[e]
            if not (lam1[e] > 0.0 and lam2[e] > 0.0 and a2 + b2 + 1.0 / (a2 * b2) - 3.0 < P.law_params[1]):
                return False
    return True


@njit(cache=True, nogil=True)
def admissible(q, P):
    """Whether q is inside the model's domain (Scene.inadmissible is None) for the covered terms."""
    if not _state_ok(q, P):
        return False
    gaps = contact_gaps(q, P)
    return gaps.size == 0 or np.min(gaps) > 0.0


@njit(cache=True, nogil=True)
def frame_measures(q, P, pressure, a_el):
    """What a recorded frame needs at q: (potential energy [J], volume [m^3], total normal force [N]
    and smallest gap [m] of every contact, linear ones first, then balls), as Scene.energy,
    Scene.volume and snapmem.model.contact.contact_report give them."""
    n_free = P.free.size
    zeros = np.zeros(n_free)
    energy = assemble(q, P, pressure, a_el, zeros, q, zeros, 1)[0]
    volume = 0.0
    for e in range(P.edges.shape[0]):
        a, b = P.edges[e, 0], P.edges[e, 1]
        ra, rb = q[2 * a], q[2 * b]
        volume += np.pi / 3.0 * (ra * ra + ra * rb + rb * rb) * (q[2 * b + 1] - q[2 * a + 1])
    x = q[: P.n_node_dofs].reshape(-1, 2)
    n_lin = P.lin_axis.size
    forces = np.zeros(n_lin + P.ball_radius.size)
    for c in range(n_lin):
        dhat = P.lin_dhat[c]
        for k in range(P.lin_ptr[c], P.lin_ptr[c + 1]):
            i = P.lin_nodes[k]
            forces[c] += P.lin_coef[c, i] * _barrier_slope(P.lin_sign[c] * x[i, P.lin_axis[c]] + P.lin_offset[c], dhat)
    for c in range(P.ball_radius.size):
        zc = q[P.ball_dof[c]] if P.ball_dof[c] >= 0 else P.ball_z0[c]
        d = ball_edge_gaps(x, P.edges, zc, P.ball_radius[c])
        for e in range(d.size):
            forces[n_lin + c] += P.ball_coef[c, e] * _barrier_slope(d[e], P.ball_dhat[c])
    return energy, volume, forces, contact_gaps(q, P)


@njit(cache=True, nogil=True)
def frames_measures(Q, P, pressure, a_el):
    """:func:`frame_measures` of every row of Q (with its pressure and electric coefficient):
    energies (T,), volumes (T,), forces (T, C), gaps (T, C)."""
    T = Q.shape[0]
    n_contacts = P.lin_axis.size + P.ball_radius.size
    energy, volume = np.empty(T), np.empty(T)
    forces, gaps = np.empty((T, n_contacts)), np.empty((T, n_contacts))
    for t in range(T):
        energy[t], volume[t], forces[t], gaps[t] = frame_measures(Q[t], P, pressure[t], a_el[t])
    return energy, volume, forces, gaps


@njit(cache=True, nogil=True)
def _barrier_slope(d, dhat):
    """|b'(d)| of the IPC barrier (snapmem.model.contact.barrier): 0 beyond dhat."""
    if d >= dhat:
        return 0.0
    e = d - dhat
    return abs(-2.0 * e * np.log(d / dhat) - e * e / d)


@njit(cache=True, nogil=True)
def max_step(q, dq, P):
    """Scene.max_step for the covered terms: radii, linear gaps and balls (nodes, then edges clear)."""
    alpha = radius_max_step(q, dq, P.n_node_dofs, FRACTION_TO_BOUNDARY)
    x, dx = q[: P.n_node_dofs].reshape(-1, 2), dq[: P.n_node_dofs].reshape(-1, 2)
    for c in range(P.lin_axis.size):
        nodes = P.lin_nodes[P.lin_ptr[c]: P.lin_ptr[c + 1]]
        alpha = min(alpha, linear_max_step(x, dx, nodes, P.lin_axis[c], P.lin_sign[c], P.lin_offset[c],
                                           FRACTION_TO_BOUNDARY))
    for c in range(P.ball_radius.size):
        body = P.ball_dof[c] >= 0
        zc = q[P.ball_dof[c]] if body else P.ball_z0[c]
        dzc = dq[P.ball_dof[c]] if body else 0.0
        radius = P.ball_radius[c]
        a = ball_node_max_step(x, dx, zc, dzc, radius, FRACTION_TO_BOUNDARY)
        floor = (1.0 - FRACTION_TO_BOUNDARY) * min(ball_min_gap(x, dx, 0.0, P.edges, zc, dzc, radius), P.ball_dhat[c])
        for _ in range(40):                            # halve until every edge keeps 10% of its gap
            if ball_min_gap(x, dx, a, P.edges, zc, dzc, radius) > floor:
                break
            a *= 0.5
        alpha = min(alpha, a)
    return alpha


@njit(cache=True, nogil=True)
def _norm(r):
    return np.max(np.abs(r)) if r.size else 0.0


@njit(cache=True, nogil=True)
def time_step(anchor, velocity, h, mass, damping, fallback, P, pressure, a_el, tol, size, max_iterations, max_cuts):
    """The step's inertia M / h^2 + C / h, momentum M v / h and guess anchor + h v (on the free
    degrees of freedom; ``mass``, ``damping`` there), the tolerance kept above the inertia term's
    rounding floor 1e3 eps max(inertia) ``size``, then :func:`step_newton`."""
    free = P.free
    n = free.size
    inertia, momentum = np.empty(n), np.empty(n)
    for i in range(n):
        inertia[i] = mass[i] / (h * h) + damping[i] / h
        momentum[i] = mass[i] * velocity[free[i]] / h
    tol = max(tol, 1e3 * np.finfo(np.float64).eps * np.max(inertia) * size)
    return step_newton(anchor + h * velocity, fallback, anchor, P, pressure, a_el, inertia, momentum, tol,
                       max_iterations, max_cuts)


@njit(cache=True, nogil=True)
def step_newton(guess, fallback, anchor, P, pressure, a_el, inertia, momentum, tol, max_iterations, max_cuts):
    """Damped Newton on the step's incremental potential: snapmem.solvers.newton.newton with merit='energy'
    (which documents every rule here), in one call. Returns (y, status, iterations, cuts, norm),
    status an index into REASONS, or HANDED_BACK."""
    if admissible(guess, P):
        q = guess.copy()
    else:
        q = fallback.copy()
        if not admissible(q, P):
            return q, 6, 0, 0, np.nan
    energy, residual, lower, border, corner, floor = assemble(q, P, pressure, a_el, inertia, anchor, momentum, 2)
    norm = _norm(residual)
    free = P.free
    last_step = np.inf
    iterations = cuts = 0
    status = 1
    dq = np.zeros(q.size)
    for _ in range(max_iterations):
        floor_tol = max(tol, floor)
        if norm <= floor_tol or (norm <= 1e3 * floor_tol and last_step <= 1e-10 * np.max(np.abs(q))):
            status = 0
            break
        if not np.isfinite(norm):
            status = 5
            break
        dx, ok = bordered_solve(lower, border, corner, -residual)
        if not ok:
            return q, HANDED_BACK, iterations, cuts, norm
        for i in range(free.size):
            dq[free[i]] = dx[i]
        alpha = min(1.0, max_step(q, dq, P))
        slope = min(0.0, residual @ dx)
        iterations += 1
        accepted = inside = False
        trial = q
        e_t, r_t, lo_t, bo_t, co_t, fl_t, n_t = energy, residual, lower, border, corner, floor, norm
        for _cut in range(max_cuts + 1):
            trial = q + alpha * dq
            inside = _state_ok(trial, P)         # the contacts' gaps: the barriers' energy is inf at a gap <= 0
            if inside:
                e_t, r_t, lo_t, bo_t, co_t, fl_t = assemble(trial, P, pressure, a_el, inertia, anchor, momentum, 2)
                inside = e_t < np.inf
                n_t = _norm(r_t)
                if np.isfinite(e_t) and np.isfinite(n_t) and (e_t <= energy + 1e-4 * alpha * slope or n_t <= 0.5 * norm):
                    accepted = True
                    break
            alpha *= 0.5
            cuts += 1
        if not accepted:
            status = 2 if inside else 3
            break
        q, energy, residual, lower, border, corner, floor = trial, e_t, r_t, lo_t, bo_t, co_t, fl_t
        norm = n_t
        last_step = alpha * np.max(np.abs(dx)) if dx.size else 0.0
    if status != 0 and norm <= max(tol, floor):
        status = 0
    return q, status, iterations, cuts, norm
