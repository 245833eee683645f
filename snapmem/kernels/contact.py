"""Compiled kernels of the ball's edge contact: point-segment gaps and their barrier.

The ball touches edges, not nodes (see :class:`snapmem.model.contact.Ball`): each edge's gap is the
distance from the ball's centre c = (0, zc) to the segment [a, b], minus the radius. Three cases
per edge (the centre projects before a, after b, or inside), each a few scalar formulas, which
numpy can only vectorise with masks and fancy indexing (what that costs: docs/performance.md).
These loops do the same arithmetic (the numpy version stays in ``Ball.edge_gap`` as the
reference the tests compare against). Also the linear gaps' barrier (rod, shell, plane), and
:func:`ipc_barrier`, the one formula of the IPC barrier every contact uses.
Compiled by numba on first use and cached on disk.
"""

from __future__ import annotations

import numpy as np
from snapmem._lazy import njit

# Offsets of an edge's ends in its (r_a, z_a, r_b, z_b) as numpy integers: numba would compile
# :func:`_node_gap` once per Python int constant (a literal argument type).
_FIRST_END, _SECOND_END = np.int64(0), np.int64(2)


@njit(cache=True, nogil=True, inline="always")
def ipc_barrier(d, dhat, c):
    """c b(d), c b'(d), c b''(d) of the IPC barrier b(d) = -(d - dhat)^2 ln(d / dhat), for
    0 < d < dhat (zero beyond dhat, infinite at d <= 0: the callers' cases) [c m^2, c m, c].

    The one formula of the barrier: the compiled contact kernels call it per node or edge
    (c = kappa A / dhat), snapmem.model.contact.barrier its ``.py_func`` on arrays (c = 1).
    """
    lg = np.log(d / dhat)
    s = d - dhat
    return -c * s * s * lg, c * (-2.0 * s * lg - s * s / d), c * (-2.0 * lg + (dhat - d) * (3.0 * d + dhat) / (d * d))


@njit(cache=True, nogil=True)
def barrier_force(d, dhat, c):
    """|c b'(d)|: the normal force [N] of a barrier with weight c at gap d (0 beyond dhat)."""
    return 0.0 if d >= dhat else abs(ipc_barrier(d, dhat, c)[1])


@njit(cache=True, nogil=True)
def ball_edge_gaps(x, edges, zc, radius):
    """Gap of every edge to the ball, shape (E,) [m]: distance from (0, zc) to the segment minus radius.

    x : (N, 2) node positions; edges : (E, 2) node indices.
    """
    m = edges.shape[0]
    d = np.empty(m)
    for e in range(m):
        ar, az = x[edges[e, 0], 0], x[edges[e, 0], 1]
        ur, uz = x[edges[e, 1], 0] - ar, x[edges[e, 1], 1] - az
        wr, wz = -ar, zc - az
        t = (wr * ur + wz * uz) / (ur * ur + uz * uz)
        t = min(1.0, max(0.0, t))
        d[e] = np.hypot(ar + t * ur, az + t * uz - zc) - radius
    return d


@njit(cache=True, nogil=True)
def ball_min_gap(x, dx, alpha, edges, zc, dzc, radius):
    """Smallest edge gap at the state x + alpha dx, zc + alpha dzc [m] (no temporaries)."""
    out = np.inf
    for e in range(edges.shape[0]):
        i, j = edges[e, 0], edges[e, 1]
        ar, az = x[i, 0] + alpha * dx[i, 0], x[i, 1] + alpha * dx[i, 1]
        ur, uz = x[j, 0] + alpha * dx[j, 0] - ar, x[j, 1] + alpha * dx[j, 1] - az
        c = zc + alpha * dzc
        t = (-ar * ur + (c - az) * uz) / (ur * ur + uz * uz)
        t = min(1.0, max(0.0, t))
        out = min(out, np.hypot(ar + t * ur, az + t * uz - c) - radius)
    return out


