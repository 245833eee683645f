"""Exact solutions to test against.

The uniformly inflated incompressible Mooney-Rivlin balloon with a voltage across its thickness
(Holzapfel; MODEL.md section 6), lam = r / R:

    p_hat = (4 H / R) [ c1_hat (lam^-1 - lam^-7) - c2_hat (lam^-5 - lam) - E_hat^2 lam / 2 ]
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import brentq


def balloon_pressure(lam, R=10.0, H=0.1, c1=0.4375, c2=0.0625, E_hat=0.0):
    """Normalised pressure p/mu of the uniformly inflated balloon at stretch ``lam`` (array ok)."""
    lam = np.asarray(lam, dtype=float)
    return 4.0 * H / R * (c1 * (1 / lam - lam ** -7) - c2 * (lam ** -5 - lam) - 0.5 * E_hat ** 2 * lam)


def balloon_e_hat(lam, p_hat, R=10.0, H=0.1, c1=0.4375, c2=0.0625):
    """E_hat at which the balloon at stretch ``lam`` is in equilibrium under p_hat (NaN where none)."""
    lam = np.asarray(lam, dtype=float)
    e2 = 2.0 / lam * (c1 * (1 / lam - lam ** -7) - c2 * (lam ** -5 - lam) - p_hat * R / (4.0 * H))
    return np.sqrt(np.where(e2 >= 0, e2, np.nan))


def balloon_pressure_slope(lam, R=10.0, H=0.1, c1=0.4375, c2=0.0625, E_hat=0.0):
    """d p_hat / d lam of :func:`balloon_pressure`."""
    lam = np.asarray(lam, dtype=float)
    return 4.0 * H / R * (c1 * (7 * lam ** -8 - lam ** -2) + c2 * (5 * lam ** -6 + 1) - 0.5 * E_hat ** 2)


def balloon_extrema(R=10.0, H=0.1, c1=0.4375, c2=0.0625, E_hat=0.0, lam_max=50.0):
    """[(lam, p_hat), ...] of the pressure extrema (roots of dp/dlam) in 1 < lam < lam_max, ascending.

    For the paper's balloon the first is the limit point (maximum), the second the pressure minimum.
    """
    lam = np.geomspace(1.0 + 1e-9, lam_max, 200001)
    slope = balloon_pressure_slope(lam, R, H, c1, c2, E_hat)
    out = []
    for i in np.flatnonzero(np.sign(slope[:-1]) != np.sign(slope[1:])):
        root = brentq(balloon_pressure_slope, lam[i], lam[i + 1], args=(R, H, c1, c2, E_hat), xtol=1e-15, rtol=1e-15)
        out.append((float(root), float(balloon_pressure(root, R, H, c1, c2, E_hat))))
    return out


def balloon_limit_point(R=10.0, H=0.1, c1=0.4375, c2=0.0625, E_hat=0.0):
    """(lam, p_hat) of the pressure maximum of the balloon curve."""
    return balloon_extrema(R, H, c1, c2, E_hat)[0]


def balloon_stretch(p_hat, R=10.0, H=0.1, c1=0.4375, c2=0.0625, E_hat=0.0):
    """Stretch on the rising (stable) branch below the limit point at pressure p_hat."""
    lam_lp, p_lp = balloon_limit_point(R, H, c1, c2, E_hat)
    if p_hat > p_lp:
        raise ValueError(f"p_hat = {p_hat}: above the limit pressure {p_lp}")
    return brentq(lambda x: balloon_pressure(x, R, H, c1, c2, E_hat) - p_hat, 1.0, lam_lp, xtol=1e-15)


def balloon_dynamics(pressure, t_end, R=10.0, H=0.1, c1=0.4375, c2=0.0625, E_hat=0.0, rho=1.0, xi=0.0,
                     rtol=1e-12, max_step=0.05):
    """The uniformly inflated balloon in time: one ODE, solved by scipy (DOP853) at tight tolerance.

    rho R^2 lam'' + xi rho R^2 lam' = p(t) R lam^2 / H - dW(lam, lam)/dlam, with W per unit reference
    volume including the electric term -(mu/2) E_hat^2 lam^4 (mu = 2 (c1 + c2)), from rest at
    lam = 1. Consistent units (normalised: mu = 1).

    Parameters
    ----------
    pressure : callable
        t -> p(t).

    Returns
    -------
    callable
        t -> (lam, lam') (scipy's dense output).
    """
    from scipy.integrate import solve_ivp
    mu = 2.0 * (c1 + c2)

    def rhs(t, y):
        lam, w = y
        dW = (4 * c1 * (lam - lam ** -5) + 4 * c2 * (lam ** 3 - lam ** -3) - 2 * mu * E_hat ** 2 * lam ** 3)
        return [w, (pressure(t) * R * lam ** 2 / H - dW) / (rho * R ** 2) - xi * w]

    sol = solve_ivp(rhs, (0.0, t_end), [1.0, 0.0], method="DOP853", rtol=rtol, atol=rtol,
                    dense_output=True, max_step=max_step)
    return sol.sol


def sphere_bifurcation_criterion(lam, n, c1=0.4375, c2=0.0625, E_hat=0.0):
    """The axisymmetric P_n bifurcation criterion of a uniformly inflated Mooney-Rivlin membrane
    sphere at stretch ``lam`` (MODEL.md section 7; Haughton & Ogden 1978), electric term included:

        l^2 (W11^2 - W12^2) + l W1 [(N - 1) W11 + 3 W12] - 2 W1^2,   N = n (n + 1),

    with W1, W11, W12 the derivatives of W_eff = c1 (I1 - 3) + c2 (I2 - 3) - (E_hat^2 / 2)
    l1^2 l2^2 at l1 = l2 = l (units of mu). Zero where P_n bifurcates (n = 0: the pressure
    extrema; n = 1: with a pole held)."""
    lam = np.asarray(lam, float)
    N = n * (n + 1)
    W1 = 2 * c1 * (lam - lam ** -5) + 2 * c2 * (lam ** 3 - lam ** -3) - E_hat ** 2 * lam ** 3
    W11 = 2 * c1 * (1 + 3 * lam ** -6) + 2 * c2 * (3 * lam ** -4 + lam ** 2) - E_hat ** 2 * lam ** 2
    W12 = 4 * c1 * lam ** -6 + 4 * c2 * lam ** 2 - 2 * E_hat ** 2 * lam ** 2
    return lam ** 2 * (W11 ** 2 - W12 ** 2) + lam * W1 * ((N - 1) * W11 + 3 * W12) - 2 * W1 ** 2


def sphere_bifurcation_stretches(n, c1=0.4375, c2=0.0625, E_hat=0.0, lam_max=10.0, samples=4000):
    """The stretches in (1, lam_max] where :func:`sphere_bifurcation_criterion` of mode n
    vanishes, ascending (sign changes on a fine grid refined by Brent's method)."""
    grid = np.linspace(1.0 + 1e-9, lam_max, samples)
    f = sphere_bifurcation_criterion(grid, n, c1, c2, E_hat)
    return [brentq(sphere_bifurcation_criterion, a, b, args=(n, c1, c2, E_hat), xtol=1e-14)
            for a, b, fa, fb in zip(grid[:-1], grid[1:], f[:-1], f[1:]) if fa * fb < 0]
