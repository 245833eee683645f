"""What a recorded frame of the compiled time step needs, for many frames in one compiled call:
potential energy, volume, and each contact's normal force and smallest gap (what
``Scene.energy``, ``Scene.volume`` and :func:`snapmem.model.contact.contact_report` give)."""

from __future__ import annotations

import numpy as np
from snapmem._lazy import njit

from snapmem.dynamics.compiled_assembly import assemble, contact_gaps
from snapmem.kernels.assembly import swept_volume
from snapmem.kernels.contact import ball_edge_gaps, barrier_force


@njit(cache=True, nogil=True)
def frame_measures(q, P, pressure, a_el):
    """What a recorded frame needs at q: (potential energy [J], volume [m^3], total normal force [N]
    and smallest gap [m] of every contact, linear ones first, then balls)."""
    n_free = P.free.size
    zeros = np.zeros(n_free)
    energy = assemble(q, P, pressure, a_el, zeros, q, zeros, 1)[0]
    volume = 0.0
    for e in range(P.edges.shape[0]):
        a, b = P.edges[e, 0], P.edges[e, 1]
        volume += swept_volume(q[2 * a], q[2 * b], q[2 * b + 1] - q[2 * a + 1], 1.0)[0]
    x = q[: P.n_node_dofs].reshape(-1, 2)
    n_lin = P.lin_axis.size
    forces = np.zeros(n_lin + P.ball_radius.size)
    for c in range(n_lin):
        for k in range(P.lin_ptr[c], P.lin_ptr[c + 1]):
            i = P.lin_nodes[k]
            forces[c] += barrier_force(P.lin_sign[c] * x[i, P.lin_axis[c]] + P.lin_offset[c], P.lin_dhat[c],
                                       P.lin_coef[c, i])
    for c in range(P.ball_radius.size):
        zc = q[P.ball_dof[c]] if P.ball_dof[c] >= 0 else P.ball_z0[c]
        d = ball_edge_gaps(x, P.edges, zc, P.ball_radius[c])
        for e in range(d.size):
            forces[n_lin + c] += barrier_force(d[e], P.ball_dhat[c], P.ball_coef[c, e])
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
