"""Viscoelastic membranes (issue 15, item 4): non-equilibrium networks with internal stretches.

The uniformly inflated balloon with one neo-Hookean network (modulus mu_v, relaxation time tau)
reduces to ODEs in (lam, lam', zeta = ln xi):

    rho R^2 lam'' + c rho R^2 lam' = p(t) R lam^2 / H - dW_eq/dlam - (2 mu_v / lam)(a^2 - a^-4),
    zeta' = (a^2 - a^-4) / (6 tau),    a = lam e^-zeta,

(the flow rule of snapmem.model.viscous at lam1 = lam2), solved here by scipy at tight tolerance.
The static ends are exact: the instantaneous response is the Mooney-Rivlin balloon with
c1 + mu_v / 2 (a neo-Hookean network adds mu_v / 2 to c1), the relaxed one the equilibrium
network's own balloon (snapmem.reference.exact).
"""

from types import SimpleNamespace

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from snapmem.catalog.registry import build_scene
from snapmem.dynamics.driver import simulate
from snapmem.dynamics.options import DynamicsOptions
from snapmem.errors import SnapmemError
from snapmem.model.viscous import ViscousNetworks, network_log_derivatives, viscous_terms
from snapmem.reference.exact import balloon_limit_point, balloon_stretch
from snapmem.statics import equilibrium

R, H, C1, C2 = 10.0, 0.1, 0.4375, 0.0625
MU_V, TAU, P = 0.5, 1.0, 0.012
RHO, DAMPING, RAMP = 1e-6, 1e3, 0.005       # overdamped and fast: quasi-static on the scale of tau
NODES = 21
MESH_ERROR = 3e-3                             # |lam - lam_exact| of the 21-node balloon at these stretches


def balloon_creep(t_end, pressure, kink=RAMP, c1=C1, c2=C2, mu_v=MU_V, tau=TAU, rho=RHO, damping=DAMPING,
                  jlim=np.inf):
    """The homogeneous viscoelastic balloon's ODEs (module docstring) by scipy (Radau, tight
    tolerances, restarted at the load's kink): t -> (lam, lam', zeta). A Gent network (``jlim``
    finite) has dW/dI1 = (mu_v / 2) / s, s = 1 - (I1(a) - 3) / jlim, I1 = 2 a^2 + a^-4: its stress
    and its flow are the neo-Hookean ones divided by s."""
    def rhs(t, y):
        lam, w, zeta = y
        a = lam * np.exp(-zeta)
        flow = (a * a - a ** -4) / (1.0 - (2 * a * a + a ** -4 - 3.0) / jlim)
        dW = 4 * c1 * (lam - lam ** -5) + 4 * c2 * (lam ** 3 - lam ** -3) + 2 * mu_v / lam * flow
        return [w, (pressure(t) * R * lam ** 2 / H - dW) / (rho * R ** 2) - damping * w, flow / (6 * tau)]

    first = solve_ivp(rhs, (0.0, kink), [1.0, 0.0, 0.0], method="Radau", rtol=1e-11, atol=1e-12,
                      dense_output=True)
    if t_end <= kink:
        return first.sol
    second = solve_ivp(rhs, (kink, t_end), first.y[:, -1], method="Radau", rtol=1e-11, atol=1e-12,
                       dense_output=True)
    return lambda t: np.where(np.asarray(t) <= kink, first.sol(np.minimum(t, kink)), second.sol(np.maximum(t, kink)))


def held_pressure(t, ramp=RAMP):
    return P * min(t / ramp, 1.0)


def run(scene, t_end, scheme="euler", dt=0.01, adaptive=False, ramp=RAMP, dt_max=0.1):
    """From rest, the pressure ramped to P in ``ramp`` [s], then held."""
    options = DynamicsOptions(scheme=scheme, dt=dt, adaptive=adaptive, dt_max=dt_max, save_interval=0.0)
    return simulate(scene, {"pressure": [(0.0, 0.0), (ramp, P), (t_end, P)]}, t_end, rho=RHO, damping=DAMPING,
                    options=options)


@pytest.fixture(scope="module")
def scene():
    return build_scene("balloon", nodes=NODES, support="free", viscous_mu=MU_V, relaxation_time=TAU)


