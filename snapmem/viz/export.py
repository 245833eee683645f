"""3D export for ParaView: a trajectory or a branch as revolved surfaces with their fields.

``export(source, out_dir)`` writes one .vtu per frame (a trajectory) or per point (a branch): the
meridian swept through ``segments`` angles, with point data

- ``lam1``, ``lam2``: meridional and hoop stretch (each node: the mean of its edges);
- ``tension_meridional``, ``tension_hoop``: principal membrane tensions T1, T2 [N/m];
- ``thickness``: current thickness h = H / (lam1 lam2) [m];
- ``electric_field``: true electric field voltage / h [V/m] (scenes with a voltage);
- ``breakdown_margin``: only where the scene provides ``breakdown_margin(q, loads)``;
- ``displacement``: x - x_bar, a 3D vector [m] (ParaView's Warp By Vector reads it).

Each rigid body of the scene (rod, shell, plane, ball) is a surface of its own (one file if it
does not move, one per frame if it does), and a .pvd collection lists them all: a time series
for a trajectory (timestep = t [s]), a parameter series for a branch (timestep = point index,
since a branch's load turns back at its folds; the control value is a constant point array
named after the control, e.g. ``pressure``).
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from snapmem.catalog.loads import loads_needed
from snapmem.catalog.scenes import get_spec
from snapmem.continuation.branch import Branch, load_points
from snapmem.continuation.problems import make_problem
from snapmem.dynamics.trajectory import Trajectory
from snapmem.errors import SnapmemError, read_npz
from snapmem.io.vtk import FORMATS, Revolution, check_segments, require_meshio, write_pvd, write_surface
from snapmem.model.contact import Ball, Plane, Rod, Shell
from snapmem.model.scene import Scene

#: Meridian nodes of a ball's profile (a half circle), before it is swept.
BALL_PROFILE_NODES = 33


@dataclass
class Frame:
    """One state to export: its series value, full state q, loads, and values written as constant
    point data (a branch point's control value)."""

    value: float
    q: np.ndarray
    loads: dict
    constants: dict = field(default_factory=dict)


@dataclass
class Export:
    """What :func:`export` wrote.

    Attributes
    ----------
    pvd : Path
        The ParaView collection (open this one).
    membrane : list of Path
        One .vtu per frame or point.
    bodies : dict of str -> list of Path
        Each rigid body's surface files.
    kind : str
        'trajectory' or 'branch'.
    """

    pvd: Path
    membrane: list
    bodies: dict
    kind: str

    @property
    def files(self) -> list:
        return [self.pvd, *self.membrane, *(p for paths in self.bodies.values() for p in paths)]


def export(source, out_dir, segments: int = 64, format: str = "vtk", scene: Scene | None = None) -> Export:
    """Write a trajectory or a branch as revolved surfaces (.vtu) and a .pvd series in ``out_dir``.

    Parameters
    ----------
    source : str, Path, Trajectory or Branch
        A trajectory (.npz from ``snapmem simulate --out`` or :meth:`Trajectory.save`), a branch
        (.npz saved by ``snapmem trace --out``), or the object itself.
    out_dir : str or Path
        Folder for the files (created if missing).
    segments : int
        Angles the meridian is swept through (>= 3). The surface's volume converges to the
        meridian's as segments^-2 (relative error (2 pi / segments)^2 / 6: 1.6e-3 at 64).
    format : str
        'vtk' (the only one).
    scene : Scene, optional
        The scene of a trajectory object whose scene is not in the catalog; by default the scene
        is rebuilt from the source's recorded name and parameters.

    Returns
    -------
    Export
        The paths written.
    """
    if format not in FORMATS:
        raise SnapmemError(f"format = {format!r}: must be one of {', '.join(FORMATS)}")
    segments = check_segments(segments)
    require_meshio()                                  # fail before any work
    kind, scene, frames, stem = _frames(source, scene)
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)

    membrane = Revolution(scene.meridian.r == 0, scene.meridian.edges, segments)
    membrane_files, entries = [], []
    width = len(str(max(len(frames) - 1, 1)))
    for i, frame in enumerate(frames):
        path = out_dir / f"{stem}_{i:0{width}d}.vtu"
        r, z = frame.q[0:scene.n_node_dofs:2], frame.q[1:scene.n_node_dofs:2]
        write_surface(path, membrane.points(r, z), membrane.triangles, membrane_fields(scene, frame, membrane))
        membrane_files.append(path)
        entries.append((frame.value if kind == "trajectory" else i, 0, path.name))

    bodies = {}
    for part, (name, surfaces) in enumerate(_body_surfaces(scene, frames, segments).items(), start=1):
        if len(surfaces) == 1:                        # a body that does not move: one file
            path = out_dir / f"{stem}_{name}.vtu"
            write_surface(path, *surfaces[0])
            bodies[name] = [path]
            entries += [(value, part, path.name) for value, _, _ in entries[:len(frames)]]
        else:
            bodies[name] = []
            for i, surface in enumerate(surfaces):
                path = out_dir / f"{stem}_{name}_{i:0{width}d}.vtu"
                write_surface(path, *surface)
                bodies[name].append(path)
                entries.append((entries[i][0], part, path.name))
    pvd = write_pvd(out_dir / f"{stem}.pvd", sorted(entries, key=lambda e: (e[0], e[1])))
    return Export(pvd, membrane_files, bodies, kind)


