"""What a recorded frame of the compiled time step needs, for many frames in one call: potential
energy, volume, and each contact's normal force and smallest gap (what ``Scene.energy``,
``Scene.volume`` and :func:`snapmem.model.contact.contact_report` give).

The membrane's part (:func:`frames_membrane`) and the contacts' (:func:`frames_contacts`) are two
kernels, which Python calls once a run. While numba's cache does not hold it, the membrane's runs
as its twin (``interpret_uncached``), on all frames and edges at once, instead of compiling for
~1 s of a cold ``snapmem simulate`` (issue 17). The twin covers the laws linear in the invariants
(no transcendental function: numpy's ``np.log`` on arrays rounds differently from numba's in ~1%
of values), so another law's frames compile; the contacts' kernel always compiles.
"""

from __future__ import annotations

import numpy as np
from snapmem._lazy import njit, python_of

from snapmem.dynamics.compiled_assembly import GRADIENT, contact_gaps, membrane_density
from snapmem.kernels.assembly import edge_stretches, linear_law_terms, meridian_stretches, swept_volume
from snapmem.kernels.contact import ball_edge_barrier, ball_edge_gaps, barrier_force, linear_barrier
from snapmem.kernels.laws import electric_density
from snapmem.kernels.linalg import sum_in_order


def frames_measures(Q, P, general_law, linear, balls, pressure, a_el):
    """What a recorded frame needs, for every row q of Q (with its pressure and electric
    coefficient): potential energy [J], volume [m^3], and the total normal force [N] and smallest
    gap [m] of every contact, linear ones first, then balls: energies (T,), volumes (T,), forces
    (T, C), gaps (T, C). ``general_law``, ``linear``, ``balls``: those terms or None (see
    :mod:`snapmem.dynamics.compiled_assembly`); without viscous networks (their stored energy
    depends on each frame's internal stretches: CompiledStep.measures_many adds it).

    The energy is compiled_assembly.assemble's at zero inertia, term by term in its order (so the
    same number to the bit; the membrane's density is the same ``membrane_density``), without the
    gradient (tests/test_compiled_step.py holds the two equal): calling ``assemble`` here would optimise and
    generate its whole call tree (the membrane's fused assembly) a second time at first use, some
    1.5 s of a cold ``snapmem simulate`` (issue 17). The volume is the one edge_assembly sums.
    """
    membrane = frames_membrane                       # (its twin covers LAW_LINEAR: another law compiles)
    energy, volume = (membrane if general_law is None else getattr(membrane, "dispatcher", membrane))(
        Q, P, general_law, pressure, a_el)
    if linear is None and balls is None:
        return energy, volume, np.zeros((Q.shape[0], 0)), np.empty((Q.shape[0], 0))
    return (energy, volume, *frames_contacts(Q, P, linear, balls, energy))


@njit(cache=True, nogil=True, interpret_uncached=True)
def frames_membrane(Q, P, general_law, pressure, a_el):
    """The membrane's part of every frame's potential energy (its density's, less pressure times
    volume) [J] and the volume [m^3], each (T,): :func:`frames_measures` without contacts."""
    T = Q.shape[0]
    energy, volume = np.empty(T), np.empty(T)
    for t in range(T):
        q = Q[t]
        lam1, lam2 = edge_stretches(q, P.edges, P.inv_length, P.inv_mid_radius)
        w = membrane_density(lam1, lam2, P, general_law, None, a_el[t])[0]
        u = 0.0
        for e in range(w.size):
            u += P.weight[e] * w[e]
        v = 0.0
        for e in range(P.edges.shape[0]):
            a, b = P.edges[e, 0], P.edges[e, 1]
            v += swept_volume(q[2 * a], q[2 * b], q[2 * b + 1] - q[2 * a + 1], 1.0)[0]
        volume[t] = v
        energy[t] = u - pressure[t] * v
    return energy, volume


