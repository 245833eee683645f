"""The compiled time step's assembly: the incremental potential of a step with its residual and
bordered band tangent, the domain checks, the contact gaps and the step limit, for the terms a
scene declared (:class:`Plan`, built by :meth:`snapmem.dynamics.compiled_step.CompiledStep.of`).

Every formula here is a kernel of snapmem.kernels (the fused membrane assembly, the laws'
densities, the contact barriers), the same ones ``Scene.evaluate`` uses.

Compiled for the terms a scene has: besides the plan ``P``, each kernel takes ``general_law``
(a :data:`GeneralLaw`, or None for LAW_LINEAR), ``linear`` (:data:`LinearContacts` or None) and
``balls`` (:data:`Balls` or None). numba prunes the branches of an argument that is None before
typing, so the code of absent terms is never compiled (a scene without contact compiles no
barrier), and each combination is its own specialisation (kept in numba's cache like any other).
Small tuples, not one plan of every array: numba passes a tuple's arrays as separate arguments.

The assembly's ``order`` is passed as :data:`GRADIENT` or :data:`TANGENT`, numpy integers: a
Python int constant would make numba compile a kernel once per value (literal argument types),
for no gain (the branches on ``order`` are not pruned).
"""

from __future__ import annotations

from collections import namedtuple

import numpy as np
from snapmem._lazy import njit

from snapmem.kernels.assembly import (edge_assembly, edge_stretches, linear_law_density, radius_max_step,
                                     residual_floor, state_check)
from snapmem.kernels.contact import (ball_edge_barrier, ball_edge_gaps, ball_min_gap, ball_node_max_step,
                                    linear_barrier, linear_max_step, linear_min_gap)
from snapmem.kernels.laws import electric_density, law_admissible, law_density, prestretch_chain
from snapmem.kernels.viscous import anchor_internal, edge_condensed, log_to_stretch, update_internal
from snapmem.model.contact import FRACTION_TO_BOUNDARY

#: The assembly's order: energy and residual (GRADIENT), and the tangent (TANGENT).
GRADIENT, TANGENT = np.int64(1), np.int64(2)

# Everything the kernels need of a scene, packed once (numba takes named tuples of arrays): the
# membrane, its law and the scatter maps (Plan), and each kind of term the scene may not have.
Plan = namedtuple("Plan", [
    "edges", "inv_length", "inv_mid_radius", "weight", "law_kind", "law_params",   # membrane; law: LAW_*
    "law_stretch",                                  # the law's prestretches (2,), None for (1, 1)
    "hess_index", "band_size", "n_band", "bandwidth", "free", "radius_dofs", "n_node_dofs", "n_bodies",
    "edge_dofs", "edge_pos", "node_hess",                                 # scatter maps of node and edge terms
])
#: A law other than LAW_LINEAR (Gent): its kind and parameters, as in the Plan.
GeneralLaw = namedtuple("GeneralLaw", ["law_kind", "law_params"])
#: The linear-gap contacts (rod, shell, plane): contact c holds nodes lin_nodes[lin_ptr[c]:lin_ptr[c + 1]].
LinearContacts = namedtuple("LinearContacts", ["lin_nodes", "lin_ptr", "lin_axis", "lin_sign", "lin_offset",
                                               "lin_dhat", "lin_coef"])
#: Viscous networks: moduli, Gent locks (inf: neo-Hookean), c = eta / h of the open step (0: none,
#: the internal stretches held at zeta_hat), the step's anchor zeta_hat (K, 2, E) and the local
#: solves' warm start (K, 2, E), updated in place by every assembly (after it: zeta* there).
#: zeta_warm_exp (K, 2, E) = exp(-2 zeta_warm), kept with it (the local solves need no exponential).
Viscous = namedtuple("Viscous", ["visc_mu", "visc_jlim", "visc_c", "zeta_hat", "zeta_warm", "zeta_warm_exp"])
#: A time step of the networks' internal log stretches, for the compiled step to open and close
#: itself (snapmem.dynamics.stepper._InternalState): the state zeta_n and history zeta_{n-1}
#: (K, 2, E; zeta_n again without history), the scheme's ``coefficients`` (h, c_now, c_previous,
#: n_star, n_now, n_previous, dt) (snapmem.dynamics.stepper.scheme_coefficients and the step dt
#: [s]), the viscosities eta_k [Pa s], and the outputs: ``zeta_new`` (K, 2, E) zeta_{n+1} and
#: ``dissipated`` (1,) the step's dissipation [J], written when the solve converges.
NetworkStep = namedtuple("NetworkStep", ["zeta", "zeta_previous", "coefficients", "viscosities", "zeta_new",
                                         "dissipated"])