@njit(cache=True, nogil=True)
def _node_gap(pr, pz, radius, body, g, h, off, order):
    """Gap of the point (pr, pz) (relative to the centre) into g[off:off+2] (and g[-1] for a body)."""
    s = np.hypot(pr, pz)
    if order >= 1:
        nr, nz = pr / s, pz / s
        n = g.size
        g[off], g[off + 1] = nr, nz
        if body:
            g[n - 1] = -nz
        if order >= 2:
            hrr, hrz, hzz = nz * nz / s, -nr * nz / s, nr * nr / s        # (I - n n^T) / s
            h[off, off], h[off, off + 1], h[off + 1, off], h[off + 1, off + 1] = hrr, hrz, hrz, hzz
            if body:
                h[off, n - 1] = h[n - 1, off] = -hrz
                h[off + 1, n - 1] = h[n - 1, off + 1] = -hzz
                h[n - 1, n - 1] = hzz
    return s - radius


@njit(cache=True, nogil=True)
def _bilinear_hessian(i, j):
    """Entry (i, j) of the constant Hessian of C = r_b zc - r_b z_a - r_a zc + r_a z_b in
    (r_a, z_a, r_b, z_b, zc)."""
    a, b = min(i, j), max(i, j)
    if (a == 0 and b == 3) or (a == 2 and b == 4):
        return 1.0
    if (a == 1 and b == 2) or (a == 0 and b == 4):
        return -1.0
    return 0.0


@njit(cache=True, nogil=True)
def _segment_gap(ar, az, ur, uz, wr, wz, radius, body, g, h, order, gC, gL):
    """Gap |C| / L - radius of the centre to the line of an edge, C = u x w, L = |u|, with its
    derivatives in (r_a, z_a, r_b, z_b[, zc]) into g, h (u = b - a, w = c - a); gC, gL are work
    arrays of g's size (no allocation per edge)."""
    C = ur * wz - uz * wr
    L = np.sqrt(ur * ur + uz * uz)
    sgn = 1.0 if C >= 0 else -1.0
    d = sgn * C / L - radius
    if order < 1:
        return d
    n = g.size
    # dC and dL in (r_a, z_a, r_b, z_b, zc)
    gC[0], gC[1], gC[2], gC[3] = uz - wz, wr - ur, wz, -wr
    hr, hz = ur / L, uz / L
    gL[0], gL[1], gL[2], gL[3] = -hr, -hz, hr, hz
    if body:
        gC[4] = ur
        gL[4] = 0.0
    for i in range(n):
        g[i] = sgn * (gC[i] / L - C / (L * L) * gL[i])
    if order < 2:
        return d
    # C is bilinear: its Hessian is constant; L's Hessian is P / L on the u block
    Prr, Prz, Pzz = (1.0 - hr * hr) / L, -hr * hz / L, (1.0 - hz * hz) / L
    for i in range(n):
        for j in range(n):
            HL = 0.0
            if i < 4 and j < 4:
                si = -1.0 if i < 2 else 1.0
                sj = -1.0 if j < 2 else 1.0
                HL = si * sj * (Prr if i % 2 == 0 and j % 2 == 0 else (Pzz if i % 2 == 1 and j % 2 == 1 else Prz))
            h[i, j] = sgn * (_bilinear_hessian(i, j) / L - (gC[i] * gL[j] + gL[i] * gC[j]) / (L * L)
                             - C / (L * L) * HL + 2.0 * C / (L * L * L) * gL[i] * gL[j])
    return d


