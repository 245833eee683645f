"""Failure checks of a real dielectric elastomer (issue 15): breakdown, pull-in (EMI), rupture."""

import numpy as np
import pytest
from scipy.optimize import minimize_scalar

from snapmem.catalog.registry import build_scene
from snapmem.continuation import ContinuationOptions, PointKind, trace
from snapmem.dynamics import DynamicsOptions, simulate
from snapmem.model.local_checks import failure_margins
from snapmem.reference.exact import balloon_e_hat, balloon_pressure

H = 0.1                # the balloon's thickness; mu = eps = 1, so the voltage is E_hat H


def uniform(scene, lam):
    """The balloon inflated uniformly to stretch lam: every edge has lam1 = lam2 = lam exactly."""
    return lam * scene.meridian.q


@pytest.mark.parametrize("exponent, prestretch", [(0.0, 1.0), (0.5, 1.0), (1.5, 1.3)])
def test_breakdown_margin_of_the_uniform_balloon_is_exact(exponent, prestretch):
    """margin = E_B(Lam^2) H / (phi lam^2), lam the stretch from the mounted state, Lam = lp lam."""
    phi, E_b = 0.03, 0.5
    scene = build_scene("balloon", nodes=21, voltage=phi, E_breakdown=E_b, breakdown_exponent=exponent,
                        prestretch=prestretch)
    for lam in (0.9, 1.0, 1.7, 3.2):
        margin = failure_margins(scene, uniform(scene, lam))["breakdown_margin"]
        exact = E_b * (prestretch * lam) ** (2 * exponent) * H / (phi * lam ** 2)
        assert margin == pytest.approx(exact, rel=1e-13)
    assert failure_margins(scene, uniform(scene, 2.0), {"voltage": 0.0})["breakdown_margin"] == np.inf


def test_no_limits_no_failure():
    scene = build_scene("balloon", nodes=11, E_hat=0.3)
    assert failure_margins(scene, uniform(scene, 2.0)) == {"breakdown_margin": np.inf, "rupture_margin": np.inf}


def test_breakdown_located_on_the_inflated_balloon():
    """Under a held voltage E_B / E = E_B H / (phi lam^2) reaches 1 at lam = sqrt(E_B H / phi): the
    EB point is located there (mesh error), on the exact p(lam) curve, and the trace goes on."""
    E_hat, lam_eb = 0.2, 1.3
    E_b = E_hat * lam_eb ** 2                 # [V/m] in the normalised units (mu = eps = 1)
    scene = build_scene("balloon", nodes=41, E_hat=E_hat, E_breakdown=E_b)
    branch = trace(scene, "pressure", until={"stretch": 1.6})
    eb = branch.points[branch.points["kind"] == "EB"]
    assert len(eb) == 1 and bool(eb["located"].iloc[0])
    assert eb["breakdown_margin"].iloc[0] == pytest.approx(1.0, abs=1e-8)
    assert eb["stretch"].iloc[0] == pytest.approx(lam_eb, rel=2e-3)
    assert eb["pressure"].iloc[0] == pytest.approx(balloon_pressure(lam_eb, E_hat=E_hat), rel=3e-3)
    table = branch.table
    assert "EB" in set(table["point"]) and table["stretch"].iloc[-1] == pytest.approx(1.6)
    assert np.all(table["breakdown_margin"][table["stretch"] < 1.29] > 1)


def test_pull_in_is_named_emi_under_voltage_control():
    """The voltage limit point of the balloon at p_hat = 0.0095 (MODEL.md: E_hat vs lam), named EMI."""
    p_hat = 0.0095
    scene = build_scene("balloon", nodes=31, pressure=p_hat, with_loads=("voltage",))
    branch = trace(scene, "voltage", until={"stretch": 2.2}, options=ContinuationOptions(stop_at_first_limit=True))
    emi = branch.limit_points()
    assert list(emi["kind"]) == ["EMI"] and "EMI" in set(branch.table["point"])
    best = minimize_scalar(lambda lam: -balloon_e_hat(lam, p_hat), bounds=(1.2, 2.5), method="bounded",
                           options={"xatol": 1e-10})
    assert emi["E_hat"].iloc[0] == pytest.approx(-best.fun, rel=5e-3)
    assert any(p.kind == PointKind.LP for p in branch.states)     # LP inside, EMI in the tables


def test_rupture_at_the_total_stretch_limit():
    """RU where the largest stretch from the stress-free state reaches stretch_limit: for a balloon
    mounted at prestretch 1.25 and limit 2, at mounted stretch 1.6."""
    scene = build_scene("balloon", nodes=31, prestretch=1.25, stretch_limit=2.0)
    branch = trace(scene, "pressure", until={"stretch": 1.8})
    ru = branch.points[branch.points["kind"] == "RU"]
    assert len(ru) == 1
    assert 1.25 * ru["stretch_max"].iloc[0] == pytest.approx(2.0, rel=1e-8)
    assert ru["stretch"].iloc[0] == pytest.approx(1.6, rel=5e-3)     # N = 31: stretch_max vs the equator's


