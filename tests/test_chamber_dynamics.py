"""Dynamics of membranes coupled through chambers (snapmem.dynamics.supplies): two unequal balloons
emptying one into the other against the exact pair, energy conservation at the scheme's order, a
flow source against the static p(V) curve, and a resistance-fed balloon's relaxation time."""

import math

import numpy as np
import pytest
from scipy.integrate import quad
from scipy.optimize import brentq

from snapmem import build_scene
from snapmem.catalog.chambers import balloon_membrane
from snapmem.catalog.scenes import get_spec
from snapmem.continuation.chambers import ChamberProblem
from snapmem.dynamics.driver import DynamicsOptions, simulate
from snapmem.dynamics.supplies import flow_volume
from snapmem.errors import SnapmemError
from snapmem.model.chambers import Chamber
from snapmem.model.multi import MultiScene
from snapmem.reference.exact import balloon_pressure
from snapmem.reference.two_balloons import balloon_volume, pair_stable
from snapmem.statics import equilibrium


def one_balloon(nodes, **params):
    """The MODEL.md balloon (R = 10) bounding a fluid chamber of its own."""
    params = get_spec("two_balloons").resolve(nodes=nodes, **params)
    return MultiScene([balloon_membrane(params, (), 10.0, "balloon")], [Chamber("volume", (0,))], name="balloon")


def exact_unequal_pair(lam0, R1, R2):
    """The stable equilibria (lam1, lam2, p) of balloons R1 < R2 holding the volume of both at lam0,
    with balloon 1 the smaller: p(lam1; R1) = p(lam2; R2), V1 + V2 = V0, p1'(V1) + p2'(V2) > 0."""
    V0 = float(balloon_volume(lam0, R1) + balloon_volume(lam0, R2))

    def lam2_of(l1):
        return ((V0 - balloon_volume(l1, R1)) / (4.0 / 3.0 * math.pi * R2 ** 3)) ** (1.0 / 3.0)

    def f(l1):
        return balloon_pressure(l1, R=R1) - balloon_pressure(lam2_of(l1), R=R2)

    grid = np.linspace(1.0001, (V0 / (4.0 / 3.0 * math.pi * R1 ** 3)) ** (1.0 / 3.0) - 1e-6, 4000)
    values = np.array([f(x) for x in grid])
    out = []
    for i in np.flatnonzero(np.sign(values[:-1]) != np.sign(values[1:])):
        l1 = brentq(f, grid[i], grid[i + 1], xtol=1e-14)
        l2 = float(lam2_of(l1))
        if pair_stable(l1, l2, R1, R2) and l1 < l2:
            out.append((l1, l2, float(balloon_pressure(l1, R=R1))))
    return out


@pytest.mark.parametrize("nodes", [51, 101])
def test_the_smaller_balloon_empties_into_the_larger_ending_at_the_exact_stable_pair(nodes):
    R1, R2, lam0 = 10.0, 10.5, 1.6
    (lam1, lam2, p), = exact_unequal_pair(lam0, R1, R2)          # one stable pair with balloon 1 small
    scene = build_scene("two_balloons", nodes=nodes, R1=R1, R2=R2)
    q0 = lam0 * scene.reference_state()                          # both at one stretch, past the maximum
    run = simulate(scene, {}, t_end=3000.0, rho=1.0, damping=0.3, q0=q0,
                   options=DynamicsOptions(scheme="euler", tol=1e-3, dt=1e-2, dt_max=100.0))
    assert run.meta["status"] == "completed"
    assert np.ptp(run["volume"]) < 1e-9 * run["volume"][0]      # the fluid's volume is held
    assert run["stretch_1"][-1] < lam0 < run["stretch_2"][-1]     # the smaller one emptied
    assert run["stretch_1"][-1] == pytest.approx(lam1, rel=1e-3)
    assert run["stretch_2"][-1] == pytest.approx(lam2, rel=1e-3)
    assert run["load_pressure"][-1] == pytest.approx(p, rel=1e-3)
    assert run["volume_1"][-1] + run["volume_2"][-1] == pytest.approx(run["volume"][-1], rel=1e-12)


