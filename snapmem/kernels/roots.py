"""Brent's root finder in Python: scipy.optimize.brentq's iteration, operation for operation.

``from scipy.optimize import brentq`` imports all of scipy.optimize, and with it scipy.linalg and
scipy.sparse, a large part of a ``snapmem trace`` (docs/performance.md, "Start-up"). The iteration is 40
lines of C in scipy (``scipy/optimize/Zeros/brentq.c``), transcribed here with the same
arithmetic in the same order, so it returns the same root bit for bit after the same function
calls (tests/test_startup_cold.py checks this against scipy on many brackets).
"""

from __future__ import annotations

import math

__all__ = ["brentq"]

#: scipy's smallest allowed ``rtol``: 4 eps.
RTOL_MIN = 4 * 2.220446049250313e-16


def brentq(f, a: float, b: float, xtol: float = 2e-12, rtol: float = RTOL_MIN, maxiter: int = 100) -> float:
    """A root of ``f`` in [a, b] (f(a), f(b) of opposite signs), as ``scipy.optimize.brentq``.

    Parameters
    ----------
    f : callable
        float -> float.
    a, b : float
        The bracket.
    xtol, rtol : float
        The root is within ``xtol + rtol |x|`` of the exact one (scipy's meaning); rtol >= 4 eps.
    maxiter : int
        Iteration limit.

    Returns
    -------
    float

    Raises
    ------
    ValueError
        f(a) and f(b) of one sign, a NaN value, or bad tolerances (scipy's errors).
    RuntimeError
        No convergence within ``maxiter`` iterations (scipy's).
    """
    if xtol <= 0:
        raise ValueError(f"xtol too small ({xtol:g} <= 0)")
    if rtol < RTOL_MIN:
        raise ValueError(f"rtol too small ({rtol:g} < {RTOL_MIN:g})")

    def value(x):
        fx = float(f(x))
        if math.isnan(fx):
            raise ValueError(f"The function value at x={x:f} is NaN; solver cannot continue.")
        return fx

    xpre, xcur = float(a), float(b)
    xblk = fblk = spre = scur = 0.0
    fpre = value(xpre)
    fcur = value(xcur)
    if fpre == 0:
        return xpre
    if fcur == 0:
        return xcur
    if math.copysign(1.0, fpre) == math.copysign(1.0, fcur):
        raise ValueError("f(a) and f(b) must have different signs")
    for _ in range(maxiter):
        if fpre != 0 and fcur != 0 and math.copysign(1.0, fpre) != math.copysign(1.0, fcur):
            xblk = xpre
            fblk = fpre
            spre = scur = xcur - xpre
        if abs(fblk) < abs(fcur):
            xpre, xcur, xblk = xcur, xblk, xcur
            fpre, fcur, fblk = fcur, fblk, fcur
        delta = (xtol + rtol * abs(xcur)) / 2
        sbis = (xblk - xcur) / 2
        if fcur == 0 or abs(sbis) < delta:
            return xcur
        if abs(spre) > delta and abs(fcur) < abs(fpre):
            if xpre == xblk:
                stry = -fcur * (xcur - xpre) / (fcur - fpre)            # interpolate
            else:
                dpre = (fpre - fcur) / (xpre - xcur)                    # extrapolate
                dblk = (fblk - fcur) / (xblk - xcur)
                stry = -fcur * (fblk * dblk - fpre * dpre) / (dblk * dpre * (fblk - fpre))
            bound = abs(spre) if abs(spre) < 3 * abs(sbis) - delta else 3 * abs(sbis) - delta   # C's MIN
            if 2 * abs(stry) < bound:
                spre, scur = scur, stry                                 # good short step
            else:
                spre = scur = sbis                                      # bisect
        else:
            spre = scur = sbis                                          # bisect
        xpre, fpre = xcur, fcur
        xcur += scur if abs(scur) > delta else (delta if sbis > 0 else -delta)
        fcur = value(xcur)
    raise RuntimeError(f"Failed to converge after {maxiter} iterations, value is {xcur:f}.")
