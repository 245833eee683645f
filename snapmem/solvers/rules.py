"""Newton's acceptance rules, written once for the Python Newton (:func:`snapmem.solvers.newton.newton`)
and the compiled time step (:mod:`snapmem.dynamics.compiled_step`) alike.

The constants are module-level floats (numba freezes them into the compiled rules) and are
collected in :data:`RULES` for reading; the rules are small compiled functions of scalars that
both paths call, so the two cannot drift apart.
"""

from __future__ import annotations

from collections import namedtuple

import numpy as np
from snapmem._lazy import njit

from snapmem.kernels.assembly import STALL_FACTOR

#: Armijo fraction: a step is accepted when the merit falls by this fraction of its linear model.
ARMIJO = 1e-4
#: A rejected step is multiplied by this (halving).
CUT = 0.5
#: Converged at rounding: the residual within STALL_FACTOR (1e3, defined with the rounding floor in
#: snapmem.kernels.assembly, whose barrier part divides by it) of the tolerance ...
#: ... while the last step was below this fraction of max |q|.
STALL_STEP = 1e-10
#: With the 'energy' merit, a step that multiplies max |R| by at most this is accepted too.
RESIDUAL_FALL = 0.5
#: The inertia term's rounding floor, STALL_FACTOR eps max(M / h^2) |q|: a time step's tolerance stays above it.
INERTIA_FLOOR = 1e3 * float(np.finfo(np.float64).eps)

#: A time step's Newton increment test: the estimate of Newton's contraction rate falls by at most
#: this factor per iteration (CVODE's CRDOWN), so that one lucky small step does not end a solve.
RATE_FALL = 0.3

NewtonRules = namedtuple("NewtonRules", "armijo cut stall_factor stall_step residual_fall inertia_floor rate_fall")
#: The constants above, together.
RULES = NewtonRules(ARMIJO, CUT, STALL_FACTOR, STALL_STEP, RESIDUAL_FALL, INERTIA_FLOOR, RATE_FALL)


@njit(cache=True, nogil=True, inline="always")
def max_abs(x):
    """max |x_i| of a 1D array: 0 if empty, NaN if x has one (as ``np.max(np.abs(x))``, which is
    its Python twin). A loop, because numba's ``np.max`` compiles its generic reduction (0.3 s of
    the compiled step's first compilation); a maximum is exact, so the value is the same."""
    largest = 0.0
    for i in range(x.size):
        a = abs(x[i])
        if a != a:
            return a
        if a > largest:
            largest = a
    return largest


@max_abs.python_twin
def _max_abs_numpy(x):
    return float(np.max(np.abs(x))) if x.size else 0.0


@njit(cache=True, nogil=True, inline="always")
def max_norm(r):
    """max |r_i| (0 for an empty r; NaN if r has one): the residual norm both solves converge in."""
    return max_abs(r)


@njit(cache=True, nogil=True, inline="always")
def step_length(alpha, dx):
    """max |alpha dx_i| of an accepted step (0 for an empty dx): what :func:`converged` compares with |q|."""
    return alpha * max_abs(dx)


@njit(cache=True, nogil=True, inline="always")
def converged(norm, tol, floor, last_step, q):
    """Whether max |R| = ``norm`` [N] is converged: at most max(tol, floor) (the tolerance, or the
    residual's rounding floor), or within STALL_FACTOR of that while the last Newton step was at the
    rounding of q (a stiff state near a law's lock; a slowly converging singular problem takes
    steps far larger than that)."""
    floor_tol = max(tol, floor)
    return norm <= floor_tol or (norm <= STALL_FACTOR * floor_tol and last_step <= STALL_STEP * max_abs(q))


@njit(cache=True, nogil=True, inline="always")
def moving_increment(dx, mass):
    """max |dx_i| over the band positions that have mass (a time step's coordinates [m]; a
    constraint's multiplier has none), NaN if one is: the increment :func:`increment_error` judges."""
    largest = 0.0
    for i in range(dx.size):
        if mass[i] > 0.0:
            a = abs(dx[i])
            if a != a:
                return a
            if a > largest:
                largest = a
    return largest


@njit(cache=True, nogil=True, inline="always")
def increment_error(increment, previous, rate):
    """A time step's Newton error left after a full Newton step of ``increment`` (its
    :func:`moving_increment` [m]), ``previous`` the full step's before it (inf: none since the
    start or a damped step) and ``rate`` the contraction rate's estimate so far (1 at the start).

    Returns (rate, error): the rate's estimate max(RATE_FALL rate, increment / previous) (CVODE's)
    and the error's, the sum of the steps still to come were they to shrink at that rate,
    rate / (1 - rate) increment (Hairer & Wanner, Solving ODEs II, IV.8); inf after a first
    full step (no rate yet) or at a rate of 1 or more (not contracting). A time step converges
    when it is at most the fraction ``newton_fraction`` of the step's error tolerance: solving
    the step's equations far below its truncation error buys nothing."""
    if previous == np.inf:
        return rate, np.inf
    rate = max(RATE_FALL * rate, increment / previous)
    if rate >= 1.0:
        return rate, np.inf
    return rate, rate / (1.0 - rate) * increment


@njit(cache=True, nogil=True, inline="always")
def converged_at_end(norm, tol, floor):
    """Whether a solve that stopped (iterations or line search exhausted) is converged all the same."""
    return norm <= max(tol, floor)


@njit(cache=True, nogil=True, inline="always")
def energy_step_accepted(trial_energy, trial_norm, energy, norm, alpha, slope):
    """The 'energy' merit (a minimisation): the trial energy is finite and falls by ARMIJO of the
    step's slope (``slope`` = R . dx, clipped at 0), or its max |R| falls to RESIDUAL_FALL of ``norm``."""
    return (np.isfinite(trial_energy) and np.isfinite(trial_norm)
            and (trial_energy <= energy + ARMIJO * alpha * min(slope, 0.0) or trial_norm <= RESIDUAL_FALL * norm))


@njit(cache=True, nogil=True, inline="always")
def residual_step_accepted(trial_squared, squared, alpha):
    """The 'residual' merit (any equilibrium): |R|^2 finite and fallen by the Armijo fraction."""
    return np.isfinite(trial_squared) and trial_squared <= (1.0 - ARMIJO * alpha) * squared


@njit(cache=True, nogil=True, inline="always")
def inertia_tolerance(tol, max_inertia, size):
    """A time step's tolerance [N]: ``tol``, kept above the inertia term's rounding floor
    INERTIA_FLOOR max(M / h^2) ``size`` (which grows as h falls)."""
    return max(tol, INERTIA_FLOOR * max_inertia * size)