@pytest.mark.parametrize("chamber", ["gas", "volume"])
def test_undamped_total_energy_drifts_at_the_midpoint_rules_order_two(chamber):
    scene = build_scene("two_balloons", nodes=21, chamber=chamber)
    first, second = scene.split(scene.reference_state())
    q0 = np.concatenate([1.3 * first, 1.2 * second])             # out of equilibrium: they swing
    drifts = []
    for dt in (0.4, 0.2, 0.1):
        run = simulate(scene, {}, t_end=20.0, rho=1.0, damping=0.0, q0=q0,
                       options=DynamicsOptions(scheme="midpoint", adaptive=False, dt=dt))
        assert run.meta["status"] == "completed"
        assert np.ptp(run["kinetic"]) > 0.5                         # it does swing
        drifts.append(np.abs(run["total"] - run["total"][0]).max())
    orders = np.log2(np.array(drifts[:-1]) / np.array(drifts[1:]))
    assert np.all(np.abs(orders - 2.0) < 0.1), (drifts, orders)
    assert drifts[-1] < 1e-3 * np.ptp(run["kinetic"])
    if chamber == "gas":             # the gas law at every frame
        amount = (0.0 + 0.25) * scene.chamber_volume(q0, 0)
        volumes = np.array([scene.chamber_volume(q, 0) for q in run["q"]])
        np.testing.assert_allclose((run["load_pressure"] + 0.25) * volumes, amount, rtol=1e-12)


def _static_pressure(scene, q, p, volume):
    """The discrete balloon's pressure at fluid volume ``volume`` (Newton on the chamber problem from q)."""
    problem = ChamberProblem(scene, "volume")
    x, _ = problem.unknowns(q, {"pressure": p})
    for _ in range(30):
        F, J = problem.evaluate(x, volume)
        if np.abs(F).max() < 1e-12:
            break
        x = x - J.factor(J.A.factor()).solve(F)
    return float(x[-1])


def test_a_slow_flow_source_follows_the_static_curve_its_lag_falling_with_the_rate():
    scene = one_balloon(21)
    V0 = scene.volume(scene.reference_state())
    V_end = float(balloon_volume(1.35))
    lags = []
    for rate in (4.0, 2.0):
        schedule = flow_volume(V0, [(0.0, 0.0), (50.0, rate)])        # the rate ramps in, then holds
        t_end = 25.0 + (V_end - V0) / rate
        run = simulate(scene, {"fluid_volume": schedule}, t_end=t_end, rho=1.0, damping=0.1,
                       options=DynamicsOptions(scheme="bdf2", tol=1e-4, dt=1e-2, dt_max=5.0))
        assert run.meta["status"] == "completed"
        np.testing.assert_allclose(run["volume"], run["load_fluid_volume"], rtol=1e-8)
        np.testing.assert_allclose(run["load_fluid_volume"][-1], V_end, rtol=1e-12)  # V0 + int Q
        last = -1
        static = _static_pressure(scene, run["q"][last], run["load_pressure"][last], run["load_fluid_volume"][last])
        lags.append(run["load_pressure"][last] / static - 1.0)
    assert 0 < lags[1] < lags[0] < 2e-3                  # the damping's lag behind the static curve
    assert lags[0] / lags[1] == pytest.approx(2.0, rel=0.15)   # proportional to the rate


