"""snapmem.reference.paths: curves at values given in advance (load or one coordinate prescribed), and
Richardson's extrapolation; the lean path the peer comparisons (studies/peers.py,
studies/sfepy_balloon.py) time against the ODE and SfePy."""

import importlib.util
from pathlib import Path

import numpy as np
import pytest

from snapmem import SnapmemError, build_scene, exact, solve
from snapmem.continuation.tracer import trace
from snapmem.reference.paths import coordinate_path, extrapolate, load_path

STUDIES = Path(__file__).resolve().parents[1] / "studies"
BALLOON = {"R": 1.0, "H": 0.01, "c1": 3e5, "c2": 3e4}             # SfePy's balloon


def study(name):
    spec = importlib.util.spec_from_file_location(name, STUDIES / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_load_path_states_are_the_equilibria_at_its_loads():
    scene = build_scene("plate", nodes=25)
    pressures = [1e-4, 2e-3, 0.01, 0.03, 0.08]            # uneven steps from nearly flat
    path = load_path(scene, pressures)
    assert path.q.shape == (5, scene.reference_state().size) and np.array_equal(path.loads, pressures)
    for q, p in zip(path.q, pressures):
        again = solve(scene, {"pressure": p}, q0=q)
        assert again.converged and again.report.iterations == 0      # already an equilibrium
        assert np.max(np.abs(again.q - q)) == 0.0


def test_coordinate_path_passes_the_torus_limit_point_where_the_trace_locates_it():
    scene = build_scene("torus", nodes=24)
    seed = solve(scene, {"pressure": 0.005})
    lp = trace(scene, "pressure", until={"outer_radius": 16.0}, start=(seed.q, seed.loads)).limit_points().iloc[0]
    radii = np.linspace(12.05, 17.4, 30)
    path = coordinate_path(scene, 0, radii, (seed.q, seed.loads))
    assert np.allclose(path.q[:, 0], radii, rtol=0, atol=1e-14)
    top = int(np.argmax(path.loads))
    assert 0 < top < len(radii) - 1                                   # a maximum inside: passed
    assert path.loads[top] == pytest.approx(lp["pressure"], rel=2e-3)
    fine = np.linspace(path.q[top - 1, 0], path.q[top + 1, 0], 41)     # the fold, sampled finely
    near = coordinate_path(scene, 0, fine, (path.q[top - 1], {"pressure": path.loads[top - 1]}))
    assert near.loads.max() == pytest.approx(lp["pressure"], rel=1e-6)
    for q, p in zip(path.q[::7], path.loads[::7]):                   # equilibria at the solved pressures
        ev = scene.evaluate(q, {"pressure": p})
        assert np.max(np.abs(ev.residual)) < 1e-9 * scene.force_scale


def test_coordinate_path_converges_at_order_2_and_richardson_removes_it():
    lam = np.array([1.4, 1.8, 2.2, 3.0, 4.3, 5.8])                   # SfePy-like big steps through the fold
    p = {}
    for n in (11, 21, 41):
        scene = build_scene("balloon", nodes=n, **BALLOON)
        p[n] = coordinate_path(scene, 2 * (n // 2), lam, (scene.reference_state(), {"pressure": 0.0})).loads
    p_exact = exact.balloon_pressure(lam, **BALLOON)
    error = {n: np.max(np.abs(p[n] / p_exact - 1)) for n in p}
    assert 3.8 < error[11] / error[21] < 4.2 and 3.8 < error[21] / error[41] < 4.2
    richardson = extrapolate([1 / 10, 1 / 20], [p[11], p[21]])
    assert np.max(np.abs(richardson / p_exact - 1)) < error[21] / 50


def test_extrapolate_is_exact_on_its_model():
    h = [0.4, 0.2, 0.1]
    assert extrapolate(h[:2], [3 + 2 * x ** 2 for x in h[:2]]) == pytest.approx(3, abs=1e-14)
    assert extrapolate(h, [3 + 2 * x ** 2 - 5 * x ** 4 for x in h]) == pytest.approx(3, abs=1e-13)
    assert extrapolate(h, [3 + x ** 2 * (2 + 5 * np.log(x)) for x in h], log_term=True) == pytest.approx(3, abs=1e-13)
    with pytest.raises(SnapmemError, match="need 2 or 3"):
        extrapolate([1.0], [np.ones(2)])


def test_coordinate_path_rejects_a_fixed_coordinate():
    scene = build_scene("torus", nodes=12)
    with pytest.raises(SnapmemError, match="not a free degree of freedom"):
        coordinate_path(scene, 1, [0.1], (scene.reference_state(), {"pressure": 0.0}))


@pytest.mark.slow
def test_peers_richardson_torus_curve_meets_the_ode():
    """studies/peers.py's path curve on 24 and 48 nodes against the ODE at tight tolerance."""
    peers = study("peers")
    radii = peers.ode_controls("torus", 12, None)
    shape, p = peers.path_curve("torus", (24, 48), radii)
    _, p_ode = peers.ode_curve("torus", 1e-9, 12, None)
    scale = 0.0409097                                                   # the limit pressure
    assert np.array_equal(shape, radii) and np.max(np.abs(p - p_ode)) / scale < 3e-5
    _, p_one = peers.path_curve("torus", (48,), radii)
    assert np.max(np.abs(p_one - p_ode)) / scale > 1e-3                 # one mesh alone: 2e-3


def test_sfepy_study_on_the_committed_sfepy_steps(tmp_path):
    """studies/sfepy_balloon.py --quick --sfepy-from (SfePy itself is optional and slow): the
    snapmem path at SfePy's own stretch steps, at equal or better error."""
    module = study("sfepy_balloon")
    table = module.main(["--quick", "--sfepy-from", str(STUDIES.parent / "results" / "sfepy_balloon.csv"),
                         "--out", str(tmp_path / "sfepy.csv")])
    summary = table[(table["table"] == "equal_error") & (table["snapmem_method"] == "snapmem_path")].iloc[0]
    sfepy = table[(table["table"] == "run") & (table["method"] == "sfepy")].iloc[0]
    assert bool(summary["sfepy_cached"]) and summary["snapmem_points"] == sfepy["points"] >= 10
    assert summary["snapmem_error"] <= summary["error"]
