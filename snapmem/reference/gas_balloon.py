"""The exact balloon on a gas reservoir: where its snap appears as the reservoir grows (a cusp).

A uniformly inflated balloon (MODEL.md's p(lam), :func:`snapmem.reference.exact.balloon_pressure`,
volume V(lam) = (4/3) pi R^3 lam^3) joined to a reservoir of volume V_d holds a fixed amount of
gas. With P = p + p_atm the absolute pressure, the gas law P (V + V_d)^gamma = A (A = n R T for
the isothermal gas, gamma = 1; the adiabat's constant for gamma > 1) makes the equilibria a
one-parameter curve in lam, along which the amount is

    A(lam) = (p(lam) + p_atm) (V(lam) + V_d)^gamma.

The control A has a maximum and a minimum (a snap under increasing gas amount) where dA/dlam = 0:

    (V + V_d) p'(lam) + gamma (p + p_atm) V'(lam) = 0,
    i.e.  V_d = D(lam) = -gamma (p + p_atm) V'(lam) / p'(lam) - V(lam),

possible only where p' < 0, between the balloon's pressure maximum and minimum. D tends to
infinity at both ends of that interval, so the reservoir size D(lam) has a minimum V_d*: below it
A(lam) is monotonic (no snap, as under volume control, V_d = 0), above it there are two limit
points that tend to the pressure maximum and minimum as V_d grows (pressure control). V_d* is the
cusp, where the pair merges.

Normalised units (mu = 1), the MODEL.md balloon's defaults; ``p_atm`` = 0.25 as the scene's.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.optimize import brentq, minimize_scalar

from snapmem.reference.exact import balloon_extrema, balloon_pressure, balloon_pressure_slope
from snapmem.reference.two_balloons import balloon_volume


def reservoir_at_fold(lam, R=10.0, p_atm=0.25, gamma=1.0, **law):
    """D(lam) [m^3]: the reservoir volume for which the balloon at stretch ``lam`` (on the falling
    part of p(lam)) is a limit point of the gas amount (module docstring)."""
    lam = np.asarray(lam, dtype=float)
    p, slope = balloon_pressure(lam, R=R, **law), balloon_pressure_slope(lam, R=R, **law)
    dV = 4.0 * math.pi * R ** 3 * lam ** 2
    return -gamma * (p + p_atm) * dV / slope - balloon_volume(lam, R)


def gas_amount(lam, reservoir, R=10.0, p_atm=0.25, gamma=1.0, **law):
    """A = (p + p_atm) (V + V_d)^gamma of the balloon at stretch ``lam`` on a reservoir ``reservoir`` [m^3]."""
    return (balloon_pressure(lam, R=R, **law) + p_atm) * (balloon_volume(lam, R) + reservoir) ** gamma


def cusp(R=10.0, p_atm=0.25, gamma=1.0, **law) -> dict:
    """The cusp: the smallest reservoir V_d* [m^3] with a snap, as ``reservoir`` (also relative to
    the balloon's reference volume, ``reservoir_ratio``), with its stretch ``lam``, gauge pressure
    ``pressure`` and gas amount ``amount``."""
    (lam_max, _), (lam_min, _) = balloon_extrema(R=R, **law)[:2]
    span = lam_min - lam_max
    found = minimize_scalar(lambda x: float(reservoir_at_fold(x, R, p_atm, gamma, **law)),
                            bounds=(lam_max + 1e-6 * span, lam_min - 1e-6 * span), method="bounded",
                            options={"xatol": 1e-13})
    lam, v = float(found.x), float(found.fun)
    return {"reservoir": v, "reservoir_ratio": v / float(balloon_volume(1.0, R)), "lam": lam,
            "pressure": float(balloon_pressure(lam, R=R, **law)), "amount": float(gas_amount(lam, v, R, p_atm, gamma, **law))}


def limit_points(reservoir, R=10.0, p_atm=0.25, gamma=1.0, **law) -> list:
    """[(lam, pressure, amount), (lam, pressure, amount)] of the maximum and the minimum of the gas
    amount on a reservoir of ``reservoir`` [m^3] (the snap up and the snap back); [] below the cusp."""
    c = cusp(R, p_atm, gamma, **law)
    if reservoir <= c["reservoir"]:
        return []
    (lam_max, _), (lam_min, _) = balloon_extrema(R=R, **law)[:2]

    def f(x):
        return float(reservoir_at_fold(x, R, p_atm, gamma, **law)) - reservoir

    out = []
    for a, b in ((lam_max, c["lam"]), (c["lam"], lam_min)):
        lo, hi = (a + 1e-12 * (b - a), b) if a == lam_max else (a, b - 1e-12 * (b - a))
        lam = brentq(f, lo, hi, xtol=1e-15, rtol=1e-15)
        out.append((lam, float(balloon_pressure(lam, R=R, **law)), float(gas_amount(lam, reservoir, R, p_atm, gamma, **law))))
    return out