#: The balls (edge contact), with the degree of freedom and border column of a ball's body (-1: fixed).
Balls = namedtuple("Balls", ["ball_radius", "ball_dhat", "ball_coef", "ball_z0", "ball_dof", "ball_col",
                             "ball_weight"])


#: The njit options of a kernel that only compiled code calls (the compiled time step's, here and
#: in snapmem.dynamics.compiled_chambers): numba then makes no CPython or C entry point for it,
#: whose lowering and machine code cost ~50 ms a kernel at first use (issue 17). numba's own
#: dispatcher would crash if Python called it; snapmem._lazy.Kernel runs its Python instead
#: (such a kernel's docstring says "compiled code only"). Kernels of snapmem.kernels, which
#: kernels running as Python call on first use, never take these options.
COMPILED_ONLY = dict(cache=True, nogil=True, no_cpython_wrapper=True, no_cfunc_wrapper=True)
#: A compiled-only kernel whose body numba inlines into its callers' (no library, typing, LLVM
#: pass or machine code of its own at first use, issue 17). Only for a kernel with no branch on an
#: argument that may be None: numba prunes those in a kernel compiled for its arguments, not in
#: an inlined body.
INLINED = dict(COMPILED_ONLY, inline="always")


@njit(**INLINED)
def membrane_density(lam1, lam2, P, general_law, viscous, a_el):
    """The membrane's density per edge (:func:`mounted_density` with the Plan's law), (w, w1, w2,
    w11, w12, w22, local solves ok): what the step's :func:`assemble` and the frames' measures
    (snapmem.dynamics.compiled_measures) both sum. Inlined (no branch of its own to prune).
    Compiled code only (COMPILED_ONLY)."""
    return mounted_density(lam1, lam2, P.law_params, P.law_stretch, general_law, viscous, a_el)


@njit(**INLINED)
def add_at_edge(e, w, w1, w2, w11, w12, w22, d, d1, d2, d11, d12, d22):
    """w[e] += d, w1[e] += d1, ...: one edge's part of a further term added to the density's six
    arrays (the networks', the electric term's). Compiled code only (COMPILED_ONLY)."""
    w[e] += d
    w1[e] += d1
    w2[e] += d2
    w11[e] += d11
    w12[e] += d12
    w22[e] += d22