@njit(cache=True, nogil=True)
def ball_edge_barrier(x, edges, zc, radius, dhat, coef, body, order):
    """The ball's barrier summed over edges: sum_e coef_e b(d_e), b the IPC barrier of width dhat.

    Parameters
    ----------
    x : (N, 2) node positions [m]; edges : (E, 2); zc : centre height [m]; radius, dhat [m]
    coef : (E,) kappa * area_e / dhat [Pa m]; body : whether zc is a degree of freedom; order : 0-2

    Returns
    -------
    energy : float (inf if an edge touches the ball)
    which : (M,) the edges within dhat
    grad : (M, n) and hess : (n, n, M), n = 4 (+1 with a body), in (r_a, z_a, r_b, z_b[, zc]),
        entry-major Hessian like the edge terms'.
    """
    m = edges.shape[0]
    n = 5 if body else 4
    dist = ball_edge_gaps(x, edges, zc, radius)
    count = 0
    for e in range(m):
        if dist[e] < dhat:
            count += 1
    which = np.empty(count, dtype=np.int64)
    k = 0
    for e in range(m):
        if dist[e] < dhat:
            which[k] = e
            k += 1
    grad = np.zeros((count, n))
    hess = np.zeros((n, n, count))
    g = np.zeros(n)
    h = np.zeros((n, n))
    gC, gL = np.empty(n), np.empty(n)
    energy = 0.0
    for k in range(count):
        e = which[k]
        i, j = edges[e, 0], edges[e, 1]
        ar, az, br, bz = x[i, 0], x[i, 1], x[j, 0], x[j, 1]
        ur, uz, wr, wz = br - ar, bz - az, -ar, zc - az
        t = (wr * ur + wz * uz) / (ur * ur + uz * uz)
        g[:] = 0.0
        h[:, :] = 0.0
        if t <= 0.0:
            d = _node_gap(ar, az - zc, radius, body, g, h, _FIRST_END, order)
        elif t >= 1.0:
            d = _node_gap(br, bz - zc, radius, body, g, h, _SECOND_END, order)
        else:
            d = _segment_gap(ar, az, ur, uz, wr, wz, radius, body, g, h, order, gC, gL)
        if d <= 0.0:
            return np.inf, which, grad, hess
        b0, b1, b2 = ipc_barrier(d, dhat, coef[e])
        energy += b0
        if order >= 1:
            for a in range(n):
                grad[k, a] = b1 * g[a]
            if order >= 2:
                for a in range(n):
                    for bb in range(n):
                        hess[a, bb, k] = b2 * g[a] * g[bb] + b1 * h[a, bb]
    return energy, which, grad, hess


@njit(cache=True, nogil=True)
def ball_node_max_step(x, dx, zc, dzc, radius, fraction):
    """Largest alpha <= 1 before any node reaches the ball along (dx, dzc), times ``fraction``:
    the first root of |p + alpha dp| = radius (p relative to the centre), over the nodes that close in."""
    alpha = 1.0
    for i in range(x.shape[0]):
        pr, pz = x[i, 0], x[i, 1] - zc
        qr, qz = dx[i, 0], dx[i, 1] - dzc
        a = qr * qr + qz * qz
        b = pr * qr + pz * qz
        c = pr * pr + pz * pz - radius * radius
        disc = b * b - a * c
        if a > 0.0 and b < 0.0 and disc >= 0.0:
            alpha = min(alpha, fraction * (-b - np.sqrt(disc)) / a)
    return alpha


@njit(cache=True, nogil=True)
def linear_barrier(x, nodes, axis, sign, offset, coef, dhat, order):
    """Barrier of a gap linear in one coordinate, d_i = sign * x[i, axis] + offset (rod, shell,
    plane), summed over ``nodes`` with weights coef_i = kappa A_i / dhat.

    Returns (energy, near (K,) the nodes within dhat, gradient (K, 2), hessian (K, 2, 2)) in each
    node's (r, z); energy is inf if a gap is not positive.
    """
    count = 0
    for k in range(nodes.size):
        if sign * x[nodes[k], axis] + offset < dhat:
            count += 1
    near = np.empty(count, dtype=np.int64)
    grad = np.zeros((count, 2))
    hess = np.zeros((count, 2, 2))
    energy = 0.0
    m = 0
    for k in range(nodes.size):
        i = nodes[k]
        d = sign * x[i, axis] + offset
        if d >= dhat:
            continue
        near[m] = i
        if d <= 0.0:
            energy = np.inf
            m += 1
            continue
        b0, b1, b2 = ipc_barrier(d, dhat, coef[i])
        energy += b0
        if order >= 1:
            grad[m, axis] = sign * b1
        if order >= 2:
            hess[m, axis, axis] = b2
        m += 1
    return energy, near, grad, hess


@njit(cache=True, nogil=True)
def linear_max_step(x, dx, nodes, axis, sign, offset, fraction):
    """Largest alpha <= 1 keeping every linear gap above (1 - fraction) of its value."""
    alpha = 1.0
    for k in range(nodes.size):
        i = nodes[k]
        rate = sign * dx[i, axis]
        if rate < 0.0:
            alpha = min(alpha, fraction * (sign * x[i, axis] + offset) / -rate)
    return alpha


@njit(cache=True, nogil=True)
def linear_min_gap(x, nodes, axis, sign, offset):
    """Smallest linear gap sign * x[i, axis] + offset over ``nodes`` [m]."""
    out = np.inf
    for k in range(nodes.size):
        out = min(out, sign * x[nodes[k], axis] + offset)
    return out
