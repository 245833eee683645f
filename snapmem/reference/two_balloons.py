"""The exact two-balloon problem: two uniformly inflated balloons sharing a fixed total volume.

Each balloon's uniform state is exact (:func:`snapmem.reference.exact.balloon_pressure`, p(lam)
with V(lam) = (4/3) pi R^3 lam^3), so the pair under total-volume control V_1 + V_2 = V_0 is a
one-degree-of-freedom problem. Its energy at fixed V_0 is E(V_1) = W_1(V_1) + W_2(V_0 - V_1)
with dW_i/dV = p_i(V), so

- equilibrium:  p_1(V_1) = p_2(V_2) (the symmetric pair, and asymmetric pairs lam_1 != lam_2);
- stability:    d2E/dV_1^2 = p_1'(V_1) + p_2'(V_2) > 0 (perturbations V_1 = -V_2, the only ones
  the total volume allows); the symmetric branch of an identical pair loses it where dp/dV = 0
  for one balloon (a pitchfork BP), and the asymmetric branch's total volume turns (an LP) where
  p_1'(V_1) + p_2'(V_2) = 0.

Normalised units (mu = 1), the MODEL.md balloon's defaults.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.optimize import brentq

from snapmem.reference.exact import balloon_extrema, balloon_pressure, balloon_pressure_slope


def balloon_volume(lam, R=10.0):
    """V = (4/3) pi R^3 lam^3 [m^3]."""
    return 4.0 / 3.0 * math.pi * R ** 3 * np.asarray(lam, float) ** 3


def pressure_volume_slope(lam, R=10.0, **law):
    """dp/dV of one balloon at stretch lam: (dp/dlam) / (dV/dlam)."""
    return balloon_pressure_slope(lam, R=R, **law) / (4.0 * math.pi * R ** 3 * np.asarray(lam, float) ** 2)


def symmetric_bifurcations(R=10.0, **law):
    """[(V_0, p, lam), ...] of the BPs of the symmetric branch of an identical pair: where one
    balloon's dp/dV = 0 (its pressure maximum and minimum)."""
    return [(2.0 * float(balloon_volume(lam, R)), p, lam) for lam, p in balloon_extrema(R=R, **law)]


def asymmetric_stretch(lam1, R=10.0, **law):
    """The partner stretch lam2 != lam1 with p(lam2) = p(lam1) on the other rising or falling part
    of an identical balloon's curve, for lam1 between the pressure maximum and minimum (the
    descending part): the root above the minimum. NaN where there is none."""
    (lam_max, p_max), (lam_min, p_min) = balloon_extrema(R=R, **law)[:2]
    p = float(balloon_pressure(lam1, R=R, **law))
    if not p_min < p < p_max:
        return math.nan
    hi = lam_min * 1.5
    while balloon_pressure(hi, R=R, **law) < p:
        hi *= 1.5
    return brentq(lambda x: balloon_pressure(x, R=R, **law) - p, lam_min, hi, xtol=1e-15)


def asymmetric_fold(R=10.0, **law):
    """(V_0, p, lam1, lam2) of the turning point of the total volume on the asymmetric branch of an
    identical pair (one balloon on the falling part lam1, the other above the minimum lam2):
    p'(V_1) + p'(V_2) = 0, the branch's change of stability."""
    (lam_max, _), (lam_min, _) = balloon_extrema(R=R, **law)[:2]

    def f(l1):
        return pressure_volume_slope(l1, R, **law) + pressure_volume_slope(asymmetric_stretch(l1, R, **law), R, **law)

    grid = np.linspace(lam_max, lam_min, 401)[1:-1]
    values = np.array([f(x) for x in grid])
    i = int(np.flatnonzero(np.sign(values[:-1]) != np.sign(values[1:]))[0])     # the first sign change
    l1 = brentq(f, grid[i], grid[i + 1], xtol=1e-15)
    l2 = asymmetric_stretch(l1, R, **law)
    return (float(balloon_volume(l1, R) + balloon_volume(l2, R)), float(balloon_pressure(l1, R=R, **law)), l1, l2)


def pair_stable(lam1, lam2, R1=10.0, R2=10.0, **law) -> bool:
    """Whether the pair (lam1, lam2) in equilibrium is stable at fixed total volume:
    p_1'(V_1) + p_2'(V_2) > 0."""
    return bool(pressure_volume_slope(lam1, R1, **law) + pressure_volume_slope(lam2, R2, **law) > 0)