@frames_membrane.python_twin
def _frames_membrane_python(Q, P, general_law, pressure, a_el):
    """:func:`frames_membrane` on (frames, edges) arrays for a law linear in the invariants
    (``general_law`` None): edge_stretches' arithmetic, membrane_density's (the law at the
    prestretched stretches, the electric term where a_el is not 0), and each frame's sums over
    its edges in the loop's order (sum_in_order)."""
    assert general_law is None, "the twin covers LAW_LINEAR (frames_measures compiles another law)"
    a, b = P.edges[:, 0], P.edges[:, 1]
    ra, za, rb, zb = Q[:, 2 * a], Q[:, 2 * a + 1], Q[:, 2 * b], Q[:, 2 * b + 1]
    _, dz, _, lam1, lam2 = python_of(meridian_stretches)(ra, za, rb, zb, P.inv_length, P.inv_mid_radius)
    l1, l2 = (lam1, lam2) if P.law_stretch is None else (P.law_stretch[0] * lam1, P.law_stretch[1] * lam2)
    w = python_of(linear_law_terms)(l1, l2, P.law_params[0], P.law_params[1])[0]
    electric = a_el != 0.0
    if electric.any():
        w[electric] += python_of(electric_density)(lam1[electric], lam2[electric], a_el[electric, None])[0]
    volume = sum_in_order(python_of(swept_volume)(ra, rb, dz, 1.0)[0].T)
    return sum_in_order((P.weight * w).T) - pressure * volume, volume


@njit(cache=True, nogil=True)
def frames_contacts(Q, P, linear, balls, energy):
    """The contacts' part of :func:`frames_measures`: their energies added to each frame's
    ``energy`` (the membrane's, in place, in assemble's order), and their forces and gaps (T, C)."""
    T = Q.shape[0]
    n_lin = 0 if linear is None else linear.lin_axis.size
    n_contacts = n_lin + (0 if balls is None else balls.ball_radius.size)
    forces, gaps = np.zeros((T, n_contacts)), np.empty((T, n_contacts))
    for t in range(T):
        q = Q[t]
        u = energy[t]
        x = q[: P.n_node_dofs].reshape(-1, 2)
        if linear is not None:
            for c in range(n_lin):
                nodes = linear.lin_nodes[linear.lin_ptr[c]: linear.lin_ptr[c + 1]]
                u += linear_barrier(x, nodes, linear.lin_axis[c], linear.lin_sign[c], linear.lin_offset[c],
                                    linear.lin_coef[c], linear.lin_dhat[c], GRADIENT)[0]
        if balls is not None:
            for c in range(balls.ball_radius.size):
                dof = balls.ball_dof[c]
                body = dof >= 0
                zc = q[dof] if body else balls.ball_z0[c]
                u += ball_edge_barrier(x, P.edges, zc, balls.ball_radius[c], balls.ball_dhat[c], balls.ball_coef[c],
                                       body, GRADIENT)[0]
                if body:
                    u += balls.ball_weight[c] * zc
        energy[t] = u
        if linear is not None:
            for c in range(n_lin):
                for k in range(linear.lin_ptr[c], linear.lin_ptr[c + 1]):
                    i = linear.lin_nodes[k]
                    forces[t, c] += barrier_force(linear.lin_sign[c] * x[i, linear.lin_axis[c]] + linear.lin_offset[c],
                                                  linear.lin_dhat[c], linear.lin_coef[c, i])
            smallest = contact_gaps(q, P, linear, None)      # the linear ones' (the balls': below)
            for c in range(n_lin):              # (a loop: row assignment compiles a shape check)
                gaps[t, c] = smallest[c]
        if balls is not None:
            for c in range(balls.ball_radius.size):
                zc = q[balls.ball_dof[c]] if balls.ball_dof[c] >= 0 else balls.ball_z0[c]
                d = ball_edge_gaps(x, P.edges, zc, balls.ball_radius[c])
                for e in range(d.size):
                    forces[t, n_lin + c] += barrier_force(d[e], balls.ball_dhat[c], balls.ball_coef[c, e])
                gaps[t, n_lin + c] = np.min(d)      # contact_gaps' number, from these gaps
    return forces, gaps