@pytest.mark.parametrize("scheme", ["bdf2", "midpoint"])
def test_a_resistance_fed_balloon_relaxes_with_time_constant_R_flow_dV_dp(scheme):
    scene = one_balloon(31)
    membrane = scene.membranes[0]
    p0 = float(balloon_pressure(1.2))
    dp = 1e-3 * p0                                                  # linear: a small step of the source
    start, end = equilibrium(membrane, {"pressure": p0}), equilibrium(membrane, {"pressure": p0 + dp})
    V0, V1 = membrane.volume(start.q), membrane.volume(end.q)
    resistance = 100.0 * dp / (V1 - V0)                               # tau = R_flow dV/dp = 100 s
    tau = resistance * (V1 - V0) / dp
    run = simulate(scene, {"source_pressure": p0 + dp, "flow_resistance": resistance, "pressure": p0},
                   t_end=3.0 * tau, rho=1e-3, damping=1.0, q0=start.q,
                   options=DynamicsOptions(scheme=scheme, tol=1e-5, dt=1e-2, dt_max=tau / 50))
    assert run.meta["status"] == "completed"
    t, V = run["t"], run["volume"]
    level = V0 + (1.0 - math.exp(-1.0)) * (V1 - V0)
    i = int(np.flatnonzero(V > level)[0])
    crossing = t[i - 1] + (level - V[i - 1]) * (t[i] - t[i - 1]) / (V[i] - V[i - 1])
    assert crossing == pytest.approx(tau, rel=5e-3)                   # V - V1 ~ exp(-t / tau)
    assert (V1 - V[-1]) / (V1 - V0) == pytest.approx(math.exp(-3.0), rel=0.03)
    assert run["fluid_volume_state"][-1] == pytest.approx(V[-1], rel=1e-6)


def test_flow_volume_integrates_a_piecewise_linear_rate_exactly():
    points = [(0.0, 0.0), (1.0, 2.0), (3.0, -1.0)]
    V = flow_volume(5.0, points)
    rate = lambda s: float(np.interp(s, *zip(*points)))               # noqa: E731
    for t in (0.0, 0.5, 1.0, 2.2, 3.0, 4.5):
        assert V(t) == pytest.approx(5.0 + quad(rate, 0.0, t, points=[1.0, 3.0])[0], rel=1e-13, abs=1e-13)
    assert flow_volume(1.0, 0.5)(4.0) == 3.0
    with pytest.raises(SnapmemError):
        flow_volume(1.0, [1.0, 2.0])


def test_a_chamber_cannot_be_both_prescribed_and_fed():
    scene = one_balloon(11)
    with pytest.raises(SnapmemError, match="not both"):
        simulate(scene, {"fluid_volume": 5000.0, "source_pressure": 0.01, "flow_resistance": 1.0}, t_end=1.0)
    with pytest.raises(SnapmemError, match="flow_resistance"):
        simulate(scene, {"source_pressure": 0.01}, t_end=1.0)
    with pytest.raises(SnapmemError, match="no such load"):
        simulate(scene, {"gas_amount": 1.0}, t_end=1.0)


def test_pump2_snaps_at_the_active_plates_limit_pressure_and_pumps_into_the_passive_plate():
    from snapmem.catalog.robots import events, run
    traj = run("pump2")
    assert traj.meta["status"] == "completed"
    found = events(traj)
    p = traj.meta["parameters"]
    assert p["t_up"] < found["snap"] < p["t_hold"] and found["snap_back"] > p["t_down"]
    # the passive plate is far more compliant than the active plate's falling branch is steep, so
    # the pair snaps just past the active plate's limit point at 300 V (79.9 Pa, pump_prestretch.csv)
    assert found["snap_pressure"] == pytest.approx(79.906, rel=5e-3)
    # what the active plate gives up when the voltage goes off, the passive one takes (one fluid)
    t, V2 = traj["t"], traj["volume_2"]
    gained = float(np.diff(np.interp([p["t_hold"], p["t_down"]], t, V2))[0])
    assert gained == pytest.approx(found["pumped_volume"], rel=1e-6)
    assert found["pumped_volume"] > 0.05                                 # [m^3]
    silent = events(run("pump2", voltage=0.0, t_end=16.0))                # no voltage: nothing to pump
    assert math.isnan(silent["snap"])


