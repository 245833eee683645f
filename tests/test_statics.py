"""Static equilibria against exact solutions, invariances and the state of rest."""

import numpy as np
import pytest

from snapmem import build_scene, equilibrium, exact, solve
from snapmem.model.scene import Scene
from snapmem.model.materials import Gent
from snapmem.model.meridian import sphere
from snapmem.model.terms import PressureWork, Stretching


@pytest.mark.parametrize("E_hat", [0.0, 0.1538, 0.2308])
@pytest.mark.parametrize("p_hat", [0.010, 0.012])
def test_balloon_stretch_converges_as_n_to_minus_two(E_hat, p_hat):
    lam_exact = exact.balloon_stretch(p_hat, E_hat=E_hat)
    errors = []
    for n in (51, 101):
        eq = equilibrium(build_scene("balloon", nodes=n, E_hat=E_hat, pressure=p_hat))
        assert eq.converged
        errors.append(abs(eq.measures()["stretch"] - lam_exact))
    assert errors[1] < 1e-3 * lam_exact
    assert 3.9 < errors[0] / errors[1] < 4.1          # second order: halving h quarters the error


def test_exact_balloon_limit_points_match_model_table():
    for E_hat, p_lp, lam_lp in [(0.0, 1.407327e-2, 1.53519), (0.1538, 1.335400e-2, 1.50664),
                                (0.2308, 1.247040e-2, 1.47809), (0.3077, 1.125986e-2, 1.44645)]:
        lam, p = exact.balloon_limit_point(E_hat=E_hat)
        assert p == pytest.approx(p_lp, rel=1e-6)
        assert lam == pytest.approx(lam_lp, abs=1e-5)


def test_neo_hookean_balloon_fold_at_seventh_root():
    lam, _ = exact.balloon_limit_point(c1=0.5, c2=0.0)
    assert lam == pytest.approx(7 ** (1 / 6), rel=1e-9)


@pytest.mark.parametrize("name", ["plate", "balloon", "torus"])
def test_reference_has_zero_energy_and_residual(name):
    scene = build_scene(name, nodes=31, with_loads=("voltage",))
    ev = scene.evaluate(scene.reference_state(), {"pressure": 0.0, "voltage": 0.0})
    assert ev.energy == pytest.approx(0.0, abs=1e-12 * scene.force_scale * scene.meridian.size)
    assert np.max(np.abs(ev.residual)) < 1e-12 * scene.force_scale


@pytest.mark.parametrize("name", ["plate", "balloon", "torus"])
def test_energy_invariant_under_z_translation(name):
    scene = build_scene(name, nodes=31, E_hat=0.2, pressure=0.01)
    rng = np.random.default_rng(1)
    q = scene.reference_state() * 1.1 + rng.normal(scale=0.05, size=2 * scene.meridian.nodes)
    shifted = q.copy()
    shifted[1::2] += 3.7
    a, b = scene.evaluate(q, order=1), scene.evaluate(shifted, order=1)
    assert b.energy == pytest.approx(a.energy, rel=1e-12)
    np.testing.assert_allclose(b.gradient, a.gradient, atol=1e-10 * np.abs(a.gradient).max())


def test_solver_reports_converged_state_with_small_residual():
    scene = build_scene("torus", nodes=60, pressure=0.02, E_hat=0.1538)
    eq = equilibrium(scene)
    assert eq.converged and eq.report.residual_norm < 1e-10 * scene.force_scale
    assert np.max(np.abs(scene.evaluate(eq.q, eq.loads, order=1).residual)) == pytest.approx(eq.report.residual_norm)


def test_plate_mooney_rivlin_rises_monotonically():
    """MODEL.md: the Mooney-Rivlin plate (c2/c1 = 0.25) has no pressure maximum."""
    deflections = [equilibrium(build_scene("plate", nodes=41, pressure=p)).measures()["deflection"]
                   for p in (0.01, 0.02, 0.04, 0.08)]
    assert np.all(np.diff(deflections) > 0)


def test_gent_step_control_never_leaves_the_domain():
    """A Newton start far from equilibrium on a Gent balloon close to its lock must not evaluate
    past the lock: the solve converges (or fails) with every trial state admissible."""
    m = sphere(1.0, 41)
    scene = Scene(m, 0.01, [Stretching(Gent(1.0, 5.0)), PressureWork()], fixed=[0, 1, 80])
    seen = []
    original = scene.evaluate

    def spy(q, loads=None, order=2):
        seen.append(scene.inadmissible(q))
        return original(q, loads, order)

    scene.evaluate = spy
    eq = solve(scene, {"pressure": 0.02}, q0=m.q * 1.5)
    assert all(why is None for why in seen)
    assert eq.converged
    lam1, lam2 = scene.stretches(eq.q)
    assert np.all(lam1 ** 2 + lam2 ** 2 + 1 / (lam1 * lam2) ** 2 - 3 < 5.0)


def test_exact_balloon_pressure_minima_match_model_table():
    for E_hat, p_min, lam_min in [(0.0, 1.318791e-2, 2.5940), (0.1538, 1.189016e-2, 2.9064),
                                  (0.2308, 1.001351e-2, 3.4771), (0.3077, 6.514594e-3, 5.3689)]:
        lam, p = exact.balloon_extrema(E_hat=E_hat)[1]
        assert p == pytest.approx(p_min, rel=1e-6)
        assert lam == pytest.approx(lam_min, abs=1e-4)


def test_gent_plate_near_its_lock_is_an_equilibrium_not_a_failure():
    """A Gent membrane stiffens without bound at its lock, so any pressure has an equilibrium; near
    the lock rounding is amplified by 1/(1 - (I1-3)/Jlim), and the solver must still converge."""
    scene = build_scene("plate", nodes=11, material="gent", Jlim=0.01, pressure=1.0)
    eq = equilibrium(scene)
    assert eq.converged
    lam1, lam2 = scene.stretches(eq.q)
    locked = lam1 ** 2 + lam2 ** 2 + 1 / (lam1 * lam2) ** 2 - 3
    assert 0.009 < locked.max() < 0.01                      # right at, never past, the lock
    pressure_forces = np.abs(scene.load_derivative(eq.q, "pressure")).max()
    assert eq.report.residual_norm < 1e-9 * pressure_forces
