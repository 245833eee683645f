"""The viscous networks' state across steps (snapmem.dynamics.stepper._InternalState): the scheme's
anchor and new state as linear maps read off the scheme, applied by one compiled call per step,
and the frames' stored energy over all frames in one call, each against the formula it stands for."""

import numpy as np
import pytest

from snapmem.catalog.registry import build_scene
from snapmem.dynamics.schemes import SCHEME_BY_NAME
from snapmem.dynamics.stepper import scheme_coefficients
from snapmem.kernels import viscous as kv
from snapmem.model.viscous import viscous_terms

RNG = np.random.default_rng(15)


@pytest.mark.parametrize("name", sorted(SCHEME_BY_NAME))
@pytest.mark.parametrize("past_dt", [None, 0.013])
def test_scheme_coefficients_are_the_schemes_maps(name, past_dt):
    """c_now z + c_previous z_prev is the scheme's x_hat of a state at rest, n_star y + n_now z +
    n_previous z_prev its new state, h its step: to rounding, for every scheme, with and without
    history (BDF2's variable-step weights, dt / dt_prev = 0.77 here)."""
    scheme, dt = SCHEME_BY_NAME[name], 0.01
    z, z_prev, y = RNG.normal(size=(3, 2, 2, 7))
    zero = np.zeros_like(z)
    past = None if past_dt is None else (z_prev, zero, past_dt)
    anchor = scheme.anchor(z, zero, 0.3, dt, past)
    h, c_now, c_prev, n_star, n_now, n_prev = scheme_coefficients(scheme, 0.3, dt, past_dt)
    previous = z if past_dt is None else z_prev
    assert h == anchor.h
    np.testing.assert_allclose(c_now * z + c_prev * previous, anchor.q, rtol=0, atol=1e-15)
    np.testing.assert_allclose(n_star * y + n_now * z + n_prev * previous, anchor.new_state(y)[0], rtol=0,
                               atol=1e-15)
    if past_dt is None:
        assert c_prev == n_prev == 0.0


def test_state_kernels_compiled_match_python_and_dissipation():
    """anchor_internal and update_internal write the linear maps into the given arrays, compiled
    and as Python alike; update_internal returns step_dissipation's energy of the step."""
    z, z_prev, star, hat = RNG.normal(size=(4, 2, 2, 9))
    viscosities, weight = np.array([2.0, 0.5]), RNG.uniform(0.1, 1.0, 9)
    for kernel in (kv.anchor_internal, kv.anchor_internal.py_func):
        out = np.empty_like(z)
        kernel(z, z_prev, 1.4, -0.4, out)
        np.testing.assert_array_equal(out, 1.4 * z + -0.4 * z_prev)
    energies = []
    for kernel in (kv.update_internal, kv.update_internal.py_func):
        out = np.empty_like(z)
        energies.append(kernel(star, z, z_prev, 2.0, -1.0, 0.0, hat, 0.005, 0.01, viscosities, weight, out))
        np.testing.assert_array_equal(out, 2.0 * star + -1.0 * z + 0.0 * z_prev)
    r = (star - hat) / 0.005
    expected = 0.01 * np.sum(viscosities[:, None] * (4 * r[:, 0] ** 2 + 4 * r[:, 0] * r[:, 1] + 4 * r[:, 1] ** 2)
                             * weight)
    np.testing.assert_allclose(energies, expected, rtol=1e-13)


def test_stored_energy_frames_is_stored_energy_of_each_frame():
    """One call over the frames gives each frame's stored_energy at its own stretches (the scene's
    kinematics) and internal stretches."""
    scene = build_scene("balloon", nodes=21, viscous_mu=0.5, relaxation_time=1.0)
    term = viscous_terms(scene)[0]
    q0 = scene.reference_state()
    Q = np.array([q0 * s for s in (1.0, 1.1, 1.3)])
    zetas = RNG.normal(scale=0.1, size=(3, term.networks, 2, scene.meridian.edges.shape[0]))
    m = scene.meridian
    many = kv.stored_energy_frames(Q, m.edges, m.inverse_length, m.inverse_mid_radius, zetas, term.moduli,
                                   term.jlims, scene.weight)
    each = [term.stored_energy(scene.kinematics(q), zeta, scene.weight) for q, zeta in zip(Q, zetas)]
    np.testing.assert_allclose(many, each, rtol=1e-14)
    assert np.all(np.diff(many) != 0.0)
