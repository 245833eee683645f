"""Compiled kernels of the membrane's assembly: invariants and their chain rule, the fused edge
assembly, stretches, scatter, domain checks and the volume gradient. Arrays in, arrays out."""

from __future__ import annotations

import numpy as np
from snapmem._lazy import njit, python_of
from snapmem.kernels.linalg import sum_in_order

_EPS = np.finfo(np.float64).eps


@njit(cache=True, nogil=True, inline="always")
def swept_volume(ra, rb, dz, scale):
    """The volume an edge sweeps about the axis, V_e = (pi/3)(r_a^2 + r_a r_b + r_b^2)(z_b - z_a)
    [m^3], with the parts of ``scale`` dV_e/d(r_a, z_a, r_b, z_b) = (ga dz, -s, gb dz, s):
    returns (V_e, c, s, ga, gb), c = scale pi/3 (the Hessian's entries are c dz, 2 c dz, +-ga, +-gb).

    The one formula of the swept volume: PressureWork.volume_local (numpy, through ``.py_func``),
    :func:`edge_assembly`, :func:`volume_gradient` and the compiled step's measures use it.
    """
    c0 = np.pi / 3.0
    s = ra * ra + ra * rb + rb * rb
    c = c0 * scale
    return c0 * s * dz, c, c * s, c * (2.0 * ra + rb), c * (ra + 2.0 * rb)


#: Newton's stall rule accepts a residual within this factor of max(tol, floor) once its steps are at the
#: rounding of q (snapmem.solvers.rules.converged; defined here because the floor below divides by it).
STALL_FACTOR = 1e3


@njit(cache=True, nogil=True, inline="always")
def residual_floor(n_nodes, force, barrier_rounding):
    """The residual's rounding floor [N], the one formula of it (``Scene.evaluate`` and the compiled
    step's assembly call it): 64 eps N ``force`` + eps ``barrier_rounding`` / STALL_FACTOR.

    The first part is the membrane's: nodal forces are sums of edge forces computed from coordinate
    differences (``force``, the largest edge force entry [N]; see snapmem.model.scene.Evaluation).

    The second is the contact barriers': a barrier's force is its stiffness times a gap computed
    from coordinates rounded to eps |x|, so it carries a noise of eps ``barrier_rounding``, the
    largest barrier Hessian entry [N/m] times the largest |coordinate| its gaps are computed from
    [m] (0 without an active barrier; :func:`snapmem.model.contact.barrier_rounding`). A barrier
    of 1e-7 of a 4 cm rod at kappa = 1e9 Pa is ~1e13 N/m stiff: ~1e-4 N of noise, far above
    Newton's tolerance. It enters divided by STALL_FACTOR, so a residual at that noise is accepted
    by the stall rule only, once Newton's steps are at the rounding of q: a state within
    STALL_FACTOR of the noise still gains from more steps (one more step takes such a gripper
    from 3e-2 N to 3e-5 N).
    """
    return 64.0 * _EPS * n_nodes * force + _EPS * barrier_rounding / STALL_FACTOR


@njit(cache=True, nogil=True, inline="always")
def _invariant_derivatives(l1, l2):
    """First and second derivatives of I1 and I2 in (lam1, lam2) at one edge (incompressible):
    (i1_1, i1_2, i1_11, i1_12, i1_22, i2_1, i2_2, i2_11, i2_12, i2_22)."""
    a2, b2 = l1 * l1, l2 * l2
    inv = 1.0 / (a2 * b2)
    return (2.0 * l1 - 2.0 * inv / l1, 2.0 * l2 - 2.0 * inv / l2,
            2.0 + 6.0 * inv / a2, 4.0 * inv / (l1 * l2), 2.0 + 6.0 * inv / b2,
            -2.0 / (a2 * l1) + 2.0 * l1 * b2, -2.0 / (b2 * l2) + 2.0 * a2 * l2,
            6.0 / (a2 * a2) + 2.0 * b2, 4.0 * l1 * l2, 6.0 / (b2 * b2) + 2.0 * a2)


