"""Edge strains of the discrete meridian and their derivatives in the edge's 4 coordinates.

Local coordinates of edge e are (r_a, z_a, r_b, z_b) of its two nodes. Everything is
vectorised over edges: shapes (E,), (E, 4). :func:`density_chain_rule` is where material
derivatives meet these strain derivatives.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from snapmem.kernels.assembly import edge_kinematics, meridian_stretches
from snapmem.kernels.switch import compiled
from snapmem.model.materials import Density
from snapmem.model.meridian import Meridian


@dataclass
class EdgeKinematics:
    """Current edge geometry and in-plane stretches of every edge.

    Attributes
    ----------
    ra, za, rb, zb : ndarray (E,)
        End-node coordinates [m].
    dr, dz : ndarray (E,)
        Edge vector components rb - ra, zb - za [m].
    l : ndarray (E,)
        Current edge length [m].
    lam1 : ndarray (E,)
        Meridional stretch l / l_bar.
    lam2 : ndarray (E,)
        Hoop stretch r_m / r_m_bar with r_m the mid radius.
    """

    ra: np.ndarray
    za: np.ndarray
    rb: np.ndarray
    zb: np.ndarray
    dr: np.ndarray
    dz: np.ndarray
    l: np.ndarray
    lam1: np.ndarray
    lam2: np.ndarray
    inv_length: np.ndarray      # 1 / l_bar
    inv_mid_radius: np.ndarray  # 1 / r_m_bar

    @classmethod
    def of(cls, meridian: Meridian, q: np.ndarray) -> "EdgeKinematics":
        """The kinematics of state q (2N,): by the compiled kernel (snapmem.kernels.assembly.edge_kinematics)
        for a 1D float array, else (or on the reference path) by the numpy expressions below."""
        inv_length = meridian.inverse_length
        inv_mid_radius = meridian.inverse_mid_radius
        if compiled() and q.dtype == np.float64 and q.ndim == 1:
            return cls(*edge_kinematics(q, meridian.edges, inv_length, inv_mid_radius), inv_length, inv_mid_radius)
        a, b = meridian.edges[:, 0], meridian.edges[:, 1]
        r, z = q[0::2], q[1::2]
        ra, za, rb, zb = r[a], z[a], r[b], z[b]
        return cls(ra, za, rb, zb, *meridian_stretches.py_func(ra, za, rb, zb, inv_length, inv_mid_radius),
                   inv_length, inv_mid_radius)


def density_chain_rule(kin: EdgeKinematics, dens: Density, weight: np.ndarray, order: int):
    """Edge gradient (E, 4) and entry-major Hessian (4, 4, E) of sum_e weight_e W(lam1_e, lam2_e).

    The one place where material derivatives meet strain derivatives:
    g = wt (W1 g1 + W2 g2), H = wt (W11 g1 g1 + W12 (g1 g2 + g2 g1) + W22 g2 g2 + W1 d2lam1),
    with g1 = dlam1/dx = (-u, -v, u, v), u, v = t / l_bar, g2 = dlam2/dx = (h, 0, h, 0),
    h = 1 / (2 r_m_bar), and d2lam1 = [[A, -A], [-A, A]] with A = (I - t t^T) / (l l_bar), t the
    unit tangent. The structure is written out: ten distinct entries of the symmetric 4x4 block,
    each a few products of (E,) arrays, instead of outer products of (E, 4) arrays. This is the
    numpy reference of snapmem.kernels.assembly.edge_assembly.
    """
    inv_l = 1.0 / kin.l
    u = kin.dr * inv_l * kin.inv_length
    v = kin.dz * inv_l * kin.inv_length
    h = 0.5 * kin.inv_mid_radius
    a1, a2 = weight * dens.w1, weight * dens.w2
    grad = np.empty((u.size, 4))
    grad[:, 0] = a2 * h - a1 * u
    grad[:, 1] = -a1 * v
    grad[:, 2] = a2 * h + a1 * u
    grad[:, 3] = a1 * v
    if order < 2:
        return grad, None
    a = weight * dens.w11
    b = (weight * dens.w12) * h
    c = (weight * dens.w22) * h * h
    d = a1 * inv_l * inv_l * kin.inv_length * inv_l          # w1 / (l^3 l_bar) times (I - t t^T) l^2
    A_rr, A_rz, A_zz = d * kin.dz * kin.dz, -d * kin.dr * kin.dz, d * kin.dr * kin.dr
    uu, uv, vv = a * u * u, a * u * v, a * v * v
    bu, bv = b * u, b * v
    hess = np.empty((4, 4, u.size))
    hess[0, 0] = uu - 2.0 * bu + c + A_rr
    hess[2, 2] = uu + 2.0 * bu + c + A_rr
    hess[0, 2] = hess[2, 0] = c - uu - A_rr
    hess[1, 1] = hess[3, 3] = vv + A_zz
    hess[1, 3] = hess[3, 1] = -vv - A_zz
    hess[0, 1] = hess[1, 0] = uv - bv + A_rz
    hess[2, 3] = hess[3, 2] = uv + bv + A_rz
    hess[0, 3] = hess[3, 0] = bv - uv - A_rz
    hess[1, 2] = hess[2, 1] = -uv - bv - A_rz
    return grad, hess