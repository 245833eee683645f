"""VTK export: the files read back with meshio, and the exported surface encloses the model's volume.

The revolved polyhedron's rings are regular polygons inscribed in the circles, so its volume is
the meridian's times sin(2 pi/S) / (2 pi/S): the relative error is (2 pi/S)^2/6 + O(S^-4)
(1.6e-3 at S = 64). The test fits the order on a log-log line and asserts ~2.
"""

from __future__ import annotations

import numpy as np
import pytest

from snapmem.catalog.robots import run
from snapmem.catalog.scenes import build_scene
from snapmem.continuation import trace
from snapmem.dynamics.trajectory import Trajectory
from snapmem.errors import SnapmemError
from snapmem.io.vtk import enclosed_volume
from snapmem.viz.export import export

meshio = pytest.importorskip("meshio")


@pytest.fixture(scope="module")
def snap(tmp_path_factory):
    """torus_snap through its snap (t = 7.6 s), coarse: a trajectory file and its volumes."""
    full = run("torus_snap", t_end=10.0, nodes=60)
    keep = np.unique(np.linspace(0, len(full["t"]) - 1, 6).astype(int))       # 6 frames are enough
    traj = Trajectory({k: v[keep] for k, v in full.data.items()}, full.meta)
    path = traj.save(tmp_path_factory.mktemp("traj") / "snap.npz")
    return path, traj


def read_volume(path) -> float:
    mesh = meshio.read(path)
    return enclosed_volume(mesh.points, mesh.cells_dict["triangle"])


