"""Time stepping against the uniformly inflated balloon's ODE, energy conservation of the
midpoint rule, adaptive steps, schedules, trajectories on disk and settling after a snap."""

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from snapmem import MooneyRivlin, PressureWork, Scene, Stretching, sphere
from snapmem.dynamics import (DynamicsOptions, PiecewiseLinear, Trajectory, lumped_masses, schedule, settle,
                      simulate)
from snapmem.solvers.newton import solve

R, H, C1, C2 = 10.0, 0.1, 0.4375, 0.0625
RHO = 1.0
P_MAX, RATE = 0.02, 0.001          # p_hat ramps through the limit point 1.4073e-2 at t = 14 s


def pressure(t):
    return min(RATE * t, P_MAX)


def balloon_ode(t_end, xi):
    """rho R^2 lam'' + xi rho R^2 lam' = p(t) R lam^2 / H - dW(lam, lam)/dlam, scipy at tight tolerance."""
    def rhs(t, y):
        lam, w = y
        dW = 4 * C1 * (lam - lam ** -5) + 4 * C2 * (lam ** 3 - lam ** -3)
        return [w, (pressure(t) * R * lam ** 2 / H - dW) / (RHO * R ** 2) - xi * w]
    sol = solve_ivp(rhs, (0, t_end), [1.0, 0.0], method="DOP853", rtol=1e-12, atol=1e-12,
                    dense_output=True, max_step=0.05)
    return sol.sol