@njit(**COMPILED_ONLY)
def mounted_density(lam1, lam2, law_params, law_stretch, general_law, viscous, a_el):
    """The membrane's density per edge at the mounted stretches (lam1, lam2): the law's (its
    prestretches ``law_stretch`` (lp1, lp2) applied; None: none, the Plan's for (1, 1)), plus the
    viscous networks' condensed one, plus the electric term(s) -a lam1^2 lam2^2 (``a_el``: the
    electric coefficient, 0 for none): (w, w1, w2, w11, w12, w22) each (E,), and whether every
    local flow-rule solve converged. The networks' solutions are left in ``viscous.zeta_warm``.
    ``general_law`` None: LAW_LINEAR with ``law_params``. The step's re-evaluation of zeta* at q
    calls it with ``a_el`` 0.

    One kernel, not the law, the networks and the electric term each their own: every kernel is
    a library of its own at first compilation (issue 17: about 0.4 s for the two it replaced).
    ``law_stretch``, ``general_law`` and ``viscous`` are arguments, so that numba prunes their
    code where they are None (it does not prune a tuple's field, nor an inline="always" kernel's
    branches). Compiled code only (COMPILED_ONLY)."""
    if law_stretch is None:
        l1, l2 = lam1, lam2
    else:
        l1, l2 = law_stretch[0] * lam1, law_stretch[1] * lam2
    if general_law is None:               # LAW_LINEAR: law_density's first branch
        w, w1, w2, w11, w12, w22 = linear_law_density(l1, l2, law_params[0], law_params[1])
    else:
        w, w1, w2, w11, w12, w22 = law_density(l1, l2, general_law.law_kind, general_law.law_params)
    if law_stretch is not None:
        w, w1, w2, w11, w12, w22 = prestretch_chain(w, w1, w2, w11, w12, w22, law_stretch[0], law_stretch[1])
    ok = True
    if viscous is not None:                  # per edge and network, numbers only (no arrays to allocate)
        for e in range(lam1.size):
            t0 = t1 = t2 = t11 = t12 = t22 = 0.0
            for k in range(viscous.visc_mu.size):
                c, mu, jlim = viscous.visc_c[k], viscous.visc_mu[k], viscous.visc_jlim[k]
                h1, h2 = viscous.zeta_hat[k, 0, e], viscous.zeta_hat[k, 1, e]
                z1, z2, u1, u2, done, p0, p1, p2, p11, p12, p22 = edge_condensed(
                    lam1[e], lam2[e], viscous.zeta_warm[k, 0, e], viscous.zeta_warm[k, 1, e],
                    viscous.zeta_warm_exp[k, 0, e], viscous.zeta_warm_exp[k, 1, e], h1, h2, mu, jlim, c)
                ok = ok and done
                if c > 0.0:
                    viscous.zeta_warm[k, 0, e] = z1
                    viscous.zeta_warm[k, 1, e] = z2
                    viscous.zeta_warm_exp[k, 0, e] = u1
                    viscous.zeta_warm_exp[k, 1, e] = u2
                t0 += p0
                t1 += p1
                t2 += p2
                t11 += p11
                t12 += p12
                t22 += p22
            v0, v1, v2, v11, v12, v22 = log_to_stretch(lam1[e], lam2[e], t0, t1, t2, t11, t12, t22)
            add_at_edge(e, w, w1, w2, w11, w12, w22, v0, v1, v2, v11, v12, v22)
    if a_el != 0.0:
        for e in range(w.size):
            ew, e1, e2, e11, e12, e22 = electric_density(lam1[e], lam2[e], a_el)
            add_at_edge(e, w, w1, w2, w11, w12, w22, ew, e1, e2, e11, e12, e22)
    return w, w1, w2, w11, w12, w22, ok


@njit(cache=True, nogil=True)
def start_networks(viscous):
    """The local solves' warm start at the step's anchor: zeta_warm = zeta_hat, zeta_warm_exp =
    exp(-2 zeta_hat) (before a step's first assembly)."""
    for k in range(viscous.zeta_hat.shape[0]):
        for i in range(2):
            for e in range(viscous.zeta_hat.shape[2]):
                viscous.zeta_warm[k, i, e] = viscous.zeta_hat[k, i, e]
                viscous.zeta_warm_exp[k, i, e] = np.exp(-2.0 * viscous.zeta_hat[k, i, e])


@njit(**COMPILED_ONLY)
def open_network_step(viscous, step):
    """Open the networks' step: the anchor zeta_hat = c_now zeta_n + c_previous zeta_{n-1} and c =
    eta / h (snapmem.kernels.viscous.anchor_internal, as the stepper's Python would).
    Compiled code only (COMPILED_ONLY)."""
    coefficients = step.coefficients
    anchor_internal(step.zeta, step.zeta_previous, coefficients[1], coefficients[2], viscous.zeta_hat)
    for k in range(viscous.visc_c.size):
        viscous.visc_c[k] = step.viscosities[k] / coefficients[0]


@njit(**COMPILED_ONLY)
def close_network_step(viscous, step, weight):
    """Close the networks' converged step from zeta* (``viscous.zeta_warm``): zeta_{n+1} into
    ``step.zeta_new`` and the step's dissipation into ``step.dissipated`` [J]
    (snapmem.kernels.viscous.update_internal). Compiled code only (COMPILED_ONLY)."""
    coefficients = step.coefficients
    step.dissipated[0] = update_internal(viscous.zeta_warm, step.zeta, step.zeta_previous, coefficients[3],
                                         coefficients[4], coefficients[5], viscous.zeta_hat, coefficients[0],
                                         coefficients[6], step.viscosities, weight, step.zeta_new)