@njit(cache=True, nogil=True)
def invariant_chain(lam1, lam2, W1, W2, W11, W12, W22):
    """Derivatives in (lam1, lam2) of W(I1, I2) from its derivatives in the invariants, per edge.

    The chain rule of :class:`snapmem.model.materials.InvariantLaw` (which documents it), fused into one
    pass over the edges. All arguments are arrays of shape (E,). Returns (w1, w2, w11, w12, w22).
    """
    n = lam1.size
    w1 = np.empty(n)
    w2 = np.empty(n)
    w11 = np.empty(n)
    w12 = np.empty(n)
    w22 = np.empty(n)
    for e in range(n):
        i1_1, i1_2, i1_11, i1_12, i1_22, i2_1, i2_2, i2_11, i2_12, i2_22 = _invariant_derivatives(lam1[e], lam2[e])
        A1, A2, A11, A12, A22 = W1[e], W2[e], W11[e], W12[e], W22[e]
        w1[e] = A1 * i1_1 + A2 * i2_1
        w2[e] = A1 * i1_2 + A2 * i2_2
        w11[e] = A1 * i1_11 + A2 * i2_11 + A11 * i1_1 * i1_1 + 2.0 * A12 * i1_1 * i2_1 + A22 * i2_1 * i2_1
        w12[e] = (A1 * i1_12 + A2 * i2_12 + A11 * i1_1 * i1_2
                  + A12 * (i1_1 * i2_2 + i2_1 * i1_2) + A22 * i2_1 * i2_2)
        w22[e] = A1 * i1_22 + A2 * i2_22 + A11 * i1_2 * i1_2 + 2.0 * A12 * i1_2 * i2_2 + A22 * i2_2 * i2_2
    return w1, w2, w11, w12, w22


@njit(cache=True, nogil=True, inline="always")
def edge_terms(ra, za, rb, zb, inv_length, inv_mid_radius, wt, w1, w2, w11, w12, w22, pressure, hessian):
    """One edge's part of :func:`edge_assembly`: its swept volume, its gradient entries (r_a, z_a,
    r_b, z_b) and, if ``hessian``, the nine distinct entries of its 4 x 4 Hessian (else zeros):
    (V_e, g0, g1, g2, g3, H00, H22, H02, H11, H13, H01, H23, H03, H12).

    Scalars in the compiled loop; arrays of all edges in its Python twin (the same operations
    elementwise, so the same numbers).
    """
    dr, dz = rb - ra, zb - za
    l = np.sqrt(dr * dr + dz * dz)
    inv_l = 1.0 / l
    u = dr * inv_l * inv_length
    v = dz * inv_l * inv_length
    h = 0.5 * inv_mid_radius
    a1, a2 = wt * w1, wt * w2
    swept, c, sp, ga, gb = swept_volume(ra, rb, dz, -pressure)
    g0, g1, g2, g3 = a2 * h - a1 * u + ga * dz, -a1 * v - sp, a2 * h + a1 * u + gb * dz, a1 * v + sp
    if not hessian:
        return swept, g0, g1, g2, g3, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0
    aa = wt * w11
    bb = wt * w12 * h
    cc = wt * w22 * h * h
    d = a1 * inv_l * inv_l * inv_length * inv_l
    A_rr, A_rz, A_zz = d * dz * dz, -d * dr * dz, d * dr * dr
    uu, uv, vv = aa * u * u, aa * u * v, aa * v * v
    bu, bv = bb * u, bb * v
    return (swept, g0, g1, g2, g3,
            uu - 2.0 * bu + cc + A_rr + 2.0 * c * dz,          # (0, 0)
            uu + 2.0 * bu + cc + A_rr + 2.0 * c * dz,          # (2, 2)
            cc - uu - A_rr + c * dz,                           # (0, 2)
            vv + A_zz,                                         # (1, 1), (3, 3)
            -vv - A_zz,                                        # (1, 3)
            uv - bv + A_rz - ga,                               # (0, 1)
            uv + bv + A_rz + gb,                               # (2, 3)
            bv - uv - A_rz + ga,                               # (0, 3)
            -uv - bv - A_rz - gb)                              # (1, 2)


