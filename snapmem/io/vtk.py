"""VTK files for ParaView: revolved surfaces as .vtu (written with meshio) and .pvd series.

This module knows geometry and files only (arrays in, files out; no physics). It turns a
meridian polyline (r_i, z_i) into the triangulated surface of revolution, computes the volume
that surface encloses, and writes frames of such surfaces, each with its point data, as a
ParaView time or parameter series. :func:`snapmem.viz.export.export` builds the point data of a
trajectory or a branch and calls it.

meshio is optional (``pip install "snapmem[vtk]"``); it is imported only when a file is written.
"""

from __future__ import annotations

import os
from pathlib import Path
from xml.sax.saxutils import quoteattr

import numpy as np

from snapmem.errors import SnapmemError

#: The formats :func:`write_series` writes (the CLI's ``--format`` choices).
FORMATS = ("vtk",)


def require_meshio():
    """The meshio module, or a SnapmemError saying how to install it."""
    try:
        import meshio
    except ImportError:
        raise SnapmemError('VTK export needs meshio, which is not installed: pip install "snapmem[vtk]"') from None
    return meshio


def check_segments(segments) -> int:
    """``segments`` as an int >= 3 (the number of angles a meridian is swept through)."""
    if isinstance(segments, bool) or not isinstance(segments, (int, np.integer)) or segments < 3:
        raise SnapmemError(f"segments = {segments!r}: must be an integer >= 3")
    return int(segments)


class Revolution:
    """Triangulation of a meridian of N nodes swept through ``segments`` angles about the z axis.

    Nodes with r = 0 (the poles of an open meridian) become one point each; every other node a
    ring of ``segments`` points. Ring point k of node i sits at angle 2 pi k / segments. Each edge
    (i, j) of the meridian becomes ``segments`` quads split into two triangles, oriented so the
    normal (b - a) x (c - a) is the swept meridian normal (dz, -dr): outward for a sphere traced
    from the south pole to the north pole or a torus traced counter-clockwise, so that
    :func:`enclosed_volume` has the sign of the meridian's volume sum(pi/3 (ra^2 + ra rb + rb^2)(zb - za)).

    Parameters
    ----------
    on_axis : ndarray of bool, shape (N,)
        Which nodes lie on the axis (fixed at r = 0).
    edges : ndarray of int, shape (E, 2)
        The meridian's edges (node pairs).
    segments : int
        Number of angles (>= 3).
    """

    def __init__(self, on_axis: np.ndarray, edges: np.ndarray, segments: int):
        self.segments = S = check_segments(segments)
        on_axis = np.asarray(on_axis, dtype=bool)
        self.on_axis = on_axis
        counts = np.where(on_axis, 1, S)
        self.first = np.concatenate([[0], np.cumsum(counts)[:-1]])      # first point of each node
        self.n_points = int(counts.sum())
        self.node_of_point = np.repeat(np.arange(on_axis.size), counts)
        self.angle = np.zeros(self.n_points)
        ring = ~on_axis[self.node_of_point]
        self.angle[ring] = 2 * np.pi * (np.arange(self.n_points) - self.first[self.node_of_point])[ring] / S
        self.triangles = self._triangles(np.asarray(edges, dtype=int))

    def _point(self, node, k):
        return np.where(self.on_axis[node], self.first[node], self.first[node] + k % self.segments)

    def _triangles(self, edges) -> np.ndarray:
        S = self.segments
        k = np.arange(S)
        tris = []
        for a, b in edges:
            a0, a1, b0, b1 = self._point(a, k), self._point(a, k + 1), self._point(b, k), self._point(b, k + 1)
            # quad a0 b0 b1 a1; drop the triangle that collapses at a pole
            if not self.on_axis[b]:
                tris.append(np.stack([a0, b1, b0], axis=1))
            if not self.on_axis[a]:
                tris.append(np.stack([a0, a1, b1], axis=1))
        return np.concatenate(tris).astype(np.int64)

    def points(self, r: np.ndarray, z: np.ndarray) -> np.ndarray:
        """3D points of the surface swept by a meridian (r, z), each (N,) [m]; shape (n_points, 3)."""
        rn, zn = np.asarray(r, dtype=float)[self.node_of_point], np.asarray(z, dtype=float)[self.node_of_point]
        return np.stack([rn * np.cos(self.angle), rn * np.sin(self.angle), zn], axis=1)

    def nodal(self, values: np.ndarray) -> np.ndarray:
        """Node values (N,) or (N, c) spread to the surface's points, shape (n_points,) or (n_points, c)."""
        return np.asarray(values)[self.node_of_point]

    def vector(self, vr: np.ndarray, vz: np.ndarray) -> np.ndarray:
        """A meridional vector field (v_r, v_z) of the nodes as 3D vectors at the points, (n_points, 3)."""
        vr, vz = self.nodal(vr), self.nodal(vz)
        return np.stack([vr * np.cos(self.angle), vr * np.sin(self.angle), vz], axis=1)


def enclosed_volume(points: np.ndarray, triangles: np.ndarray) -> float:
    """Signed volume enclosed by a triangulated surface [m^3] (divergence theorem).

    V = (1/6) sum over triangles of a . (b x c): exact for a closed surface, and for an open one
    the volume of the cone joining it to the origin (which is the volume between the surface and
    the plane z = 0 when its rim lies in that plane).
    """
    a, b, c = (points[triangles[:, i]] for i in range(3))
    return float(np.einsum("ij,ij->", a, np.cross(b, c)) / 6.0)


def write_surface(path, points: np.ndarray, triangles: np.ndarray, point_data: dict | None = None) -> Path:
    """Write one triangulated surface to a .vtu file (binary, via meshio).

    Parameters
    ----------
    points : ndarray (P, 3)
        [m].
    triangles : ndarray of int (T, 3)
    point_data : dict of str -> ndarray (P,) or (P, 3), optional
    """
    meshio = require_meshio()
    path = Path(path)
    mesh = meshio.Mesh(points, [("triangle", triangles)],
                       point_data={k: np.ascontiguousarray(v, dtype=float) for k, v in (point_data or {}).items()})
    tmp = path.with_name(path.stem + ".tmp" + path.suffix)
    meshio.write(tmp, mesh, file_format="vtu")
    os.replace(tmp, path)
    return path


def write_pvd(path, entries) -> Path:
    """Write a ParaView collection: ``entries`` are (time or parameter value, part, file name) triples,
    file names relative to the .pvd's folder; parts number the surfaces shown together."""
    path = Path(path)
    lines = ['<?xml version="1.0"?>',
             '<VTKFile type="Collection" version="0.1" byte_order="LittleEndian">', "  <Collection>"]
    for value, part, name in entries:
        lines.append(f'    <DataSet timestep="{float(value):.17g}" group="" part="{int(part)}" '
                     f"file={quoteattr(str(name))}/>")
    lines += ["  </Collection>", "</VTKFile>", ""]
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text("\n".join(lines))
    os.replace(tmp, path)
    return path
