"""The robotic scenes and torus_snap: registered, buildable, physically sensible on small
settings; contact never penetrated; the CLI's simulate and replay."""

import numpy as np
import pytest

from snapmem import build_scene
from snapmem.cli import main
from snapmem.dynamics.driver import Trajectory, simulate
from snapmem.catalog.robots import ROBOTIC_SCENES, events, experiment, resting, run
from snapmem.catalog.scenes import SCENES


def test_robotic_scenes_are_registered_and_build():
    for name in ROBOTIC_SCENES + ("torus_snap",):
        assert name in SCENES
        ex = experiment(name, nodes=21)
        assert ex.scene.inadmissible(ex.scene.reference_state() if ex.q0 is None else ex.q0) is None
        defaults = {p.name: p.default for p in SCENES[name].parameters}
        assert (ex.t_end, ex.rho, ex.damping) == (defaults["t_end"], defaults["rho"], defaults["xi"])
    paper = {p.name: p.default for p in SCENES["torus_snap"].parameters}      # the C++ code's scene
    assert (paper["rho"], paper["xi"], paper["t_end"], paper["nodes"]) == (100.0, 1.0, 100.0, 200)


def test_torus_snap_settles_at_the_reference_outer_radius():
    """The paper's C++ default scene: snaps through and settles with outer radius near 88.6."""
    traj = run("torus_snap")
    assert traj.meta["status"] == "completed"
    outer = traj["r"][-1].max()
    assert outer == pytest.approx(88.6, rel=2e-3)
    assert 2.0 < traj.snap_time() < 6.0              # p(t) = 100 t crosses the free torus's limit
    assert traj["kinetic"][-1] < 1e-6 * traj["kinetic"].max()


def test_gripper_contact_force_rises_with_pressure_by_continuation():
    """Continuation through the free limit point onto the rod: force zero before contact, then rising."""
    from snapmem.continuation.tracer import ContinuationOptions, trace
    scene = build_scene("gripper_rod", Rw=0.07, nodes=40)
    branch = trace(scene, "pressure", until={"pressure": 2000.0}, options=ContinuationOptions(max_steps=400))
    table = branch.table
    assert table["rod_gap"].min() > 0
    lp = branch.points[branch.points["kind"] == "LP"]["control"].iloc[0]
    assert 1650 < lp < 1800                             # the free torus's limit, paper: about 1750 Pa
    touching = table[table["rod_force"] > 0]
    assert len(touching) > 5
    tail = touching[touching["stable"]]
    assert np.all(np.diff(tail["rod_force"].to_numpy()[-5:]) > 0)


def test_ball_rests_lower_when_heavier_and_higher_at_more_pressure():
    heights = {}
    for mb in (0.1, 0.5):
        for p in (400.0, 500.0):
            scene = build_scene("ball_drop", nodes=31, mb=mb, pressure=p)
            q = resting(scene, p)
            heights[mb, p] = q[-1]
            assert scene.inadmissible(q) is None
    assert heights[0.5, 500.0] < heights[0.1, 500.0]
    assert heights[0.5, 400.0] < heights[0.5, 500.0]


def test_ball_drop_never_penetrates_and_lands():
    ex = experiment("ball_drop", nodes=21, drop=0.01, xi=10.0)
    traj = simulate(ex.scene, ex.loads, 0.4, rho=ex.rho, damping=ex.damping, q0=ex.q0,
                    options=ex.options, damp_bodies=True)
    assert traj.meta["status"] == "completed"
    assert np.all(traj["min_gap"] > 0)
    assert traj["ball_force"].max() > 0
    assert traj["ball_z"][-1] < traj["ball_z"][0]


def test_cli_simulate_and_replay(tmp_path, capsys):
    out = tmp_path / "traj.npz"
    assert main(["simulate", "torus_snap", "--set", "nodes=40", "--t-end", "8", "--quiet", "--frames", "40",
                 "--out", str(out)]) == 0
    text = capsys.readouterr().out
    values = dict(line.split(": ", 1) for line in text.strip().splitlines())
    assert values["status"] == "completed" and float(values["t_end"]) == 8.0
    assert float(values["real_time_factor"]) > 0
    traj = Trajectory.load(out)
    assert traj["r"].shape[1] == 40 and traj["t"][-1] == pytest.approx(8.0)
    gif = tmp_path / "traj.gif"
    assert main(["replay", str(out), "--out", str(gif), "--frames", "6"]) == 0
    assert gif.stat().st_size > 1000


def _study(name):
    import importlib.util
    from pathlib import Path
    path = Path(__file__).resolve().parents[1] / "studies" / f"{name}.py"
    spec = importlib.util.spec_from_file_location(name, path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_bench_robots_quick_runs_and_converges(tmp_path):
    table = _study("bench_robots").main(["--quick", "--scenes", "torus_snap", "gripper_rod",
                                         "--out", str(tmp_path / "bench.csv")])
    row = table.set_index("scene").loc["torus_snap"]
    assert row["converged_1pct"] and row["real_time_factor"] > 50
    assert (tmp_path / "bench.csv.json").exists()


def test_robot_curves_quick_pump_limit_points(tmp_path):
    """At 300 V the pump's limit pressure is below the unactuated one (voltage softens)."""
    limits = _study("robot_curves").main(["--quick", "--only", "pump", "--out", str(tmp_path)])["pump"]
    first = limits[limits["kind"] == "LP"].groupby("phi")["pressure"].first()
    assert 70 < first[300.0] < first[0.0] < 95


def test_event_interpolation_is_exact_for_lines_and_parabolas():
    from snapmem.catalog.robots import _crossing, _extremum
    t = np.linspace(0.0, 1.0, 11)
    line = 2.0 - 3.0 * t
    assert _crossing(t, line, 0.65, falling=True) == pytest.approx(0.45, abs=1e-14)
    assert np.isnan(_crossing(t, line, 0.65, falling=False))
    parabola = 1.0 + 3.0 * (t - 0.437) ** 2
    tm, ym = _extremum(t, parabola, np.ones(t.size, bool), lowest=True)
    assert tm == pytest.approx(0.437, abs=1e-12) and ym == pytest.approx(1.0, abs=1e-12)
    assert _extremum(t, parabola, t > 0.6, lowest=True) is None


def test_ball_drop_events_are_ordered_and_physical():
    """Impact about when free fall from ``drop`` closes the gap, then the lowest point, then the rebound."""
    traj = run("ball_drop", nodes=21, t_end=0.8)
    ev = events(traj)
    drop, dhat, g = 0.05, traj.meta["parameters"]["dhat"], 10.0
    free_fall = np.sqrt(2 * (drop - dhat) / g)                    # undamped; xi = 1 slows it slightly
    assert free_fall < ev["impact"] < 1.05 * free_fall
    assert ev["impact"] < ev["bounce"] < ev["rebound"] < 0.8
    start = traj["ball_z"][0] + traj.meta["parameters"]["R"]
    assert 0 < ev["rebound_height"] < start                       # damping: lower than it fell from