#: Where each of the 16 entries of an edge's Hessian (row-major over r_a, z_a, r_b, z_b) is among
#: :func:`edge_terms`'s nine distinct ones (0 = H00, ..., 8 = H12).
HESSIAN_SLOTS = (0, 5, 2, 7, 5, 3, 8, 4, 2, 8, 1, 6, 7, 4, 6, 3)


@njit(cache=True, nogil=True, inline="always")
def edge_assembly(q, edges, inv_length, inv_mid_radius, weight, w1, w2, w11, w12, w22, pressure,
                  band_index, n_band_entries, order):
    """Gradient and band Hessian of the density terms (given their derivatives) plus the pressure work.

    The same arithmetic as ``snapmem.model.scene._chain_rule`` and ``PressureWork.volume_local`` (which
    document it and are the reference the tests compare with), fused with the scatter: one pass
    over the edges and no E x 16 temporaries (the edge's arithmetic: :func:`edge_terms`).

    Parameters
    ----------
    q : (2N,) state; edges : (E, 2); inv_length, inv_mid_radius, weight : (E,)
    w1 .. w22 : (E,) derivatives of the summed density in (lam1, lam2)
    pressure : float, the pressure of the PressureWork term (0 if none)
    band_index : (16 E,) entry-major flat positions in the band (the last slot is a trash slot)
    order : 1 (gradient) or 2 (gradient and band)

    Returns
    -------
    gradient : (2N,), band : (n_band_entries + 1,), volume : float, largest edge force entry : float
    """
    n_edges = edges.shape[0]
    gradient = np.empty(q.size)       # zeros (np.empty and a fill: np.zeros is one more overload to compile)
    gradient[:] = 0.0
    band = np.empty(n_band_entries + 1 if order >= 2 else 1)
    band[:] = 0.0
    volume = 0.0
    force = 0.0                       # largest edge force entry (for the rounding floor)
    distinct = np.empty(9)
    for e in range(n_edges):
        a, b = edges[e, 0], edges[e, 1]
        (swept, g0, g1, g2, g3, distinct[0], distinct[1], distinct[2], distinct[3], distinct[4], distinct[5],
         distinct[6], distinct[7], distinct[8]) = edge_terms(q[2 * a], q[2 * a + 1], q[2 * b], q[2 * b + 1],
                                                             inv_length[e], inv_mid_radius[e], weight[e], w1[e], w2[e],
                                                             w11[e], w12[e], w22[e], pressure, order >= 2)
        volume += swept
        gradient[2 * a] += g0
        gradient[2 * a + 1] += g1
        gradient[2 * b] += g2
        gradient[2 * b + 1] += g3
        force = max(force, abs(g0), abs(g1), abs(g2), abs(g3))
        if order < 2:
            continue
        for k in range(16):
            band[band_index[k * n_edges + e]] += distinct[HESSIAN_SLOTS[k]]
    return gradient, band, volume, force


@edge_assembly.python_twin
def _edge_assembly_python(q, edges, inv_length, inv_mid_radius, weight, w1, w2, w11, w12, w22, pressure,
                          band_index, n_band_entries, order):
    """:func:`edge_assembly` on all edges at once: :func:`edge_terms` on arrays, and the scatter by
    ``np.add.at``, which adds in the order of its indices (the loop's order)."""
    n_edges = edges.shape[0]
    a, b = edges[:, 0], edges[:, 1]
    swept, g0, g1, g2, g3, *distinct = python_of(edge_terms)(q[2 * a], q[2 * a + 1], q[2 * b], q[2 * b + 1],
                                                             inv_length, inv_mid_radius, weight, w1, w2, w11, w12,
                                                             w22, pressure, order >= 2)
    gradient = np.zeros(q.size)
    np.add.at(gradient, np.stack([2 * a, 2 * a + 1, 2 * b, 2 * b + 1], axis=1).ravel(),
              np.stack([g0, g1, g2, g3], axis=1).ravel())
    force = float(np.fmax.reduce(np.abs(np.stack([g0, g1, g2, g3])).ravel(), initial=0.0))
    band = np.zeros(n_band_entries + 1 if order >= 2 else 1)
    if order >= 2 and n_edges:
        entries = np.stack([np.broadcast_to(distinct[k], (n_edges,)) for k in HESSIAN_SLOTS], axis=1)
        np.add.at(band, band_index[:16 * n_edges].reshape(16, n_edges).T.ravel(), entries.ravel())
    return gradient, band, sum_in_order(np.broadcast_to(swept, (n_edges,))), force