def membrane_fields(scene: Scene, frame: Frame, surface: Revolution) -> dict:
    """Point data of the membrane surface at one frame (see the module docstring), arrays (n_points,)
    or (n_points, 3)."""
    q = frame.q
    lam1, lam2 = scene.stretches(q)
    t1, t2 = scene.tensions(q, frame.loads)
    h = edge_thickness(scene.thickness, lam1, lam2)
    edge_values = {"lam1": lam1, "lam2": lam2, "tension_meridional": t1, "tension_hoop": t2, "thickness": h}
    loads = scene.resolve_loads(frame.loads)
    if "voltage" in loads:
        edge_values["electric_field"] = loads["voltage"] / h
    out = {name: surface.nodal(node_mean(scene.meridian, v)) for name, v in edge_values.items()}
    margin = getattr(scene, "breakdown_margin", None)
    if callable(margin):
        values = np.asarray(margin(q, frame.loads), dtype=float)
        out["breakdown_margin"] = surface.nodal(node_mean(scene.meridian, values)
                                                if values.size == scene.meridian.edges.shape[0] else values)
    d = q[: scene.n_node_dofs] - scene.meridian.q
    out["displacement"] = surface.vector(d[0::2], d[1::2])
    out.update({name: np.full(surface.n_points, value) for name, value in frame.constants.items()})
    return out


def edge_thickness(H: float, lam1: np.ndarray, lam2: np.ndarray) -> np.ndarray:
    """Current thickness h = H / (lam1 lam2) of every edge [m] (incompressible membrane)."""
    return H / (lam1 * lam2)


def node_mean(meridian, edge_values: np.ndarray) -> np.ndarray:
    """Each node's mean of its edges' values, shape (N,) (a pole or an open end: its one edge)."""
    edges = meridian.edges
    total = np.bincount(edges.ravel(), np.repeat(np.asarray(edge_values, dtype=float), 2), minlength=meridian.nodes)
    count = np.bincount(edges.ravel(), minlength=meridian.nodes)
    return total / count


# ------------------------------------------------------------------------------------------------
# sources: trajectories and branches, from files or objects
def _frames(source, scene):
    if isinstance(source, Trajectory):
        return ("trajectory", *_trajectory_frames(source, scene), "trajectory")
    if isinstance(source, Branch):
        problem = make_problem(source.scene, source.control)
        frames = [_branch_frame(problem, p.x, p.lam, source.control) for p in source.states]
        return "branch", source.scene, frames, "branch"
    path = Path(source)
    if not path.exists():
        raise SnapmemError(f"{path}: no such file")
    if path.suffix != ".npz":
        raise SnapmemError(f"{path}: must be the .npz of 'snapmem simulate --out' or 'snapmem trace --out'")
    data = read_npz(path, "trajectory or branch file", required=("meta",))
    if "t" in data and "r" in data:
        meta = json.loads(str(data.pop("meta")))
        return ("trajectory", *_trajectory_frames(Trajectory(data, meta), scene), path.stem)
    if "lam" in data and "x" in data:
        saved = load_points(path)
        meta = saved["meta"]
        scene = scene or _rebuild(meta, loads_needed(meta["control"]))
        problem = make_problem(scene, meta["control"])
        frames = [_branch_frame(problem, x, lam, meta["control"]) for x, lam in zip(saved["x"], saved["lam"])]
        return "branch", scene, frames, path.stem
    raise SnapmemError(f"{path}: neither a trajectory (arrays t, r, z) nor a branch (arrays x, lam); "
                       "export reads the .npz of 'snapmem simulate --out' or 'snapmem trace --out'")