def test_condensed_density_is_the_derivative_of_the_incremental_potential():
    """Inside a step, the condensed density's w_i and w_ij are central differences of w and w_i."""
    term = ViscousNetworks([0.5, 0.2], [1.0, 0.1])
    rng = np.random.default_rng(1)
    lam1, lam2 = 0.8 + rng.random(6), 0.9 + rng.random(6)
    term.begin_step(0.05, 0.2 * rng.random((2, 2, 6)) - 0.05)

    def density(a, b):
        term._warm = None
        return term.density(SimpleNamespace(lam1=a, lam2=b), {})

    d, h = density(lam1, lam2), 1e-6
    for first, (da, db), seconds in (("w1", (h, 0), ("w11", "w12")), ("w2", (0, h), ("w12", "w22"))):
        up, down = density(lam1 + da, lam2 + db), density(lam1 - da, lam2 - db)
        np.testing.assert_allclose(getattr(d, first), (up.w - down.w) / (2 * h), rtol=1e-7, atol=1e-10)
        np.testing.assert_allclose(getattr(d, seconds[0]), (up.w1 - down.w1) / (2 * h), rtol=1e-6, atol=1e-9)
        np.testing.assert_allclose(getattr(d, seconds[1]), (up.w2 - down.w2) / (2 * h), rtol=1e-6, atol=1e-9)


def test_small_strain_modes_relax_with_the_relaxation_time():
    """At a held small stretch, one implicit Euler step of tiny h moves zeta by h e / tau in every mode."""
    tau, h = 0.7, 1e-7
    term = ViscousNetworks(2.0, tau)
    for e in ([1e-5, 1e-5], [1e-5, -1e-5], [1e-5, 0.0]):
        term.begin_step(h, np.zeros((1, 2, 1)))
        zeta = term.internal(SimpleNamespace(lam1=np.exp([e[0]]), lam2=np.exp([e[1]])))[0, :, 0]
        np.testing.assert_allclose(zeta, h * np.array(e) / tau, rtol=1e-4, atol=1e-4 * h * 1e-5 / tau)


def test_static_limits_are_the_balloon_formulas_of_each_law():
    """relaxed: the equilibrium network alone; instantaneous: c1 + mu_v / 2 (xi = 1)."""
    for limit, c1 in (("relaxed", C1), ("instantaneous", C1 + MU_V / 2)):
        s = build_scene("balloon", nodes=NODES, support="free", viscous_mu=MU_V, relaxation_time=TAU,
                        viscous_limit=limit)
        eq = equilibrium(s, {"pressure": P})
        assert eq.converged
        assert abs(s.probes["stretch"](eq.q) - balloon_stretch(P, R, H, c1, C2)) < MESH_ERROR


def test_held_pressure_creeps_from_instantaneous_to_relaxed(scene):
    """The `snapmem simulate balloon --set viscous_mu=0.5 --set relaxation_time=1` case, held 60 tau."""
    t_end = 60.0
    traj = run(scene, t_end, "euler", dt=1e-4, adaptive=True, dt_max=0.1)    # the inertial start resolved
    assert traj.meta["status"] == "completed"
    lam = traj["r"].max(axis=1) / R
    t = traj["t"]
    held = t >= 0.05                                   # after the ramp and the (overdamped) inertia
    assert np.all(np.diff(lam[held]) > -1e-9)          # monotone, to the Newton tolerance once relaxed
    instantaneous, relaxed = balloon_stretch(P, R, H, C1 + MU_V / 2, C2), balloon_stretch(P, R, H, C1, C2)
    # the first held frame: near the glassy state, off it only by what crept in 0.05 tau
    early = balloon_creep(t[held][0], held_pressure)(t[held][0])[0]
    assert abs(early - instantaneous) < 0.015 * (relaxed - instantaneous)
    assert abs(lam[held][0] - early) < MESH_ERROR
    assert abs(lam[-1] - relaxed) < MESH_ERROR
    assert np.abs(lam[held] - balloon_creep(t_end, held_pressure)(t[held])[0]).max() < MESH_ERROR
    xi = traj["xi"]                                    # (T, 1, 2, E)
    assert xi.shape == (t.size, 1, 2, NODES - 1) and np.allclose(xi[0], 1.0, rtol=0, atol=1e-14) and np.all(xi[-1] > 1.0)