@njit(cache=True, nogil=True, inline="always")
def linear_law_terms(l1, l2, W1, W2):
    """W = W1 (I1 - 3) + W2 (I2 - 3) and its derivatives in (lam1, lam2) at one edge (or elementwise
    on arrays): (w, w1, w2, w11, w12, w22)."""
    a2, b2 = l1 * l1, l2 * l2
    w = W1 * (a2 + b2 + 1.0 / (a2 * b2) - 3.0) + W2 * (1.0 / a2 + 1.0 / b2 + a2 * b2 - 3.0)
    i1_1, i1_2, i1_11, i1_12, i1_22, i2_1, i2_2, i2_11, i2_12, i2_22 = _invariant_derivatives(l1, l2)
    return (w, W1 * i1_1 + W2 * i2_1, W1 * i1_2 + W2 * i2_2, W1 * i1_11 + W2 * i2_11, W1 * i1_12 + W2 * i2_12,
            W1 * i1_22 + W2 * i2_22)


@njit(cache=True, nogil=True, inline="always")
def linear_law_density(lam1, lam2, W1, W2):
    """W = W1 (I1 - 3) + W2 (I2 - 3) with constant W1, W2 (neo-Hookean, Mooney-Rivlin) and its
    derivatives in (lam1, lam2), in one pass: returns (w, w1, w2, w11, w12, w22), each (E,).

    :func:`invariant_chain` with its second invariant derivatives zero (no temporaries: a time
    step assembles this ~7 times); the edge's arithmetic is :func:`linear_law_terms`.
    """
    n = lam1.size
    w, w1, w2 = np.empty(n), np.empty(n), np.empty(n)
    w11, w12, w22 = np.empty(n), np.empty(n), np.empty(n)
    for e in range(n):
        w[e], w1[e], w2[e], w11[e], w12[e], w22[e] = linear_law_terms(lam1[e], lam2[e], W1, W2)
    return w, w1, w2, w11, w12, w22


@linear_law_density.python_twin
def _linear_law_density_python(lam1, lam2, W1, W2):
    return tuple(np.broadcast_to(x, lam1.shape).copy() for x in python_of(linear_law_terms)(lam1, lam2, W1, W2))


@njit(cache=True, nogil=True, inline="always")
def meridian_stretches(ra, za, rb, zb, inv_length, inv_mid_radius):
    """An edge's (dr, dz, length l, meridional stretch lam1 = l / L, hoop stretch lam2 = (r_a + r_b)
    / (2 R)), from its end nodes (r_a, z_a), (r_b, z_b) [m] and the reference 1 / L and 1 / R [1/m]:
    the membrane's kinematics, written once. Scalars in the compiled loops; arrays of edges (or of
    frames by edges) in numpy code (snapmem.model.kinematics, the frames' measures' twin)."""
    dr, dz = rb - ra, zb - za
    l = np.sqrt(dr * dr + dz * dz)
    return dr, dz, l, l * inv_length, 0.5 * (ra + rb) * inv_mid_radius


@njit(cache=True, nogil=True)
def edge_kinematics(q, edges, inv_length, inv_mid_radius):
    """End coordinates, edge vector, length and stretches of every edge in one pass.

    The arithmetic of :meth:`snapmem.model.kinematics.EdgeKinematics.of` (which documents it).
    Returns ra, za, rb, zb, dr, dz, l, lam1, lam2, each of shape (E,).
    """
    n = edges.shape[0]
    ra, za, rb, zb = np.empty(n), np.empty(n), np.empty(n), np.empty(n)
    dr, dz, l, lam1, lam2 = np.empty(n), np.empty(n), np.empty(n), np.empty(n), np.empty(n)
    for e in range(n):
        a, b = edges[e, 0], edges[e, 1]
        ra[e], za[e], rb[e], zb[e] = q[2 * a], q[2 * a + 1], q[2 * b], q[2 * b + 1]
        dr[e], dz[e], l[e], lam1[e], lam2[e] = meridian_stretches(ra[e], za[e], rb[e], zb[e], inv_length[e],
                                                                  inv_mid_radius[e])
    return ra, za, rb, zb, dr, dz, l, lam1, lam2