@njit(**COMPILED_ONLY)
def assemble(q, P, general_law, linear, balls, viscous, pressure, a_el, inertia, anchor, momentum, order):
    """The step's incremental potential Pi(q) + (1/2) d^T diag(inertia) d - momentum . d, d = (q -
    anchor) on the free degrees of freedom: (energy, residual, lower, border, corner, floor); the
    band, border and corner only at ``order`` 2 (zeros below). Energy inf if a contact gap is not positive.

    The same terms as ``Scene.evaluate`` (which documents them) for the declared terms, by the
    same kernels and formulas; ``general_law``, ``linear``, ``balls``, ``viscous``: the terms or None
    (module docstring). Energy inf also where a local flow-rule solve of the networks fails.
     Compiled code only (COMPILED_ONLY)."""
    lam1, lam2 = edge_stretches(q, P.edges, P.inv_length, P.inv_mid_radius)
    w, w1, w2, w11, w12, w22, local_ok = membrane_density(lam1, lam2, P, general_law, viscous, a_el)
    energy = 0.0 if local_ok else np.inf
    for e in range(w.size):
        energy += P.weight[e] * w[e]
    gradient, band, volume, force = edge_assembly(q, P.edges, P.inv_length, P.inv_mid_radius, P.weight, w1, w2, w11,
                                                  w12, w22, pressure, P.hess_index, P.band_size, order)
    energy -= pressure * volume
    k, nb = P.n_bodies, P.n_band
    border = np.empty((k, nb))                 # zeros (as edge_assembly's: np.empty and a fill)
    border[:] = 0.0
    corner = np.empty((k, k))
    corner[:] = 0.0
    x = q[: P.n_node_dofs].reshape(-1, 2)
    barrier_rounding = 0.0                # as snapmem.model.contact.barrier_rounding (the rounding floor's)
    if linear is not None:
        for c in range(linear.lin_axis.size):              # rod, shell, plane: node barriers
            nodes = linear.lin_nodes[linear.lin_ptr[c]: linear.lin_ptr[c + 1]]
            e_c, near, g, h = linear_barrier(x, nodes, linear.lin_axis[c], linear.lin_sign[c], linear.lin_offset[c],
                                             linear.lin_coef[c], linear.lin_dhat[c], order)
            energy += e_c
            if order >= 2 and near.size:
                span = abs(linear.lin_offset[c])
                for m in range(near.size):
                    span = max(span, abs(x[near[m], linear.lin_axis[c]]))
                barrier_rounding = max(barrier_rounding, np.max(np.abs(h)) * span)
            for m in range(near.size):
                i = near[m]
                gradient[2 * i] += g[m, 0]
                gradient[2 * i + 1] += g[m, 1]
                for a in range(2 if order >= 2 else 0):
                    for b in range(2):
                        band[P.node_hess[i, a, b]] += h[m, a, b]
    if balls is not None:
        n_edges = P.edges.shape[0]
        for c in range(balls.ball_radius.size):            # balls: edge barriers, weight, border
            dof, col = balls.ball_dof[c], balls.ball_col[c]
            body = dof >= 0
            zc = q[dof] if body else balls.ball_z0[c]
            e_c, which, g, h = ball_edge_barrier(x, P.edges, zc, balls.ball_radius[c], balls.ball_dhat[c],
                                                 balls.ball_coef[c], body, order)
            energy += e_c
            if order >= 2 and which.size:
                span = abs(zc)
                for m in range(which.size):
                    for a in range(2):
                        node = P.edges[which[m], a]
                        span = max(span, abs(x[node, 0]), abs(x[node, 1]))
                barrier_rounding = max(barrier_rounding, np.max(np.abs(h)) * span)
            if body:
                energy += balls.ball_weight[c] * zc
                gradient[dof] += balls.ball_weight[c]
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
        lower = np.empty((nb, P.bandwidth + 1)).T
        lower[:] = 0.0
        return energy, residual, lower, border, corner, 0.0
    lower = band[: P.band_size].reshape(nb, P.bandwidth + 1).T
    for i in range(nb):
        lower[0, i] += inertia[i]
    for i in range(k):
        corner[i, i] += inertia[nb + i]
    return energy, residual, lower, border, corner, residual_floor(P.n_node_dofs // 2, force, barrier_rounding)


@njit(cache=True, nogil=True)
def assemble_entry(q, P, general_law, linear, balls, viscous, pressure, a_el, inertia, anchor, momentum, order):
    """:func:`assemble` for Python callers (CompiledStep.assemble, the tests): assemble itself,
    called by compiled code only, has no Python entry point."""
    return assemble(q, P, general_law, linear, balls, viscous, pressure, a_el, inertia, anchor, momentum, order)


@njit(cache=True, nogil=True)
def contact_gaps(q, P, linear, balls):
    """Smallest gap of every contact, linear ones first, then balls, shape (L + B,) [m]."""
    x = q[: P.n_node_dofs].reshape(-1, 2)
    n_lin = 0 if linear is None else linear.lin_axis.size
    n_balls = 0 if balls is None else balls.ball_radius.size
    gaps = np.empty(n_lin + n_balls)
    if linear is not None:
        for c in range(n_lin):
            nodes = linear.lin_nodes[linear.lin_ptr[c]: linear.lin_ptr[c + 1]]
            gaps[c] = linear_min_gap(x, nodes, linear.lin_axis[c], linear.lin_sign[c], linear.lin_offset[c])
    if balls is not None:
        for c in range(n_balls):
            zc = q[balls.ball_dof[c]] if balls.ball_dof[c] >= 0 else balls.ball_z0[c]
            gaps[n_lin + c] = np.min(ball_edge_gaps(x, P.edges, zc, balls.ball_radius[c]))
    return gaps


@njit(**COMPILED_ONLY)
def mounted_admissible(lam1, lam2, general_law, law_stretch):
    """Whether the mounted stretches (lam1, lam2), prestretched by ``law_stretch`` (None: none),
    are inside ``general_law``'s domain (snapmem.kernels.laws.law_admissible). Compiled code only (COMPILED_ONLY)."""
    if law_stretch is None:
        return law_admissible(lam1, lam2, general_law.law_kind, general_law.law_params)
    return law_admissible(law_stretch[0] * lam1, law_stretch[1] * lam2, general_law.law_kind, general_law.law_params)


@njit(**COMPILED_ONLY)
def state_ok(q, P, general_law):
    """q finite, free radii positive, no edge collapsed, inside the law's domain (Gent's lock):
    the domain apart from the contacts. Compiled code only (COMPILED_ONLY)."""
    if state_check(q, P.radius_dofs) != -1:
        return False
    for e in range(P.edges.shape[0]):
        a, b = P.edges[e, 0], P.edges[e, 1]
        if q[2 * a] == q[2 * b] and q[2 * a + 1] == q[2 * b + 1]:
            return False
    if general_law is None:                  # LAW_LINEAR: every positive stretch is inside
        return True
    lam1, lam2 = edge_stretches(q, P.edges, P.inv_length, P.inv_mid_radius)
    return mounted_admissible(lam1, lam2, general_law, P.law_stretch)


@njit(cache=True, nogil=True)
def admissible(q, P, general_law, linear, balls):
    """Whether q is inside the model's domain (Scene.inadmissible is None) for the declared terms."""
    if not state_ok(q, P, general_law):
        return False
    if linear is None and balls is None:
        return True
    gaps = contact_gaps(q, P, linear, balls)
    return gaps.size == 0 or np.min(gaps) > 0.0


@njit(**COMPILED_ONLY)
def max_step(q, dq, P, linear, balls):
    """Scene.max_step for the declared terms: radii, linear gaps and balls (nodes, then edges clear).
    Compiled code only (COMPILED_ONLY)."""
    alpha = radius_max_step(q, dq, P.n_node_dofs, FRACTION_TO_BOUNDARY)
    x, dx = q[: P.n_node_dofs].reshape(-1, 2), dq[: P.n_node_dofs].reshape(-1, 2)
    if linear is not None:
        for c in range(linear.lin_axis.size):
            nodes = linear.lin_nodes[linear.lin_ptr[c]: linear.lin_ptr[c + 1]]
            alpha = min(alpha, linear_max_step(x, dx, nodes, linear.lin_axis[c], linear.lin_sign[c],
                                               linear.lin_offset[c], FRACTION_TO_BOUNDARY))
    if balls is not None:
        for c in range(balls.ball_radius.size):
            body = balls.ball_dof[c] >= 0
            zc = q[balls.ball_dof[c]] if body else balls.ball_z0[c]
            dzc = dq[balls.ball_dof[c]] if body else 0.0
            radius = balls.ball_radius[c]
            a = ball_node_max_step(x, dx, zc, dzc, radius, FRACTION_TO_BOUNDARY)
            floor = (1.0 - FRACTION_TO_BOUNDARY) * min(ball_min_gap(x, dx, 0.0, P.edges, zc, dzc, radius),
                                                       balls.ball_dhat[c])
            for _ in range(40):                        # halve until every edge keeps 10% of its gap
                if ball_min_gap(x, dx, a, P.edges, zc, dzc, radius) > floor:
                    break
                a *= 0.5
            alpha = min(alpha, a)
    return alpha