def test_creep_curve_is_the_ode_and_converges_at_the_schemes_order(scene):
    """A ramp the steps resolve (0.2 s), then held; fixed steps."""
    t_end, ramp = 2.0, 0.2
    ode = balloon_creep(t_end, lambda t: held_pressure(t, ramp), kink=ramp)
    for scheme, order in (("euler", 1), ("bdf2", 2)):
        curves = []
        for dt in (0.02, 0.01, 0.005):
            traj = run(scene, t_end, scheme, dt, ramp=ramp)
            curves.append(traj["r"].max(axis=1)[-1] / R)
            lam, t = traj["r"].max(axis=1) / R, traj["t"]
            assert np.abs(lam - ode(t)[0]).max() < MESH_ERROR
        # at a fixed mesh, the differences between halvings of dt fall by 2^order
        ratio = abs(curves[0] - curves[1]) / abs(curves[1] - curves[2])
        assert 2 ** order * 0.7 < ratio < 2 ** order * 1.4, (scheme, ratio)


def test_dissipation_is_nonnegative_and_is_the_driving_force_times_the_flow(scene):
    """Implicit Euler: every step's dissipation is sum weight f_e(eps - zeta_{n+1}) . (zeta_{n+1} - zeta_n),
    computed here from the recorded frames alone, and it is >= 0."""
    traj = run(scene, 1.0, "euler", 0.01)
    zeta = np.log(traj["xi"][:, 0])                     # (T, 2, E)
    steps = []
    for k in range(1, zeta.shape[0]):
        kin = scene.kinematics(traj["q"][k])
        e = np.log(np.stack([kin.lam1, kin.lam2])) - zeta[k]
        _, f1, f2, *_ = network_log_derivatives(e[0], e[1], MU_V)
        flow = zeta[k] - zeta[k - 1]
        steps.append(float(scene.weight @ (f1 * flow[0] + f2 * flow[1])))
    steps = np.array(steps)
    assert np.all(steps >= 0.0) and steps.max() > 0.0
    np.testing.assert_allclose(np.diff(traj["dissipation"]), steps, rtol=1e-6, atol=1e-12 * steps.max())


def test_elastic_scene_is_unchanged_and_bad_networks_are_refused():
    assert not any(isinstance(t, ViscousNetworks) for t in build_scene("balloon", nodes=11).terms)
    with pytest.raises(SnapmemError, match="relaxation_time"):
        build_scene("balloon", nodes=11, viscous_mu=[0.5, 0.2], relaxation_time=1.0)
    with pytest.raises(SnapmemError, match="viscous_mu"):
        build_scene("balloon", nodes=11, viscous_mu=-1.0, relaxation_time=1.0)
    two = build_scene("balloon", nodes=11, viscous_mu="0.5,0.2", relaxation_time="1,0.1").terms[-1]
    np.testing.assert_array_equal(two.moduli, [0.5, 0.2])
    np.testing.assert_array_equal(two.times, [1.0, 0.1])


def snap_time(scene, rate, t_end):
    """The time [s] the balloon under p = rate t passes lam = 2 (past its limit point at about 1.5)."""
    options = DynamicsOptions(scheme="euler", dt=1e-4 * t_end, adaptive=True, dt_max=t_end / 200, save_interval=0.0)
    traj = simulate(scene, {"pressure": [(0.0, 0.0), (t_end, rate * t_end)]}, t_end, rho=RHO, damping=DAMPING,
                    options=options, stop=lambda t, q, v: q[0::2].max() / R > 2.5)
    lam = traj["r"].max(axis=1) / R
    passed = np.flatnonzero(lam > 2.0)
    assert passed.size, "no snap"
    return float(traj["t"][passed[0]])


def test_snap_under_a_ramp_is_delayed_at_fast_rates_and_elastic_at_slow_rates(scene):
    """The ramp reaches the relaxed limit pressure p_LP at t_LP. Fast (t_LP = 0.1 tau): the networks stay
    glassy and the snap comes with the glassy balloon's (c1 + mu_v / 2), over 20% later than the
    elastic one. Slow (t_LP = 10, 100, 1000 tau): the delay falls to the elastic prediction."""
    p_lp = balloon_limit_point(R, H, C1, C2)[1]
    p_glassy = balloon_limit_point(R, H, C1 + MU_V / 2, C2)[1]
    elastic = build_scene("balloon", nodes=NODES, support="free")
    glassy = build_scene("balloon", nodes=NODES, support="free", c1=C1 + MU_V / 2)

    def times(t_lp, *scenes):
        return [snap_time(s, p_lp / t_lp, 2.0 * t_lp * p_glassy / p_lp) for s in scenes]

    t_visco, t_elastic, t_glassy = times(0.1 * TAU, scene, elastic, glassy)
    assert t_visco > 1.2 * t_elastic
    assert abs(t_visco / t_glassy - 1.0) < 0.02
    delays = [t_v / t_e - 1.0 for t_v, t_e in (times(t_lp, scene, elastic) for t_lp in (10 * TAU, 100 * TAU, 1000 * TAU))]
    assert delays[0] > delays[1] > delays[2] > 0.0
    assert delays[1] < 0.6 * delays[0] and delays[2] < 0.6 * delays[1] and delays[2] < 0.02


