"""The compiled step's fused local solve (snapmem.kernels.viscous.edge_condensed) against the
flow rule and condensed density it fuses (network_internal, then network_condensed), and the
series of exp(2 s) it updates the elastic stretches with."""

import numpy as np
import pytest

from snapmem._lazy import python_of
from snapmem.kernels import viscous as kv

RNG = np.random.default_rng(2026)


def test_exp_twice_is_exp_to_rounding():
    s = np.concatenate([RNG.uniform(-1, 1, 50) * kv.SERIES_BELOW, [0.0, 0.999 * kv.SERIES_BELOW, -kv.SERIES_BELOW],
                        RNG.uniform(-0.3, 0.3, 20)])
    series = np.array([kv.exp_twice.py_func(x) for x in s])
    np.testing.assert_allclose(series, np.exp(2.0 * s), rtol=4e-16, atol=0)


@pytest.mark.parametrize("jlim", [np.inf, 3.0], ids=["neo-Hookean", "Gent"])
def test_edge_condensed_is_the_local_solve_then_the_condensed_density(jlim):
    """From a warm start off the solution (as in a Newton iteration), at stretches of a few per
    cent to 40%: the same internal stretches and density to rounding, with converged = True."""
    mu, c = 0.7, 2.5
    for _ in range(40):
        lam = RNG.uniform(0.8, 1.4, 2)
        zhat = RNG.uniform(-0.1, 0.1, 2)
        start = zhat + RNG.uniform(-0.05, 0.05, 2)
        eps = np.log(lam)
        # python_of: its callees as Python too (a caller compiled before may have bound their module
        # names to dispatchers, which these arrays would compile for: 10 s)
        z1, z2, ok = python_of(kv.network_internal)(eps[:1], eps[1:], start[:1], start[1:], zhat[:1], zhat[1:], mu,
                                                    jlim, c)
        assert ok
        expected = kv.network_condensed.py_func(eps[0], eps[1], z1[0], z2[0], zhat[0], zhat[1], mu, jlim, c)
        got = kv.edge_condensed.py_func(lam[0], lam[1], start[0], start[1], np.exp(-2 * start[0]),
                                        np.exp(-2 * start[1]), zhat[0], zhat[1], mu, jlim, c)
        fz1, fz2, u1, u2, done = got[:5]
        assert done
        assert abs(fz1 - z1[0]) < 1e-13 and abs(fz2 - z2[0]) < 1e-13
        assert abs(u1 - np.exp(-2 * fz1)) < 1e-13 and abs(u2 - np.exp(-2 * fz2)) < 1e-13
        scale = max(abs(x) for x in expected)
        np.testing.assert_allclose(got[5:], expected, rtol=0, atol=1e-12 * scale)


def test_edge_condensed_without_a_step_holds_the_anchor():
    """c = 0 (outside a step): zeta stays at zeta_hat, the network's own density there."""
    lam, zhat = np.array([1.2, 0.9]), np.array([0.05, -0.02])
    got = kv.edge_condensed.py_func(lam[0], lam[1], 0.3, 0.3, 1.0, 1.0, zhat[0], zhat[1], 0.7, np.inf, 0.0)
    assert got[:2] == (zhat[0], zhat[1]) and got[4]
    expected = kv.network_log_derivatives.py_func(np.log(lam[0]) - zhat[0], np.log(lam[1]) - zhat[1], 0.7, np.inf)
    np.testing.assert_allclose(got[5:], expected, rtol=1e-14, atol=1e-15)