def test_trajectory_volume_converges_as_segments_squared(snap, tmp_path):
    path, traj = snap
    last = len(traj["t"]) - 1
    segments = np.array([16, 32, 64, 128])
    errors = []
    for s in segments:
        out = export(path, tmp_path / f"s{s}", segments=int(s))
        assert len(out.membrane) == len(traj["t"])
        errors.append(abs(read_volume(out.membrane[last]) / traj["volume"][last] - 1.0))
    errors = np.array(errors)
    assert errors[segments == 64][0] < 2e-3
    order = -np.polyfit(np.log(segments), np.log(errors), 1)[0]
    assert order == pytest.approx(2.0, abs=0.05)
    # every frame, not just the last: the snapped torus and the one at rest
    out = export(path, tmp_path / "s64", segments=64)
    for i in (0, last // 2, last):
        assert read_volume(out.membrane[i]) == pytest.approx(traj["volume"][i], rel=2e-3)


def test_trajectory_fields_and_series(snap, tmp_path):
    path, traj = snap
    out = export(path, tmp_path, segments=12)
    mesh = meshio.read(out.membrane[-1])
    n = traj["r"].shape[1]
    assert mesh.points.shape == (12 * n, 3)                # a torus: no node on the axis
    assert mesh.cells_dict["triangle"].shape == (2 * 12 * n, 3)
    data = mesh.point_data
    assert {"lam1", "lam2", "tension_meridional", "tension_hoop", "thickness", "displacement"} <= set(data)
    assert "electric_field" not in data                   # torus_snap has no voltage
    # stretches and thickness recomputed here from the coordinates, edge by edge (closed meridian),
    # then averaged onto nodes: ring 0 (angle 0, the points k = 0 of each node) carries them
    H = traj.meta["parameters"]["H"]
    ref = _reference(traj).reshape(n, 2)
    cur = traj["q"][-1][:2 * n].reshape(n, 2)
    nxt = np.roll(np.arange(n), -1)
    lam1 = np.linalg.norm(cur[nxt] - cur, axis=1) / np.linalg.norm(ref[nxt] - ref, axis=1)
    lam2 = (cur[nxt, 0] + cur[:, 0]) / (ref[nxt, 0] + ref[:, 0])
    h = H / (lam1 * lam2)
    ring = np.arange(n) * 12

    def node_mean(e):
        return 0.5 * (e + np.roll(e, 1))

    np.testing.assert_allclose(data["lam1"][ring], node_mean(lam1), rtol=1e-12)
    np.testing.assert_allclose(data["lam2"][ring], node_mean(lam2), rtol=1e-12)
    np.testing.assert_allclose(data["thickness"][ring], node_mean(h), rtol=1e-12)
    assert np.all(data["tension_hoop"] > 0)               # inflated: taut
    # ring 0 lies in the plane y = 0: its displacement is the meridian's (r, z) displacement
    ring0 = np.flatnonzero(np.isclose(mesh.points[:, 1], 0.0) & (mesh.points[:, 0] > 0))
    d = traj["q"][-1][:2 * n] - _reference(traj)
    np.testing.assert_allclose(data["displacement"][ring0][:, [0, 2]], d.reshape(n, 2), atol=1e-9)
    # the .pvd lists every frame at its time
    text = out.pvd.read_text()
    assert text.count("<DataSet") == len(traj["t"])
    assert f'timestep="{traj["t"][-1]:.17g}"' in text


def _reference(traj):
    scene = build_scene("torus_snap", nodes=traj["r"].shape[1])
    return scene.meridian.q


def test_branch_of_a_charged_balloon(tmp_path):
    """A branch in E_hat: one surface per point, the electric field voltage / h, the poles single
    points, and the volume of the branch table."""
    scene = build_scene("balloon", ("voltage",), nodes=31, pressure=0.01)
    branch = trace(scene, "E_hat", until={"stretch_max": 1.6})
    out = export(branch, tmp_path, segments=64)
    assert out.kind == "branch" and len(out.membrane) == len(branch.states)
    mesh = meshio.read(out.membrane[-1])
    assert mesh.points.shape == (64 * 29 + 2, 3)
    row = branch.table.iloc[-1]
    assert read_volume(out.membrane[-1]) == pytest.approx(row["volume"], rel=2e-3)
    data = mesh.point_data
    np.testing.assert_allclose(data["E_hat"], row["E_hat"])
    voltage = row["voltage"]
    np.testing.assert_allclose(data["electric_field"] * data["thickness"], voltage, rtol=0.05)
    assert np.all(data["tension_meridional"] > 0)


def test_bodies_are_surfaces_of_their_own(tmp_path):
    """ball_drop: a plate (plane, one file) and a falling ball (one sphere per frame, at its height)."""
    traj = run("ball_drop", t_end=0.02)
    path = traj.save(tmp_path / "ball.npz")
    out = export(path, tmp_path / "vtk", segments=48)
    assert set(out.bodies) == {"plane", "ball"}
    assert len(out.bodies["plane"]) == 1 and len(out.bodies["ball"]) == len(traj["t"])
    ball = meshio.read(out.bodies["ball"][-1])
    rb = traj.meta["parameters"]["rb"]
    centre = ball.points.mean(axis=0)
    assert centre[2] == pytest.approx(traj["ball_z"][-1], abs=1e-12)
    # the polyhedral sphere: volume within its own discretisation error of 4/3 pi rb^3
    assert read_volume(out.bodies["ball"][-1]) == pytest.approx(4 / 3 * np.pi * rb ** 3, rel=1e-2)


def test_bad_inputs(snap, tmp_path):
    path, _ = snap
    with pytest.raises(SnapmemError, match="segments"):
        export(path, tmp_path, segments=2)
    with pytest.raises(SnapmemError, match="format"):
        export(path, tmp_path, format="stl")
    with pytest.raises(SnapmemError, match="no such file"):
        export(tmp_path / "missing.npz", tmp_path)


def test_missing_meshio_says_how_to_install(snap, tmp_path, monkeypatch):
    import builtins
    real_import = builtins.__import__

    def no_meshio(name, *args, **kwargs):
        if name == "meshio":
            raise ImportError("no meshio")
        return real_import(name, *args, **kwargs)

    monkeypatch.setattr(builtins, "__import__", no_meshio)
    with pytest.raises(SnapmemError, match=r'pip install "snapmem\[vtk\]"'):
        export(snap[0], tmp_path)


def test_cli_export(snap, tmp_path, capsys):
    from snapmem.cli import main
    assert main(["export", str(snap[0]), "--format", "vtk", "--out", str(tmp_path), "--segments", "8"]) == 0
    assert "wrote:" in capsys.readouterr().out
    assert (tmp_path / "snap.pvd").exists()
    assert main(["export", str(snap[0]), "--out", str(tmp_path), "--segments", "2"]) == 2
