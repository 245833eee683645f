"""Every study runs on its small setting (--quick) and its table holds a number worth checking."""

import importlib.util
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

STUDIES = Path(__file__).resolve().parents[1] / "studies"


def run(name, tmp_path):
    spec = importlib.util.spec_from_file_location(name, STUDIES / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    module.main(["--quick", "--out", str(tmp_path)])
    return lambda table: pd.read_csv(tmp_path / f"{table}.csv")


def test_fig3(tmp_path):
    read = run("fig3_validation", tmp_path)
    assert read("fig3_plate")["point"].isna().all()          # no limit point on the MR plate (an empty column)
    torus = read("fig3_torus")
    assert torus.loc[torus["point"] == "LP", "pressure"].iloc[0] == pytest.approx(0.04091, rel=5e-3)
    assert read("fig3_balloon")["stretch"].iloc[-1] == pytest.approx(4.0, abs=1e-9)


def test_fig4(tmp_path):
    read = run("fig4_electro_balloon", tmp_path)
    a = read("fig4a_balloon_pressure")
    assert np.max(np.abs(a["pressure"] - a["p_exact"])) < 2e-4            # N = 41 against the exact curve
    b = read("fig4b_balloon_voltage")
    lp = b[(b["point"] == "LP") & (b["p_hat"] == 0.0095)]["E_hat"].iloc[0]
    assert lp == pytest.approx(0.3954, rel=5e-3)


def test_fig5(tmp_path):
    read = run("fig5_electro_torus", tmp_path)
    a = read("fig5a_torus_pressure")
    limits = a[a["point"] == "LP"].groupby("E_hat_value")["pressure"].first()
    assert limits.is_monotonic_decreasing and limits.loc[0.0] == pytest.approx(0.04091, rel=1e-2)


def test_torus_limit_maps(tmp_path):
    read = run("torus_limit_maps", tmp_path)
    pm = read("torus_limit_pressure_map")
    assert {"aspect_ratio", "E_hat", "p_limit", "u_max_limit"} <= set(pm.columns)
    checked = pm.dropna(subset=["p_limit_traced"])
    assert len(checked) >= 1 and np.allclose(checked["p_limit"], checked["p_limit_traced"], rtol=1e-8)
    vm = read("torus_limit_voltage_map")
    assert {"aspect_ratio", "pressure", "E_hat_limit", "u_max_limit"} <= set(vm.columns)
    assert (~vm["exists"]).any() and vm["exists"].any()                  # some designs have no limit point


def test_torus_limit_convergence(tmp_path):
    t = run("torus_limit_convergence", tmp_path)("torus_limit_convergence")
    assert 1.8 < t["observed_order"].iloc[-1] < 2.2


def test_error_vs_runtime(tmp_path):
    t = run("error_vs_runtime", tmp_path)("error_vs_runtime")
    curve = t[t["problem"] == "balloon curve"].set_index("setting")["error"]
    assert 3.5 < curve.loc[21] / curve.loc[41] < 4.5                     # N^-2 against the exact formula
    assert set(t[t["problem"].str.startswith("dynamic")]["method"]) == {"euler", "midpoint", "bdf2"}


def test_fig9(tmp_path):
    started = time.perf_counter()
    read = run("fig9_timing", tmp_path)
    elapsed = time.perf_counter() - started
    a, b = read("fig9a_static_cost"), read("fig9b_dynamic_cost")
    assert (b["status"] == "completed").all()
    # each row times its own run inside the study: finite, positive, and together no more than
    # the study took (a start time or a running total instead would fail this)
    walls = pd.concat([a["wall_time_s"], b["wall_time_s"]])
    assert np.isfinite(walls).all() and (walls > 0).all() and walls.sum() <= elapsed


@pytest.mark.parametrize("design", [{"case": "mesh", "parameters": '{"nodes": 11}'},
                                    {"case": "fat_torus", "parameters": '{"aspect_ratio": 0.95}'},
                                    {"case": "no_equilibrium", "parameters": '{"E_hat": 1.0}'}])
def test_stress_cases_succeed_or_fail_clearly(design):
    from snapmem import stress_cases as stress
    row = stress.run_case(design)
    assert row["outcome"] == "ok" and row["message"]
    # no equilibrium exists at E_hat = 1: the solve reports a failure, and the row says why
    assert (row["reason"] == stress.NO_EQUILIBRIUM_REASON) == (design["case"] == "no_equilibrium")


def test_fig6_8_robots(tmp_path):
    robots = tmp_path / "robots"
    robots.mkdir()
    spec = importlib.util.spec_from_file_location("robot_curves", STUDIES / "robot_curves.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    module.main(["--quick", "--out", str(robots)])
    spec = importlib.util.spec_from_file_location("fig6_8_robots", STUDIES / "fig6_8_robots.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    cycle = module.main(["--quick", "--out", str(tmp_path), "--tables", str(robots)])
    assert cycle["volume"].max() > 100 * cycle["volume"].iloc[0]          # the pump snapped through
    assert (tmp_path / "fig7_gripper_rod_force.png").stat().st_size > 1000


def test_contact_barrier(tmp_path):
    """A wider barrier holds the ball higher: its gap at rest is about 0.75 dhat, so the rest height
    rises by at least about that much of the 2 mm of width added (measured: 3.6 mm, the rest from
    a contact spread over more edges indenting the balloon less)."""
    t = run("contact_barrier", tmp_path)("contact_barrier").set_index("dhat")
    rise = t.loc[3e-3, "rest_height"] - t.loc[1e-3, "rest_height"]
    assert 0.7 * 2e-3 < rise < 3.0 * 2e-3
    assert (t["drop_min_gap"] > 0).all() and (t["gripper_min_gap"] > 0).all()
    assert t["drop_impact"].lt(t["drop_bounce"]).all() and t["drop_bounce"].lt(t["drop_rebound"]).all()
    assert t.loc[1e-3, "rest_height_rel"] == 0.0                 # the finest barrier of the quick grid


def test_failure_cost(tmp_path):
    """The benchmark times what it says: with the checks, the balloon under pressure locates EB
    (one more point), without them no EB and no RU; every other event the same. (Its timings are
    not asserted: they are the benchmark's output.)"""
    t = run("failure_cost", tmp_path)("failure_cost").set_index(["design", "control"])
    pressure = t.loc[("balloon", "pressure")]
    assert "EB" in pressure["events_checked"].split() and pressure["points"] == pressure["points_unchecked"] + 1
    for (design, control), row in t.iterrows():
        unchecked = row["events_unchecked"].split()
        assert "EB" not in unchecked and "RU" not in unchecked
        assert [e for e in row["events_checked"].split() if e not in ("EB", "RU")] == unchecked
        assert np.isfinite(row["cost_ratio_median"]) and row["pairs"] == 3
