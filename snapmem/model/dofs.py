"""A scene's degree-of-freedom map: which entries of q are free, their numbering in the banded
stiffness, and where each edge's and node's local blocks go in it.

Free degrees of freedom are numbered so that K is banded: in node order for an open meridian
(half-bandwidth 3), and for a closed meridian in the interleaved order 0, N-1, 1, N-2, ... that
puts every edge's two nodes at most two places apart (half-bandwidth 5), so the edge N-1 -> 0
needs no corner block and the solve stays a plain O(N) band factorisation. Rigid bodies' own
degrees of freedom come after the 2N node coordinates and after the band positions.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from snapmem.model.meridian import Meridian


@dataclass(frozen=True, eq=False)
class DofMap:
    """The numbering of a scene's degrees of freedom (build with :meth:`build`).

    Attributes
    ----------
    n_nodes : int
        Nodes N; the node coordinates are q[:2N] = (r_0, z_0, r_1, ...).
    n_bodies : int
        Rigid bodies k; their heights are q[2N:].
    free : ndarray (n_band + k,) of int
        The degree of freedom at each band position, then the bodies'.
    n_band : int
        Free node degrees of freedom (the order of the band block).
    bandwidth : int
        Half-bandwidth b of the band block.
    band_size : int
        (b + 1) n_band: entries of the flat lower band (its trash slot is entry band_size).
    edge_dofs : ndarray (E, 4) of int
        Each edge's (r_a, z_a, r_b, z_b) indices in q.
    edge_pos : ndarray (E, 4) of int
        Their band positions (-1 where fixed).
    hess_index : ndarray (16 E,) of int
        Entry-major flat positions in the lower band of each edge's 4 x 4 block (upper-triangle
        twins and fixed entries go to the trash slot).
    node_pos : ndarray (N, 2) of int
        Each node's (r, z) band positions (-1 where fixed).
    node_hess : ndarray (N, 2, 2) of int
        Flat band positions of each node's 2 x 2 block (as ``hess_index``).
    radius_dofs : ndarray of int
        The free radii's indices in q (each must stay positive).
    body_slices : tuple of slice
        Per node term, where its bodies' heights are in q.
    """

    n_nodes: int
    n_bodies: int
    free: np.ndarray
    n_band: int
    bandwidth: int
    band_size: int
    edge_dofs: np.ndarray
    edge_pos: np.ndarray
    hess_index: np.ndarray
    node_pos: np.ndarray
    node_hess: np.ndarray
    radius_dofs: np.ndarray
    body_slices: tuple

    @property
    def n_node_dofs(self) -> int:
        return 2 * self.n_nodes

    @classmethod
    def build(cls, meridian: Meridian, fixed, bodies_per_term) -> "DofMap":
        """The map of a meridian with degrees of freedom ``fixed`` (indices in q) and node terms
        having ``bodies_per_term`` bodies each."""
        n_nodes = meridian.nodes
        n_node_dofs = 2 * n_nodes
        offsets = np.cumsum([0] + list(bodies_per_term))
        body_slices = tuple(slice(n_node_dofs + a, n_node_dofs + b) for a, b in zip(offsets[:-1], offsets[1:]))
        n_bodies = int(offsets[-1])
        if meridian.closed:
            half = (n_nodes + 1) // 2
            order = np.empty(n_nodes, dtype=int)
            order[0::2] = np.arange(half)
            order[1::2] = np.arange(n_nodes - 1, half - 1, -1)
        else:
            order = np.arange(n_nodes)
        dof_order = (2 * order[:, None] + np.arange(2)).ravel()
        is_fixed = np.zeros(n_node_dofs, dtype=bool)
        is_fixed[list(fixed)] = True
        free = dof_order[~is_fixed[dof_order]]                 # band position -> dof
        n_band = free.size
        free = np.concatenate([free, n_node_dofs + np.arange(n_bodies)])   # bodies last
        position = np.full(n_node_dofs, -1)
        position[free[:n_band]] = np.arange(n_band)
        edges = meridian.edges
        edge_dofs = np.concatenate([2 * edges[:, :1] + np.arange(2), 2 * edges[:, 1:] + np.arange(2)], axis=1)
        edge_pos = position[edge_dofs]                          # (E, 4)
        i, j = edge_pos[:, :, None], edge_pos[:, None, :]       # (E, 4, 1), (E, 1, 4)
        valid = (i >= 0) & (j >= 0)
        b = max(1, int(np.max(np.where(valid, np.abs(i - j), 0))))
        rows = b + 1
        band_size = rows * n_band
        # the lower band, lower[i - j, j] = K[i, j] (i >= j), flattened as lower.T in C order; the
        # upper triangle's entries (i < j, the symmetric twins) and fixed dofs go to a trash slot
        flat = np.where(valid & (i >= j), j * rows + (i - j), band_size)
        hess_index = flat.transpose(1, 2, 0).ravel()           # entry-major, like the local Hessians
        # node terms: each node's 2x2 block (r_i, z_i) into the same band
        node_pos = position[2 * np.arange(n_nodes)[:, None] + np.arange(2)]          # (N, 2)
        i, j = node_pos[:, :, None], node_pos[:, None, :]
        valid = (i >= 0) & (j >= 0)
        node_hess = np.where(valid & (i >= j), j * rows + (i - j), band_size)        # (N, 2, 2)
        fixed_r = {d for d in fixed if d % 2 == 0 and d < n_node_dofs}
        radius_dofs = np.array([d for d in range(0, n_node_dofs, 2) if d not in fixed_r], dtype=int)
        return cls(n_nodes, n_bodies, free, n_band, b, band_size, edge_dofs, edge_pos, hess_index, node_pos,
                   node_hess, radius_dofs, body_slices)


def node_areas(meridian: Meridian) -> np.ndarray:
    """Each node's reference ring area 2 pi r_bar_i l_bar_i (a pole node: its cap pi l_bar^2), (N,) [m^2]."""
    lv = meridian.node_lengths()
    area = 2.0 * np.pi * meridian.r * lv
    pole = meridian.r == 0
    area[pole] = np.pi * lv[pole] ** 2
    return area
