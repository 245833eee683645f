"""snapmem's discrete model against the independent ODE shooting reference (snapmem.reference.membrane_ode).

At fixed pressure, snapmem's answer must converge to the continuous one as N^-2, and the ODE
solution's own error (default tolerances against much tighter ones) must be far below the
discretisation error it is used to measure.
"""

import numpy as np
import pytest

from snapmem import build_scene, equilibrium
from snapmem.continuation.tracer import ContinuationOptions, trace
from snapmem.reference.exact import balloon_limit_point, balloon_pressure
from snapmem.model.materials import Gent
from snapmem.reference.membrane_ode import ODEOptions, PlateODE, SphereODE, TorusODE, e_hat

TIGHT = ODEOptions(rtol=1e-13, atol=1e-15, pole_offset=1e-7)


def observed_order(nodes, errors):
    """Slope of -log|error| against log N, least squares."""
    slope = np.polyfit(np.log(nodes), np.log(np.abs(errors)), 1)[0]
    return -slope


def snapmem_errors(scene_name, nodes, pressure, reference, names):
    out = {name: [] for name in names}
    for n in nodes:
        eq = equilibrium(build_scene(scene_name, nodes=n, pressure=pressure))
        assert eq.converged
        m = eq.measures()
        for name in names:
            out[name].append(m[name] - reference[name])
    return {name: np.array(v) for name, v in out.items()}


@pytest.mark.parametrize("lam", [1.3, 2.5])
def test_sphere_shooting_reproduces_the_exact_balloon(lam):
    p = SphereODE().pressure(lam)
    assert p == pytest.approx(balloon_pressure(lam), rel=1e-9)


def test_sphere_shooting_with_voltage():
    E = 0.2308
    lam, p_lp = balloon_limit_point(E_hat=E)
    assert SphereODE(E_hat=E).pressure(lam) == pytest.approx(p_lp, rel=1e-9)


@pytest.mark.parametrize("p_hat", [0.02, 0.05])
def test_plate_converges_to_the_ode_solution_as_n_squared(p_hat):
    ref = PlateODE().at_pressure(p_hat).measures
    tight = PlateODE(options=TIGHT).at_pressure(p_hat).measures
    nodes = np.array([100, 200, 400, 800])
    err = snapmem_errors("plate", nodes, p_hat, ref, ("deflection", "volume"))
    for name, e in err.items():
        order = observed_order(nodes, e)
        assert 1.8 <= order <= 2.2, (name, order, e)
        # the reference's own error is far below the finest discretisation error
        assert abs(tight[name] - ref[name]) < 1e-4 * np.min(np.abs(e)), (name, tight[name] - ref[name])
    # snapmem's apex rises monotonically towards the continuous answer from above
    assert np.all(err["deflection"] > 0) and np.all(np.diff(err["deflection"]) < 0)


def test_torus_converges_to_the_ode_solution_as_n_squared():
    p_hat = 0.02
    ode = TorusODE()
    r_o, lam_o = ode.at_pressure(p_hat)
    ref = ode.solution(r_o, lam_o, p_hat).measures
    tight_r, _ = TorusODE(options=TIGHT).at_pressure(p_hat, (r_o, lam_o))
    assert ref["closure_error"] < 1e-11
    nodes = np.array([96, 192, 384, 768])
    err = snapmem_errors("torus", nodes, p_hat, ref, ("outer_radius", "volume", "u_max"))
    for name, e in err.items():
        order = observed_order(nodes, e)
        assert 1.8 <= order <= 2.2, (name, order, e)
    assert abs(tight_r - r_o) < 1e-4 * np.min(np.abs(err["outer_radius"]))
    assert ref["outer_radius"] == pytest.approx(12.33665044, abs=1e-7)


def snapmem_limit_pressures(scene_name, nodes, start_loads, until, **params):
    """Pressures of the first located limit point of snapmem's traced branch, one per mesh."""
    out = []
    for n in nodes:
        scene = build_scene(scene_name, nodes=n, **params)
        start = equilibrium(scene, start_loads)
        branch = trace(scene, "pressure", until=until, start=(start.q, start.loads),
                       options=ContinuationOptions(stop_at_first_limit=True))
        lp = branch.limit_points()
        assert len(lp) and bool(lp["located"].iloc[0])
        out.append(float(lp["pressure"].iloc[0]))
    return np.array(out)


@pytest.mark.slow                     # ~10 s: run by .ci/run with -m slow
def test_torus_limit_point_is_a_pressure_maximum_and_snapmem_converges_to_it():
    ode = TorusODE()
    lp = ode.limit_point()
    p_lp, r_lp = lp.pressure, lp.measures["outer_radius"]
    assert p_lp == pytest.approx(0.0409097492646, rel=1e-9)
    assert lp.measures["taut"]
    guess = (lp.measures["outer_stretch"], p_lp)
    for dr in (-1e-3, 1e-3):
        assert ode.at_outer_radius(r_lp + dr, guess)[1] < p_lp
    # snapmem's located fold converges to it as N^-2 (errors 2.0e-5, 5.0e-6, 1.3e-6 of 0.0409)
    nodes = np.array([100, 200, 400])
    err = snapmem_limit_pressures("torus", nodes, {"pressure": 0.005}, {"outer_radius": 17.0}) - p_lp
    assert 1.9 <= observed_order(nodes, err) <= 2.1, err
    assert np.all(err > 0)


@pytest.mark.slow
def test_pump_limit_points_at_300_volts_match_snapmem():
    """The Gent pump plate at 300 V: the ODE's pressure maximum, snapmem's fold converging to it."""
    E = e_hat(300.0, 1e-4, 1e-10, 45e3)
    ode = PlateODE(R=0.1, H=1e-4, law=Gent(45e3, 270.0), E_hat=E)
    rows = [(lam0, ode.pressure(lam0, 79.0)) for lam0 in (2.0, 2.1, 2.2)]
    lp = ode.pressure_extremum(rows, "max")
    assert lp.pressure == pytest.approx(79.9027578619, rel=1e-9)
    assert lp.measures["taut"]
    nodes = np.array([51, 101, 201])
    err = snapmem_limit_pressures("pump", nodes, {"pressure": 20.0}, {"stretch_max": 4.0}) - lp.pressure
    assert 1.8 <= observed_order(nodes, err) <= 2.2, err