@njit(cache=True, nogil=True, inline="always")
def edge_stretches(q, edges, inv_length, inv_mid_radius):
    """(lam1, lam2) of every edge, each (E,): :func:`edge_kinematics`'s stretches alone."""
    n = edges.shape[0]
    lam1, lam2 = np.empty(n), np.empty(n)
    for e in range(n):
        a, b = edges[e, 0], edges[e, 1]
        lam1[e], lam2[e] = meridian_stretches(q[2 * a], q[2 * a + 1], q[2 * b], q[2 * b + 1], inv_length[e],
                                              inv_mid_radius[e])[3:]
    return lam1, lam2


@njit(cache=True, nogil=True)
def scatter_add(target, index, values):
    """target[index[i]] += values[i] for every i with index[i] >= 0 (repeats accumulate).

    The node terms' few local entries into the band, gradient and border: numpy's bincount needs
    a target-sized pass per call and np.add.at is slow; this is one pass over the entries.
    """
    for i in range(index.size):
        j = index[i]
        if j >= 0:
            target[j] += values[i]


@njit(cache=True, nogil=True, inline="always")
def state_check(q, radius_dofs):
    """-1 if q is finite and every listed radius positive; -2 if q has NaN or inf; else the
    first radius degree of freedom that is not positive (the scene's domain check, one pass)."""
    for i in range(q.size):
        if not np.isfinite(q[i]):
            return -2
    for k in range(radius_dofs.size):
        if q[radius_dofs[k]] <= 0.0:
            return radius_dofs[k]
    return -1


@njit(cache=True, nogil=True)
def volume_gradient(q, edges, n_dof):
    """dV/dq of the swept volume V = sum_e (pi/3)(r_a^2 + r_a r_b + r_b^2)(z_b - z_a), shape (n_dof,)
    [m^2]: the pressure's load derivative (:func:`swept_volume`)."""
    g = np.zeros(n_dof)
    for e in range(edges.shape[0]):
        a, b = edges[e, 0], edges[e, 1]
        ra, za, rb, zb = q[2 * a], q[2 * a + 1], q[2 * b], q[2 * b + 1]
        dz = zb - za
        _, _, s, ga, gb = swept_volume(ra, rb, dz, 1.0)
        g[2 * a] += ga * dz
        g[2 * a + 1] -= s
        g[2 * b] += gb * dz
        g[2 * b + 1] += s
    return g


@volume_gradient.python_twin
def _volume_gradient_python(q, edges, n_dof):
    a, b = edges[:, 0], edges[:, 1]
    ra, za, rb, zb = q[2 * a], q[2 * a + 1], q[2 * b], q[2 * b + 1]
    dz = zb - za
    _, _, s, ga, gb = swept_volume.py_func(ra, rb, dz, 1.0)
    g = np.zeros(n_dof)
    np.add.at(g, np.stack([2 * a, 2 * a + 1, 2 * b, 2 * b + 1], axis=1).ravel(),
              np.stack([ga * dz, -s, gb * dz, s], axis=1).ravel())          # g -= s is g += (-s), exactly
    return g


@state_check.python_twin
def _state_check_python(q, radius_dofs):
    if not np.isfinite(q).all():
        return -2
    bad = q[radius_dofs] <= 0.0
    return radius_dofs[np.argmax(bad)] if bad.any() else -1


@njit(cache=True, nogil=True, inline="always")
def radius_max_step(q, dq, n_node_dofs, fraction):
    """Largest alpha <= 1 with every positive radius r_i + alpha dr_i above (1 - fraction) r_i."""
    alpha = 1.0
    for i in range(0, n_node_dofs, 2):
        if dq[i] < 0.0 and q[i] > 0.0:
            alpha = min(alpha, fraction * q[i] / -dq[i])
    return alpha
