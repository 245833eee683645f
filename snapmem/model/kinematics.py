"""Edge strains of the discrete meridian and their derivatives in the edge's 4 coordinates.

Local coordinates of edge e are (r_a, z_a, r_b, z_b) of its two nodes. Everything is
vectorised over edges: shapes (E,), (E, 4).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from snapmem.kernels.assembly import edge_kinematics
from snapmem.model.meridian import Meridian


#: Use the compiled kernel (snapmem.kernels.edge_kinematics); False keeps the numpy expressions.
compiled = True


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
        inv_length = meridian.inverse_length
        inv_mid_radius = meridian.inverse_mid_radius
        if compiled and q.dtype == np.float64 and q.ndim == 1:
            return cls(*edge_kinematics(q, meridian.edges, inv_length, inv_mid_radius), inv_length, inv_mid_radius)
        a, b = meridian.edges[:, 0], meridian.edges[:, 1]
        r, z = q[0::2], q[1::2]
        ra, za, rb, zb = r[a], z[a], r[b], z[b]
        dr, dz = rb - ra, zb - za
        l = np.sqrt(dr * dr + dz * dz)
        return cls(ra, za, rb, zb, dr, dz, l, l * inv_length, 0.5 * (ra + rb) * inv_mid_radius,
                   inv_length, inv_mid_radius)

    def lam1_gradient(self) -> np.ndarray:
        """d lam1 / d(r_a, z_a, r_b, z_b), shape (E, 4)."""
        tr = self.dr / self.l * self.inv_length
        tz = self.dz / self.l * self.inv_length
        return np.stack([-tr, -tz, tr, tz], axis=1)

    def lam1_hessian_block(self):
        """The 2x2 block A of d2 lam1 / dx2 = [[A, -A], [-A, A]]: (A_rr, A_rz, A_zz), each (E,).

        A = (I - t t^T) / (l l_bar) with t the unit tangent.
        """
        c = self.inv_length / (self.l ** 3)
        return self.dz * self.dz * c, -self.dr * self.dz * c, self.dr * self.dr * c

    def lam2_gradient(self) -> np.ndarray:
        """d lam2 / d(r_a, z_a, r_b, z_b), shape (E, 4); lam2 is linear, its Hessian is zero."""
        h = 0.5 * self.inv_mid_radius
        zero = np.zeros_like(h)
        return np.stack([h, zero, h, zero], axis=1)