def test_an_interrupted_chamber_run_keeps_its_frames_and_the_chambers_columns():
    scene = one_balloon(11, stretch_limit=3.0)
    V0 = scene.volume(scene.reference_state())

    def interrupt(t, t_end):
        if t > 2.05:                            # after the step to t = 2.1
            raise KeyboardInterrupt

    traj = simulate(scene, {"fluid_volume": flow_volume(V0, 100.0)}, 10.0, rho=1.0, damping=0.5,
                    progress=interrupt, options=DynamicsOptions(scheme="euler", dt=0.1, adaptive=False))
    assert traj.meta["status"].startswith("interrupted at t = 2.1")
    assert len(traj["t"]) == len(traj["volume_1"]) == len(traj["load_pressure"]) == len(traj["r_1"]) == 22
    # Euler holds the fluid's volume at every step's end (the midpoint rule: at the step's middle)
    np.testing.assert_allclose(traj["volume"], V0 + 100.0 * traj["t"], rtol=1e-9)
    assert np.all(np.isfinite(traj["total"])) and traj["load_pressure"][-1] > 0
    measured = scene.measures(traj["q"][-1])                # the per-membrane columns are the measures
    for key in ("volume_1", "u_max_1", "stretch_max_1", "stretch_1"):
        assert traj[key][-1] == pytest.approx(measured[key], rel=1e-12), key
    np.testing.assert_allclose(traj["rupture_margin"], 3.0 / traj["stretch_max_1"], rtol=1e-12)
    assert np.all(traj["breakdown_margin_1"] == np.inf)                 # no breakdown strength set


# ------------------------------------------------------------------------------------------------
# the compiled bordered step (snapmem.dynamics.compiled_chambers) against the numpy step
def _both_steps(monkeypatch, make_run):
    """(compiled run, numpy run) of make_run(), the numpy one with the compiled step refused; the
    first must have taken the compiled step."""
    import snapmem.dynamics.supplies as supplies
    seen = []
    original = supplies.ChamberStepper.__init__

    def spy(self, *args, **kwargs):
        original(self, *args, **kwargs)
        seen.append(self.compiled)
    with monkeypatch.context() as patch:
        patch.setattr(supplies.ChamberStepper, "__init__", spy)
        compiled = make_run()
        patch.setattr(supplies.ChamberCompiledStep, "of", classmethod(lambda cls, scene, multiplied: None))
        numpy_run = make_run()
    assert seen[0] is not None and seen[-1] is None
    return compiled, numpy_run


def _agree_to_round_off(a, b, columns):
    assert a.meta["status"] == b.meta["status"] == "completed"
    assert a.meta["steps"] == b.meta["steps"] and a.meta["rejected"] == b.meta["rejected"]
    np.testing.assert_allclose(a["t"], b["t"], rtol=1e-9, atol=0)      # the step control amplifies rounding
    scale = np.abs(b["q"]).max()
    assert np.abs(a["q"] - b["q"]).max() < 1e-10 * scale
    for key in list(columns) + ["potential", "total", "chamber_energy", "volume"]:   # the frames' measures too
        np.testing.assert_allclose(a[key], b[key], rtol=1e-9, atol=1e-12 * np.abs(b[key]).max(), err_msg=key)


def test_the_compiled_chamber_step_takes_pump2s_steps_as_the_numpy_step_to_round_off(monkeypatch):
    from snapmem.catalog.robots import run
    compiled, numpy_run = _both_steps(monkeypatch, lambda: run("pump2", t_end=13.0))     # past the snap (12.6 s)
    _agree_to_round_off(compiled, numpy_run, ["load_pressure", "volume_1", "volume_2", "kinetic_1"])
    assert compiled["volume_1"].max() > 0.2                      # it did snap (0.0026 -> 0.27 m^3)