JLIM_V = 0.3     # a Gent network near its lock: at the glassy start I1(a) - 3 is about 0.2 of 0.3


def test_gent_network_creep_is_the_ode_and_converges_at_the_schemes_order():
    """A Gent non-equilibrium network (``viscous_Jlim``): the creep curve is the homogeneous
    balloon's ODE with the Gent network's stress and flow, and bdf2 converges at order 2 in dt."""
    gent = build_scene("balloon", nodes=NODES, support="free", viscous_mu=MU_V, relaxation_time=TAU,
                       viscous_Jlim=JLIM_V)
    assert viscous_terms(gent)[0].jlims.tolist() == [JLIM_V]
    t_end, ramp = 2.0, 0.2
    ode = balloon_creep(t_end, lambda t: held_pressure(t, ramp), kink=ramp, jlim=JLIM_V)
    neo = balloon_creep(t_end, lambda t: held_pressure(t, ramp), kink=ramp)
    t_check = np.linspace(0.0, t_end, 201)
    assert np.abs(ode(t_check)[0] - neo(t_check)[0]).max() > 3 * MESH_ERROR     # the lock matters here
    finals = []
    for dt in (0.02, 0.01, 0.005):
        traj = run(gent, t_end, "bdf2", dt, ramp=ramp)
        lam, t = traj["r"].max(axis=1) / R, traj["t"]
        assert np.abs(lam - ode(t)[0]).max() < MESH_ERROR
        finals.append(lam[-1])
    ratio = abs(finals[0] - finals[1]) / abs(finals[1] - finals[2])
    assert 4 * 0.7 < ratio < 4 * 1.4, ratio


def test_gent_network_derivatives_are_finite_differences_and_tend_to_neo_hookean():
    e1, e2, h = np.array([0.11, -0.05]), np.array([0.06, 0.14]), 1e-6     # I1 - 3 below JLIM_V
    w, f1, f2, f11, f12, f22 = network_log_derivatives(e1, e2, MU_V, JLIM_V)
    for g, (d1, d2) in ((f1, (h, 0)), (f2, (0, h))):
        fd = (network_log_derivatives(e1 + d1, e2 + d2, MU_V, JLIM_V)[0]
              - network_log_derivatives(e1 - d1, e2 - d2, MU_V, JLIM_V)[0]) / (2 * h)
        np.testing.assert_allclose(g, fd, rtol=1e-8)
    fd11 = (network_log_derivatives(e1 + h, e2, MU_V, JLIM_V)[1] - network_log_derivatives(e1 - h, e2, MU_V, JLIM_V)[1])
    fd12 = (network_log_derivatives(e1, e2 + h, MU_V, JLIM_V)[1] - network_log_derivatives(e1, e2 - h, MU_V, JLIM_V)[1])
    fd22 = (network_log_derivatives(e1, e2 + h, MU_V, JLIM_V)[2] - network_log_derivatives(e1, e2 - h, MU_V, JLIM_V)[2])
    np.testing.assert_allclose([f11, f12, f22], np.array([fd11, fd12, fd22]) / (2 * h), rtol=1e-7)
    big = network_log_derivatives(e1, e2, MU_V, 1e5)      # off neo-Hookean by O(1 / Jlim)
    for a, b in zip(big, network_log_derivatives(e1, e2, MU_V)):
        np.testing.assert_allclose(a, b, rtol=1e-4)
    with pytest.raises(SnapmemError, match="viscous_Jlim"):
        build_scene("balloon", nodes=11, viscous_mu=[0.5, 0.2], relaxation_time=[1.0, 0.1], viscous_Jlim=2.0)
