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


# --------------------------------------------------------------------------------------------
# bifurcations, loss of ellipticity and cusps of the inflated sphere (MODEL.md section 7)

def _mooney_rivlin_equibiaxial(lam, c1, c2, E_hat):
    """(W1, W11, W12) of the Mooney-Rivlin W_eff = W - (mu/2) E_hat^2 lam1^2 lam2^2 at
    lam1 = lam2 = lam, mu = 2 (c1 + c2) (normalised: c1 + c2 = 1/2 is mu = 1)."""
    lam = np.asarray(lam, dtype=float)
    a = 2.0 * (c1 + c2) * E_hat ** 2
    w1 = 2 * c1 * (lam - lam ** -5) + 2 * c2 * (lam ** 3 - lam ** -3) - a * lam ** 3
    w11 = 2 * c1 + 6 * c1 * lam ** -6 + 6 * c2 * lam ** -4 + 2 * c2 * lam ** 2 - a * lam ** 2
    w12 = 4 * c1 * lam ** -6 + 4 * c2 * lam ** 2 - 2 * a * lam ** 2
    return w1, w11, w12


def sphere_bifurcation_criterion(lam, n, c1=0.4375, c2=0.0625, E_hat=0.0):
    """The P_n bifurcation criterion of the uniformly inflated Mooney-Rivlin membrane sphere (array ok).

    l^2 (W11^2 - W12^2) + l W1 [(N - 1) W11 + 3 W12] - 2 W1^2 with N = n (n + 1) and W1, W11, W12
    the derivatives of W_eff (electric term included) at lam1 = lam2 = l (Haughton & Ogden 1978;
    MODEL.md section 7). Zero where the axisymmetric Legendre mode P_n bifurcates from the sphere;
    n = 0 gives the pressure extrema, n = 1 the mode of a sphere with one pole held.
    Normalised units (mu = 2 (c1 + c2)); the value is in mu^2.
    """
    lam = np.asarray(lam, dtype=float)
    N = n * (n + 1)
    w1, w11, w12 = _mooney_rivlin_equibiaxial(lam, c1, c2, E_hat)
    return lam ** 2 * (w11 ** 2 - w12 ** 2) + lam * w1 * ((N - 1) * w11 + 3 * w12) - 2 * w1 ** 2


def _roots(f, lo, hi, samples=20001):
    grid = np.geomspace(lo, hi, samples)
    values = f(grid)
    return [float(brentq(f, grid[i], grid[i + 1], xtol=1e-15, rtol=1e-15))
            for i in np.flatnonzero(np.sign(values[:-1]) * np.sign(values[1:]) < 0)]


def sphere_bifurcation_stretches(n, c1=0.4375, c2=0.0625, E_hat=0.0, lam_max=10.0):
    """Stretches 1 < lam < lam_max where the P_n mode bifurcates from the uniformly inflated
    sphere (roots of :func:`sphere_bifurcation_criterion` on the falling part of p(lam), where
    dp/dlam < 0 as a bifurcation needs; for n = 0 every root, the pressure extrema; roots where the sphere is no longer elliptic are kept:
    see :func:`sphere_ellipticity_loss`), ascending."""
    def f(lam):
        return sphere_bifurcation_criterion(lam, n, c1, c2, E_hat)
    return [lam for lam in _roots(f, 1.0 + 1e-9, lam_max)
            if n == 0 or balloon_pressure_slope(lam, c1=c1, c2=c2, E_hat=E_hat) < 0]


def sphere_ellipticity_loss(c1=0.4375, c2=0.0625, E_hat=0.0, lam_max=10.0):
    """The first stretch 1 < lam < lam_max where the uniformly inflated Mooney-Rivlin sphere
    loses strong ellipticity (W11 of W_eff = 0; MODEL.md section 7), or None."""
    roots = _roots(lambda lam: _mooney_rivlin_equibiaxial(lam, c1, c2, E_hat)[1], 1.0 + 1e-9, lam_max)
    return roots[0] if roots else None