def test_trajectory_records_the_failure_margins():
    """A held voltage and a slowly rising pressure: breakdown_margin per frame is the edges' min of
    E_B H / (phi lam1 lam2), and failure_time interpolates where it reaches 1."""
    from snapmem.dynamics import schedule
    E_hat, E_b, h = 0.2, 0.2 * 1.2 ** 2, 0.01       # a small balloon (R = 1), quick in time
    scene = build_scene("balloon", nodes=11, R=1.0, H=h, E_hat=E_hat, E_breakdown=E_b)
    traj = simulate(scene, schedule(pressure=[(0, 0), (3.0, 0.012), (6.0, 0.012)]), 6.0, rho=1.0, damping=5.0,
                    options=DynamicsOptions(dt=0.05))
    margins = traj["breakdown_margin"]
    assert margins.shape == traj["t"].shape and np.all(np.isinf(traj["rupture_margin"]))
    assert margins[0] == pytest.approx(E_b / E_hat, rel=1e-12)          # at rest: E_B H / phi
    k = len(margins) // 2
    lam1, lam2 = scene.stretches(traj["q"][k])
    assert margins[k] == pytest.approx(E_b * h / (E_hat * h * np.max(lam1 * lam2)), rel=1e-12)
    t_fail = traj.failure_time("breakdown_margin")
    assert t_fail is not None and margins[traj["t"] < t_fail].min() > 1.0 and margins[-1] < 1.0


def test_breakdown_curve_in_pressure_is_the_exact_one():
    """The EB event of the balloon traced in voltage at p_hat = 0.0095, continued in the pressure:
    every point has E_hat lam^2 = E_B (exponent 0, mu = eps = 1) and lies on the exact p(lam; E_hat),
    through the unstable part between the pressure extrema (mesh error at N = 31)."""
    from snapmem.continuation.event_curves import event_curve
    lam_eb, p_hat = 1.3, 0.0095
    E_b = float(balloon_e_hat(lam_eb, p_hat)) * lam_eb ** 2

    def scene_at(p):
        return build_scene("balloon", nodes=31, pressure=p, with_loads=("voltage",), E_breakdown=E_b)

    branch = trace(scene_at(p_hat), "voltage", until={"stretch": 1.5})
    eb = next(p for p in branch.states if p.kind == PointKind.EB)
    curve = event_curve(scene_at, p_hat, eb.x, eb.lam, "breakdown_margin", v_range=(0.004, 0.0135), ds_max=0.2)
    t = curve.table
    assert curve.status == "left the range of v" and t["stretch"].max() > 3.0
    assert not t["stable"].all() and t["stable"].iloc[-1]
    np.testing.assert_allclose(t["breakdown_margin"], 1.0, atol=1e-9)
    np.testing.assert_allclose(t["E_hat"] * t["stretch"] ** 2, E_b, rtol=1e-2)
    np.testing.assert_allclose(t["pressure"], balloon_pressure(t["stretch"], E_hat=t["E_hat"]), atol=4e-5)


@pytest.mark.slow
def test_actuation_window_study_quick(tmp_path):
    """The study on its small setting: the plate mounted stress-free wrinkles (LT) before it pulls
    in, and every EB row of the window keeps E_B / E = 1."""
    study = _study("actuation_window")
    table, first = study.main(["--quick", "--out", str(tmp_path)])
    plate = first[first["design"] == "plate lp = 1"]
    assert plate["kind"].iloc[0] == "LT" and abs(plate["min_tension"].iloc[0]) < 1e-8
    eb = table[table["curve"] == "EB"]
    assert len(eb) > 5 and np.allclose(eb["breakdown_margin"], 1.0, atol=1e-8)
    assert (tmp_path / "actuation_window.png").exists()


@pytest.mark.slow
def test_pump_prestretch_study_quick(tmp_path):
    """Prestretch 2 raises the pump's snap pressure at 300 V from ~80 Pa to ~386 Pa (N = 31)."""
    study = _study("pump_prestretch")
    snaps = study.main(["--quick", "--out", str(tmp_path)]).set_index(["prestretch", "phi"])
    assert 75.0 < snaps.loc[(1.0, 300.0), "snap_pressure"] < 85.0
    assert 370.0 < snaps.loc[(2.0, 300.0), "snap_pressure"] < 400.0
    assert snaps.loc[(2.0, 300.0), "pumped_volume"] > 0.0


def _study(name):
    """A study script as a module (studies/ is not a package)."""
    import importlib.util
    from pathlib import Path
    spec = importlib.util.spec_from_file_location(name, Path(__file__).parents[1] / "studies" / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_failure_margins_of_many_frames_match_the_single_state_ones():
    scene = build_scene("balloon", nodes=15, E_hat=0.3, E_breakdown=0.5, breakdown_exponent=0.4, stretch_limit=3.0,
                        prestretch=1.2)
    from snapmem.model.local_checks import failure_margins_many
    rng = np.random.default_rng(3)
    Q = np.array([scene.meridian.q * s * (1 + 0.02 * rng.standard_normal(scene.meridian.q.size))
                  for s in (1.0, 1.3, 1.8)])
    Q[:, 0::2][:, [0, -1]] = 0.0                         # poles on the axis
    voltages = np.array([0.0, 0.03, -0.05])
    many = failure_margins_many(scene, Q, voltages)
    for k in range(3):
        one = failure_margins(scene, Q[k], {"voltage": voltages[k]})
        for name in one:
            assert many[name][k] == pytest.approx(one[name], rel=1e-13)