@pytest.mark.parametrize("chamber", ["volume", "gas"])
def test_the_compiled_chamber_step_empties_the_smaller_balloon_as_the_numpy_step(monkeypatch, chamber):
    scene = build_scene("two_balloons", nodes=21, R1=10.0, R2=10.5, chamber=chamber)
    q0 = 1.6 * scene.reference_state()

    def make_run():
        return simulate(scene, {}, t_end=300.0, rho=1.0, damping=0.3, q0=q0,
                        options=DynamicsOptions(scheme="euler", tol=1e-3, dt=1e-2, dt_max=100.0))
    compiled, numpy_run = _both_steps(monkeypatch, make_run)
    _agree_to_round_off(compiled, numpy_run, ["load_pressure", "volume_1", "volume_2", "stretch_1", "stretch_2"])
    assert compiled["stretch_1"][-1] < 1.6 < compiled["stretch_2"][-1]      # it got to the emptying


def test_the_compiled_chamber_step_relaxes_a_resistance_fed_balloon_as_the_numpy_step(monkeypatch):
    scene = one_balloon(21)
    p0 = float(balloon_pressure(1.2))
    dp = 1e-3 * p0
    start, end = equilibrium(scene.membranes[0], {"pressure": p0}), equilibrium(scene.membranes[0], {"pressure": p0 + dp})
    V0, V1 = (scene.membranes[0].volume(e.q) for e in (start, end))
    resistance = 100.0 * dp / (V1 - V0)                               # tau = 100 s

    def make_run():
        return simulate(scene, {"source_pressure": p0 + dp, "flow_resistance": resistance, "pressure": p0},
                        t_end=50.0, rho=1e-3, damping=1.0, q0=start.q,
                        options=DynamicsOptions(scheme="bdf2", tol=1e-5, dt=1e-2, dt_max=2.0))
    compiled, numpy_run = _both_steps(monkeypatch, make_run)
    _agree_to_round_off(compiled, numpy_run, ["load_pressure", "volume", "fluid_volume_state"])
    assert (compiled["volume"][-1] - V0) / (V1 - V0) == pytest.approx(1.0 - math.exp(-0.5), rel=0.02)  # filling


def test_the_compiled_chamber_step_runs_a_prescribed_pressure_chamber_and_a_fluid_one_side_by_side(monkeypatch):
    """Two balloons, one under a prescribed pressure (a load, no border) and one on a fluid chamber:
    the pressure-driven one creeps towards its equilibrium at that pressure, as the numpy step."""
    params = get_spec("two_balloons").resolve(nodes=21)
    membranes = [balloon_membrane(params, (), 10.0, "pressed"), balloon_membrane(params, (), 10.0, "held")]
    p = float(balloon_pressure(1.3))
    scene = MultiScene(membranes, [Chamber("pressure", (0,), pressure=p), Chamber("volume", (1,))], name="pair")
    first, second = scene.split(scene.reference_state())
    q0 = np.concatenate([1.2 * first, 1.25 * second])

    def make_run():
        return simulate(scene, {}, t_end=200.0, rho=1.0, damping=0.5, q0=q0,
                        options=DynamicsOptions(scheme="bdf2", tol=1e-4, dt=1e-2, dt_max=5.0))
    compiled, numpy_run = _both_steps(monkeypatch, make_run)
    _agree_to_round_off(compiled, numpy_run, ["load_pressure_2", "volume_1", "volume_2", "stretch_1"])
    rest = equilibrium(membranes[0], {"pressure": p})         # the pressed balloon's equilibrium at p
    settled = membranes[0].volume(rest.q)
    assert abs(compiled["volume_1"][-1] - settled) < 0.1 * abs(compiled["volume_1"][0] - settled)   # creeping there
    assert np.ptp(compiled["volume_2"]) < 1e-9 * compiled["volume_2"][0]  # the fluid's volume held