def balloon(n):
    """Sphere with poles on the axis and the equator held at z = 0 (no rigid motion, no bias)."""
    m = sphere(R, n)
    return Scene(m, H, [Stretching(MooneyRivlin(C1, C2)), PressureWork()],
                 fixed=[0, 2 * (n - 1), 2 * (n // 2) + 1])


def equator_stretch(scene, t_end, xi, scheme, dt):
    traj = simulate(scene, schedule(pressure=[(0, 0), (P_MAX / RATE, P_MAX), (t_end, P_MAX)]), t_end, rho=RHO,
                    damping=xi, options=DynamicsOptions(scheme=scheme, dt=dt, adaptive=False))
    return traj["t"], traj["r"][:, scene.meridian.nodes // 2] / R


def slope(x, y):
    return np.polyfit(np.log(x), np.log(y), 1)[0]


def test_lumped_masses_sum_to_the_membrane_mass():
    scene = balloon(81)
    m = lumped_masses(scene, 2.0)
    assert m.shape == (2 * 81,)
    assert np.all(m > 0)
    assert m[0::2].sum() == pytest.approx(2.0 * H * 4 * np.pi * R ** 2, rel=1e-3)


def test_implicit_euler_is_first_order_against_the_balloon_ode():
    """Through the limit point and the snap to lam ~ 8: error ~ dt^1 (spatial error ~2e-3 is far below)."""
    t_end, xi = 56.0, 0.1
    ode = balloon_ode(t_end, xi)
    scene = balloon(81)
    dts = [0.2, 0.1, 0.05]
    errors = []
    for dt in dts:
        t, lam = equator_stretch(scene, t_end, xi, "euler", dt)
        errors.append(np.max(np.abs(lam - ode(t)[0])))
    assert ode(48.0)[0] > 7.0                      # the snap is inside the window
    assert 0.85 < slope(dts, errors) < 1.15
    assert errors[-1] < 0.06


def test_midpoint_is_second_order_and_converges_to_the_balloon_ode():
    """Time error of the midpoint rule ~ dt^2 (measured against a run with dt / 8 on the same mesh,
    which removes the mesh's own error), and that run within the mesh error of the ODE."""
    t_end, xi = 56.0, 0.1
    ode = balloon_ode(t_end, xi)
    scene = balloon(81)
    fine_dt = 0.025
    t_fine, lam_fine = equator_stretch(scene, t_end, xi, "midpoint", fine_dt)
    dts = [0.4, 0.2, 0.1]
    errors = []
    for dt in dts:
        t, lam = equator_stretch(scene, t_end, xi, "midpoint", dt)
        errors.append(np.max(np.abs(lam - np.interp(t, t_fine, lam_fine))))
    assert 1.8 < slope(dts, errors) < 2.2
    assert np.max(np.abs(lam_fine - ode(t_fine)[0])) < 1e-2      # mesh error at N = 81, lam up to 8


def test_error_against_the_ode_falls_as_n_to_the_minus_two():
    t_end, xi = 40.0, 0.5
    ode = balloon_ode(t_end, xi)
    ns = [21, 41, 81]
    errors = []
    for n in ns:
        t, lam = equator_stretch(balloon(n), t_end, xi, "midpoint", 0.05)
        errors.append(np.max(np.abs(lam - ode(t)[0])))
    assert ode(t_end)[0] > 1.6                     # past the limit stretch 1.535
    assert -2.15 < slope(ns, errors) < -1.85


def test_midpoint_conserves_energy_over_100_periods_undamped():
    """A small breathing oscillation about the equilibrium at p_hat = 0.01, no damping."""
    from snapmem.reference import exact
    scene = balloon(21)
    p = 0.01
    lam = exact.balloon_stretch(p)
    eq = solve(scene, {"pressure": p}, q0=scene.reference_state() * lam)
    assert eq.converged
    v0 = 0.002 * eq.q                            # uniform breathing kick
    v0[list(scene.fixed)] = 0
    # linearised breathing frequency of the ODE: rho R^2 omega^2 = d/dlam (dW/dlam - p R lam^2 / H)
    k = 4 * C1 * (1 + 5 * lam ** -6) + 4 * C2 * (3 * lam ** 2 + 3 * lam ** -4) - 2 * p * R * lam / H
    period = 2 * np.pi * R * np.sqrt(RHO / k)
    traj = simulate(scene, {"pressure": p}, 101 * period, rho=RHO, damping=0.0, q0=eq.q, v0=v0,
                    options=DynamicsOptions(dt=period / 30, adaptive=False))
    r_eq = traj["r"][:, scene.meridian.nodes // 2] - eq.q[2 * (scene.meridian.nodes // 2)]
    crossings = np.flatnonzero((r_eq[:-1] < 0) & (r_eq[1:] >= 0))
    assert crossings.size >= 100                 # 100 oscillation periods
    total = traj["total"]
    drift = np.max(np.abs(total - total[0])) / abs(total[0])
    assert drift < 1e-3
    # and relative to the oscillation's own energy, which is the stricter measure
    assert np.max(np.abs(total - total[0])) / traj["kinetic"].max() < 1e-2


def test_adaptive_steps_resolve_the_snap_and_stretch_elsewhere():
    t_end, xi = 56.0, 0.1
    ode = balloon_ode(t_end, xi)
    scene = balloon(41)
    traj = simulate(scene, schedule(pressure=[(0, 0), (P_MAX / RATE, P_MAX)]), t_end, rho=RHO, damping=xi,
                    options=DynamicsOptions(dt=0.01, tol=1e-4))
    lam = traj["r"][:, 20] / R
    assert np.max(np.abs(lam - ode(traj["t"])[0])) < 0.05
    dt = traj["dt"][1:]
    assert dt.max() > 20 * dt.min()
    assert traj.meta["steps"] < 2000


def test_schedule_is_piecewise_linear_and_breakpoints_are_hit():
    f = schedule(pressure=[(0, 0), (5, 0), (20, 150)], voltage=300.0)
    assert f(10.0) == {"pressure": 50.0, "voltage": 300.0}
    assert f(30.0)["pressure"] == 150.0
    assert PiecewiseLinear((0, 1), (2, 4))(0.25) == 2.5
    scene = balloon(11)
    traj = simulate(scene, schedule(pressure=[(0, 0), (0.3, 0.001), (1.0, 0.001)]), 1.0, rho=RHO,
                    options=DynamicsOptions(dt=0.07))
    assert np.any(np.isclose(traj["t"], 0.3, atol=1e-12))


def test_trajectory_roundtrip_without_pickle(tmp_path):
    scene = balloon(11)
    traj = simulate(scene, {"pressure": 0.005}, 0.5, rho=RHO, damping=1.0, options=DynamicsOptions(dt=0.05))
    path = tmp_path / "traj.npz"
    traj.save(path)
    back = Trajectory.load(path)
    for key in ("t", "r", "z", "volume", "kinetic", "potential", "load_pressure", "min_gap"):
        np.testing.assert_array_equal(back[key], traj[key])
    assert back.meta["scheme"] == "midpoint" and back.meta["steps"] == traj.meta["steps"]
    with np.load(path, allow_pickle=False) as f:
        assert "meta" in f.files


def test_settle_after_the_limit_point_lands_on_the_far_branch():
    """Just past the balloon's limit pressure, the damped motion comes to rest on the far branch."""
    from snapmem.reference import exact
    scene = balloon(41)
    lam_lp, p_lp = exact.balloon_limit_point()
    p = p_lp * 1.002
    q = scene.reference_state() * lam_lp
    rest = settle(scene, q, {"pressure": p}, rho=RHO, damping=0.5, t_max=2000.0)
    assert rest.at_rest
    lam = rest.q[2 * 20] / R
    far = [lam_ for lam_ in np.linspace(2.6, 12, 100000) if True]
    p_far = exact.balloon_pressure(np.array(far))
    lam_exact = far[int(np.argmin(np.abs(p_far - p)))]
    assert lam == pytest.approx(lam_exact, rel=5e-3)


def test_energy_and_residual_line_searches_agree():
    """Both Newton line searches of a time step converge to the same trajectory (to the Newton tolerance)."""
    scene = balloon(21)
    out = {}
    for ls in ("energy", "residual"):
        traj = simulate(scene, schedule(pressure=[(0, 0), (20, 0.016)]), 30.0, rho=RHO, damping=0.5,
                        options=DynamicsOptions(scheme="bdf2", dt=0.1, adaptive=False, line_search=ls))
        out[ls] = traj["r"][:, 10]
    np.testing.assert_allclose(out["energy"], out["residual"], rtol=1e-6)


def test_an_interrupted_simulation_keeps_its_frames():
    """Ctrl-C (KeyboardInterrupt) during a run ends it with the frames computed so far, not nothing."""
    scene = balloon(21)

    def interrupt(t, t_end):
        if t > 2.05:                            # after the step to t = 2.1
            raise KeyboardInterrupt

    traj = simulate(scene, {"pressure": pressure}, 10.0, rho=RHO, damping=0.5, progress=interrupt,
                    options=DynamicsOptions(dt=0.1, adaptive=False))
    assert traj.meta["status"].startswith("interrupted at t = 2.1")
    assert traj["t"][-1] == pytest.approx(2.1) and traj.meta["t_end"] == pytest.approx(2.1)
    assert len(traj["t"]) == len(traj["potential"]) == len(traj["r"]) == 22          # t = 0, 0.1, ..., 2.1
    assert np.all(np.isfinite(traj["total"]))


def test_an_interrupted_save_leaves_the_previous_file_whole(tmp_path, monkeypatch):
    import snapmem.io.results as results
    scene = balloon(21)
    traj = simulate(scene, {"pressure": 0.005}, 0.3, rho=RHO, options=DynamicsOptions(dt=0.1, adaptive=False))
    path = tmp_path / "traj"                                       # numpy's rule: .npz appended
    traj.save(path)
    assert (tmp_path / "traj.npz").exists()

    def broken(handle, **arrays):
        handle.write(b"PK\x03\x04 half a zip")
        raise KeyboardInterrupt

    monkeypatch.setattr(results.np, "savez_compressed", broken)
    with pytest.raises(KeyboardInterrupt):
        traj.save(tmp_path / "traj.npz")
    back = Trajectory.load(tmp_path / "traj.npz")
    assert np.array_equal(back["q"], traj["q"]) and back.meta["status"] == "completed"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["traj.npz"]


@pytest.mark.parametrize("name", ["euler", "midpoint", "bdf2"])
@pytest.mark.parametrize("history", [False, True])
def test_a_schemes_outcome_is_its_new_state_acceleration_and_error_bit_for_bit(name, history):
    """Scheme.outcome, one compiled pass on a run's arrays, gives what new_state, acceleration and
    local_error give (and the largest |q_i| of the membrane's entries), to the bit: the driver
    takes a step's outcome from it. The base class's outcome (those methods composed) agrees too."""
    from snapmem.dynamics.schemes import SCHEME_BY_NAME, Scheme
    rng = np.random.default_rng(7)
    q, v, y, a_prev, q_past, v_past = rng.normal(size=(6, 23))
    free = np.array([0, 2, 3, 5, 8, 13, 21])
    anchor = SCHEME_BY_NAME[name].anchor(q, v, 0.2, 0.01, (q_past, v_past, 0.013) if history else None)
    got = anchor.scheme.outcome(anchor, y, a_prev, free, 20)
    q_new, v_new = anchor.new_state(y)
    a_new = anchor.acceleration(v_new)
    expected = (q_new, v_new, a_new, anchor.scheme.local_error(0.01, a_new, a_prev, free), np.abs(q_new[:20]).max())
    for a, b in zip(got, expected):
        assert np.array_equal(a, b)
    assert Scheme.outcome(anchor.scheme, anchor, y, a_prev, free, 20)[3] == got[3]
    assert got[3] > 0 and (got[0] is y) == (name != "midpoint")