def _branch_frame(problem, x, lam, control) -> Frame:
    q, loads = problem.state(np.asarray(x, dtype=float), float(lam))
    return Frame(float(lam), q, dict(loads), {control: float(lam)})


def _trajectory_frames(traj: Trajectory, scene):
    loads = [k.removeprefix("load_") for k in traj.data if k.startswith("load_")]
    if scene is None:
        scene = _rebuild(traj.meta, tuple(name for name in loads if name == "voltage"))
    q = traj.data.get("q")
    if q is None:
        raise SnapmemError("trajectory: has no states q (saved by an old version?); re-run simulate --out")
    n = scene.reference_state().size
    if q.shape[1] != n:
        raise SnapmemError(f"trajectory: states have {q.shape[1]} unknowns, scene {scene.name!r} has {n}")
    frames = [Frame(float(t), q[i], {name: float(traj[f"load_{name}"][i]) for name in loads})
              for i, t in enumerate(traj["t"])]
    return scene, frames


def _rebuild(meta: dict, with_loads: tuple) -> Scene:
    """The scene a file was computed with, from its recorded name and parameters."""
    name = meta.get("scene")
    if not name:
        raise SnapmemError("the file records no scene name; pass scene= to export()")
    params = {k: v for k, v in (meta.get("parameters") or {}).items() if v is not None}
    return get_spec(name).build(with_loads, **params)


# ------------------------------------------------------------------------------------------------
# rigid bodies: each a revolved profile
def _body_surfaces(scene: Scene, frames, segments: int) -> dict:
    """name -> list of (points, triangles) per frame (one entry when the body does not move)."""
    n = scene.n_node_dofs
    r_all = np.concatenate([f.q[0:n:2] for f in frames])
    z_all = np.concatenate([f.q[1:n:2] for f in frames])
    span = max(np.ptp(z_all), np.max(r_all), 1e-12)
    zlo, zhi = z_all.min() - 0.1 * span, z_all.max() + 0.1 * span
    out, body_index = {}, {b.name: n + i for i, b in enumerate(scene.bodies)}
    for term in scene.node_terms:
        if isinstance(term, (Rod, Shell)):
            name = "rod" if isinstance(term, Rod) else "shell"
            out[_unique(out, name)] = [_revolve([term.radius, term.radius], [zlo, zhi], segments)]
        elif isinstance(term, Plane):
            radius = 1.2 * np.max(r_all)
            out[_unique(out, "plane")] = [_revolve([0.0, radius], [term.z0, term.z0], segments)]
        elif isinstance(term, Ball):
            heights = ([f.q[body_index[term.name]] for f in frames] if term.name in body_index else [term.z0])
            angle = np.linspace(-0.5 * np.pi, 0.5 * np.pi, BALL_PROFILE_NODES)
            pr, pz = term.radius * np.cos(angle), term.radius * np.sin(angle)
            pr[[0, -1]] = 0.0
            out[_unique(out, term.name)] = [_revolve(pr, pz + zb, segments) for zb in heights]
    return out


def _revolve(r, z, segments):
    r, z = np.asarray(r, dtype=float), np.asarray(z, dtype=float)
    idx = np.arange(r.size)
    surface = Revolution(r == 0, np.stack([idx[:-1], idx[1:]], axis=1), segments)
    return surface.points(r, z), surface.triangles


def _unique(existing: dict, name: str) -> str:
    out, i = name, 1
    while out in existing:
        i += 1
        out = f"{name}{i}"
    return out
