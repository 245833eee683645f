"""Reference meridians: the curve whose revolution about the z axis is the membrane.

The degrees of freedom are q = (r_0, z_0, r_1, z_1, ...), shape (2N,). Edge e joins nodes
``edges[e, 0]`` and ``edges[e, 1]``; a closed meridian (a torus) has the extra edge N-1 -> 0.
Meridians are traversed so that the enclosed region lies on the left in the (r, z) plane
(counter-clockwise): the swept volume V(q) is then positive.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, field

import numpy as np

from snapmem.errors import SnapmemError, check_int, check_real


@dataclass(frozen=True, eq=False)
class Meridian:
    """A reference meridian with its edge topology and reference edge quantities.

    Attributes
    ----------
    r, z : ndarray, shape (N,)
        Reference node coordinates [m].
    closed : bool
        Whether the last node connects back to the first (torus).
    """

    r: np.ndarray
    z: np.ndarray
    closed: bool = False
    check_crossings: bool = field(default=True, repr=False)   # False for our own (simple) shapes
    edges: np.ndarray = field(init=False, repr=False)
    length: np.ndarray = field(init=False, repr=False)       # l_bar, shape (E,)
    mid_radius: np.ndarray = field(init=False, repr=False)   # r_m_bar, shape (E,)

    def __post_init__(self):
        r = np.array(self.r, dtype=float)
        z = np.array(self.z, dtype=float)
        if r.ndim != 1 or z.ndim != 1 or r.shape != z.shape:
            raise SnapmemError(f"meridian r, z: shapes {np.shape(self.r)} and {np.shape(self.z)}; "
                               "must be two 1D arrays of the same length")
        n = r.size
        if n < 3:
            raise SnapmemError(f"nodes = {n}: must be >= 3")
        if not (np.all(np.isfinite(r)) and np.all(np.isfinite(z))):
            raise SnapmemError("meridian r, z: must be finite (got NaN or inf)")
        if np.any(r < 0):
            i = int(np.argmin(r))
            raise SnapmemError(f"meridian r[{i}] = {r[i]:g}: radii must be >= 0 (the axis is r = 0)")
        on_axis = np.flatnonzero(r == 0)
        allowed = {0, n - 1} if not self.closed else set()
        if any(int(i) not in allowed for i in on_axis):
            raise SnapmemError(f"meridian r = 0 at node(s) {on_axis.tolist()}: only the end nodes of "
                               "an open meridian may lie on the axis")
        idx = np.arange(n)
        edges = np.stack([idx, np.roll(idx, -1)], axis=1)
        if not self.closed:
            edges = edges[:-1]
        length = np.hypot(r[edges[:, 1]] - r[edges[:, 0]], z[edges[:, 1]] - z[edges[:, 0]])
        if np.any(length <= 0):
            e = int(np.argmin(length))
            raise SnapmemError(f"meridian edge {e} has zero length: consecutive nodes must differ")
        if self.check_crossings:
            _check_simple(r, z, edges)
        for name, value in (("r", r), ("z", z), ("edges", edges), ("length", length),
                            ("mid_radius", 0.5 * (r[edges[:, 0]] + r[edges[:, 1]]))):
            value.setflags(write=False)
            object.__setattr__(self, name, value)

    @functools.cached_property
    def inverse_length(self) -> np.ndarray:
        """1 / l_bar of every edge, shape (E,)."""
        return 1.0 / self.length

    @functools.cached_property
    def inverse_mid_radius(self) -> np.ndarray:
        """1 / r_m_bar of every edge, shape (E,)."""
        return 1.0 / self.mid_radius

    @property
    def nodes(self) -> int:
        """Number of nodes N."""
        return self.r.size

    @property
    def q(self) -> np.ndarray:
        """Reference degrees of freedom, shape (2N,)."""
        q = np.empty(2 * self.nodes)
        q[0::2], q[1::2] = self.r, self.z
        return q

    @property
    def size(self) -> float:
        """A length scale [m]: the largest distance of a node from the origin of the (r, z) plane."""
        return float(np.max(np.hypot(self.r, self.z)))

    def node_lengths(self) -> np.ndarray:
        """Voronoi (half-edge sum) reference length of each node, shape (N,) [m]."""
        lv = np.zeros(self.nodes)
        np.add.at(lv, self.edges.ravel(), np.repeat(0.5 * self.length, 2))
        return lv

    def dof(self, node: int, component: str) -> int:
        """Index in q of ``component`` ('r' or 'z') of ``node`` (negative counts from the end)."""
        if component not in ("r", "z"):
            raise SnapmemError(f"component = {component!r}: must be 'r' or 'z'")
        node = range(self.nodes)[node]
        return 2 * node + (component == "z")

    def axis_radii(self) -> list[int]:
        """Degrees of freedom r of the nodes on the axis (fixed at r = 0 by symmetry)."""
        return [2 * int(i) for i in np.flatnonzero(self.r == 0)]

    pole_radii = axis_radii


def _check_simple(r, z, edges):
    """Raise SnapmemError if two non-adjacent edges of the meridian cross."""
    e = edges.shape[0]
    a = np.stack([r[edges[:, 0]], z[edges[:, 0]]], 1)
    b = np.stack([r[edges[:, 1]], z[edges[:, 1]]], 1)
    d = b - a

    def cross(u, v):
        return u[..., 0] * v[..., 1] - u[..., 1] * v[..., 0]

    block = max(1, 2_000_000 // max(e, 1))          # pairs per block bounded: O(E^2) time, O(E) memory
    for start in range(0, e, block):
        rows = slice(start, min(e, start + block))
        ai, aj = a[rows, None], a[None, :]
        di, dj = d[rows, None], d[None, :]
        denom = cross(di, dj)
        with np.errstate(divide="ignore", invalid="ignore"):
            s = cross(aj - ai, dj) / denom
            t = cross(aj - ai, di) / denom
        hit = (denom != 0) & (s > 0) & (s < 1) & (t > 0) & (t < 1)
        idx = np.arange(e)
        adjacent = np.abs(idx[rows, None] - idx[None, :]) <= 1
        shares_node = ((edges[rows, None, 0] == edges[None, :, 1]) | (edges[rows, None, 1] == edges[None, :, 0]))
        hit &= ~(adjacent | shares_node)
        if np.any(hit):
            i, j = np.argwhere(hit)[0]
            raise SnapmemError(f"meridian is self-intersecting: edges {start + i} and {j} cross")


def disc(R: float, nodes: int) -> Meridian:
    """Flat circular plate of radius R [m]: nodes from the rim (r = R) to the axis (r = 0).

    Rim first so that a membrane bulging to +z encloses a positive volume above z = 0.
    """
    R = check_real("R", R, minimum=0.0, min_inclusive=False)
    nodes = check_int("nodes", nodes, minimum=3)
    r = np.linspace(R, 0.0, nodes)
    return Meridian(r, np.zeros(nodes), check_crossings=False)


def sphere(R: float, nodes: int) -> Meridian:
    """Sphere of radius R [m]: half circle from the south pole to the north pole, equal angles."""
    R = check_real("R", R, minimum=0.0, min_inclusive=False)
    nodes = check_int("nodes", nodes, minimum=3)
    theta = np.linspace(-0.5 * np.pi, 0.5 * np.pi, nodes)
    r = R * np.cos(theta)
    r[0] = r[-1] = 0.0
    z = R * np.sin(theta)
    if nodes % 2:
        z[nodes // 2] = 0.0
        r[nodes // 2] = R
    return Meridian(r, z, check_crossings=False)


def torus(Rb: float, Rs: float, nodes: int) -> Meridian:
    """Torus: circle of radius Rs [m] about (Rb, 0), Rs < Rb; closed, counter-clockwise.

    Node 0 is the outer equator (r = Rb + Rs, z = 0).
    """
    Rb = check_real("Rb", Rb, minimum=0.0, min_inclusive=False)
    Rs = check_real("Rs", Rs, minimum=0.0, min_inclusive=False)
    if Rs >= Rb:
        raise SnapmemError(f"Rs = {Rs:g}: must be < Rb = {Rb:g} (the cross-section may not reach the axis)")
    nodes = check_int("nodes", nodes, minimum=3)
    theta = 2.0 * np.pi * np.arange(nodes) / nodes
    r = Rb + Rs * np.cos(theta)
    z = Rs * np.sin(theta)
    if nodes % 2 == 0:
        z[nodes // 2] = 0.0
    return Meridian(r, z, closed=True, check_crossings=False)