def balloon_cusp_mooney_rivlin(E_hat=0.0):
    """(c2/c1, lam, p_hat) where the Mooney-Rivlin balloon's two pressure extrema merge (its
    snap disappears): dp/dlam = d2p/dlam2 = 0 of the exact p(lam), at mu = 2 (c1 + c2) = 1 and
    R/H = 100. Above this ratio p(lam) rises monotonically."""
    from scipy.optimize import fsolve

    def equations(z):
        lam, r = z
        c1, c2 = 0.5 / (1 + r), 0.5 * r / (1 + r)
        d1 = c1 * (7 * lam ** -8 - lam ** -2) + c2 * (5 * lam ** -6 + 1) - 0.5 * E_hat ** 2
        d2 = c1 * (2 * lam ** -3 - 56 * lam ** -9) - 30 * c2 * lam ** -7
        return [d1, d2]

    lam, ratio = fsolve(equations, [2.0, 0.2], xtol=1e-14)
    c1, c2 = 0.5 / (1 + ratio), 0.5 * ratio / (1 + ratio)
    return float(ratio), float(lam), float(balloon_pressure(lam, c1=c1, c2=c2, E_hat=E_hat))


def _gent_pressure_derivatives(lam, Jlim, E_hat=0.0, R=10.0, H=0.1):
    """(p_hat, dp/dlam, d2p/dlam2) of the uniformly inflated Gent balloon (mu = 1).

    p = (H / R) W'(lam) / lam^2 with W(lam) = -(Jlim/2) ln(1 - u/Jlim) - (E_hat^2/2) lam^4,
    u = I1 - 3 = 2 lam^2 + lam^-4 - 3: W' = (Jlim/2) u' / (Jlim - u) - 2 E_hat^2 lam^3.
    """
    u = 2 * lam ** 2 + lam ** -4 - 3
    du, d2u, d3u = 4 * lam - 4 * lam ** -5, 4 + 20 * lam ** -6, -120 * lam ** -7
    D = Jlim - u
    h = du / D
    dh = d2u / D + du ** 2 / D ** 2
    d2h = d3u / D + 3 * du * d2u / D ** 2 + 2 * du ** 3 / D ** 3
    A = 0.5 * Jlim
    g = A * h / lam ** 2 - 2 * E_hat ** 2 * lam
    dg = A * (dh / lam ** 2 - 2 * h / lam ** 3) - 2 * E_hat ** 2
    d2g = A * (d2h / lam ** 2 - 4 * dh / lam ** 3 + 6 * h / lam ** 4)
    return H / R * g, H / R * dg, H / R * d2g


def balloon_cusp_gent(E_hat=0.0, R=10.0, H=0.1):
    """(Jlim, lam, p_hat) where the Gent balloon's two pressure extrema merge: dp/dlam =
    d2p/dlam2 = 0 of the exact p(lam) (mu = 1). Below this Jlim p(lam) rises monotonically."""
    from scipy.optimize import fsolve

    def equations(z):
        lam, J = z
        _, d1, d2 = _gent_pressure_derivatives(lam, J, E_hat, R, H)
        return [d1 * R / H, d2 * R / H]

    lam, Jlim = fsolve(equations, [1.65, 17.8], xtol=1e-12)
    return float(Jlim), float(lam), float(_gent_pressure_derivatives(lam, Jlim, E_hat, R, H)[0])


def balloon_limit_sensitivity_e_hat(R=10.0, H=0.1, c1=0.4375, c2=0.0625, E_hat=0.0):
    """d p_hat / d E_hat at the balloon's limit point: -4 (H/R) E_hat lam_LP (the envelope
    theorem on the exact p(lam): dp/dlam = 0 there, so only the explicit E_hat dependence counts)."""
    lam = balloon_limit_point(R, H, c1, c2, E_hat)[0]
    return -4.0 * H / R * E_hat * lam
