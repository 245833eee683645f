"""The compiled time step's assembly: the incremental potential of a step with its residual and
bordered band tangent, the domain checks, the contact gaps and the step limit, for the terms a
scene declared (:class:`Plan`, built by :meth:`snapmem.dynamics.compiled_step.CompiledStep.of`).

Every formula here is a kernel of snapmem.kernels (the fused membrane assembly, the laws'
densities, the contact barriers), the same ones ``Scene.evaluate`` uses.
"""

from __future__ import annotations

from collections import namedtuple

import numpy as np
from snapmem._lazy import njit

from snapmem.kernels.assembly import edge_assembly, edge_stretches, radius_max_step, residual_floor, state_check
from snapmem.kernels.contact import (ball_edge_barrier, ball_edge_gaps, ball_min_gap, ball_node_max_step,
                                    linear_barrier, linear_max_step, linear_min_gap)
from snapmem.kernels.laws import LAW_LINEAR, electric_density, law_admissible, law_density
from snapmem.model.contact import FRACTION_TO_BOUNDARY

# Everything the kernels need of a scene, packed once (numba takes named tuples of arrays).
Plan = namedtuple("Plan", [
    "edges", "inv_length", "inv_mid_radius", "weight", "law_kind", "law_params",   # membrane; law: LAW_*
    "hess_index", "band_size", "n_band", "bandwidth", "free", "radius_dofs", "n_node_dofs", "n_bodies",
    "edge_dofs", "edge_pos", "node_hess",                                 # scatter maps of node and edge terms
    "lin_nodes", "lin_ptr", "lin_axis", "lin_sign", "lin_offset", "lin_dhat", "lin_coef",   # rod, shell, plane
    "ball_radius", "ball_dhat", "ball_coef", "ball_z0", "ball_dof", "ball_col", "ball_weight",  # balls
])


@njit(cache=True, nogil=True)
def assemble(q, P, pressure, a_el, inertia, anchor, momentum, order):
    """The step's incremental potential Pi(q) + (1/2) d^T diag(inertia) d - momentum . d, d = (q -
    anchor) on the free degrees of freedom: (energy, residual, lower, border, corner, floor); the
    band, border and corner only at ``order`` 2 (zeros below). Energy inf if a contact gap is not positive.

    The same terms as ``Scene.evaluate`` (which documents them) for the declared terms, by the
    same kernels and formulas.
    """
    lam1, lam2 = edge_stretches(q, P.edges, P.inv_length, P.inv_mid_radius)
    w, w1, w2, w11, w12, w22 = law_density(lam1, lam2, P.law_kind, P.law_params)
    if a_el != 0.0:                       # the electric term(s), -a lam1^2 lam2^2
        for e in range(w.size):
            ew, e1, e2, e11, e12, e22 = electric_density(lam1[e], lam2[e], a_el)
            w[e] += ew
            w1[e] += e1
            w2[e] += e2
            w11[e] += e11
            w12[e] += e12
            w22[e] += e22
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
    return energy, residual, lower, border, corner, residual_floor(P.n_node_dofs // 2, force)


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
def state_ok(q, P):
    """q finite, free radii positive, no edge collapsed, inside the law's domain (Gent's lock):
    the domain apart from the contacts."""
    if state_check(q, P.radius_dofs) != -1:
        return False
    for e in range(P.edges.shape[0]):
        a, b = P.edges[e, 0], P.edges[e, 1]
        if q[2 * a] == q[2 * b] and q[2 * a + 1] == q[2 * b + 1]:
            return False
    if P.law_kind == LAW_LINEAR:
        return True
    lam1, lam2 = edge_stretches(q, P.edges, P.inv_length, P.inv_mid_radius)
    return law_admissible(lam1, lam2, P.law_kind, P.law_params)


@njit(cache=True, nogil=True)
def admissible(q, P):
    """Whether q is inside the model's domain (Scene.inadmissible is None) for the declared terms."""
    if not state_ok(q, P):
        return False
    gaps = contact_gaps(q, P)
    return gaps.size == 0 or np.min(gaps) > 0.0


@njit(cache=True, nogil=True)
def max_step(q, dq, P):
    """Scene.max_step for the declared terms: radii, linear gaps and balls (nodes, then edges clear)."""
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
