"""The adaptive step control of a run, written once for the Python loop
(snapmem.dynamics.driver.simulate) and the compiled one (snapmem.dynamics.compiled_run).

Each is a plain Python function of numbers, which the Python loop calls, and an inlined copy
(``*_compiled``) for the compiled loop: the same operations in the same order, so both loops take
the same steps to the bit (numba compiles without fastmath; a power with a constant exponent
would be folded into products there, so none is written here).

The rules (Hairer, Norsett & Wanner, Solving ODEs I, II.4): a step whose error ratio
err = estimate / (tol max(L, max |q|)) exceeds 1 is retaken with dt max(MAX_SHRINK,
SAFETY err^(-1/(order+1))) (not below dt_min); an accepted one lets the next grow by
min(MAX_GROWTH, SAFETY err^(-1/(order+1))), not at all after a hard Newton solve (more than
HARD_NEWTON iterations); a step whose Newton fails is retaken at FAILED_CUT of its length. Steps
end at t_end and land on the load schedule's kinks.
"""

from __future__ import annotations

from snapmem._lazy import inlined

#: Safety factor of the step-size formula.
SAFETY = 0.9
#: A step grows at most by this factor...
MAX_GROWTH = 2.0
#: ... and a rejected one shrinks at most to this fraction.
MAX_SHRINK = 0.2
#: A step whose Newton did not converge is retaken at this fraction of its length.
FAILED_CUT = 0.25
#: A step whose Newton took more iterations than this does not let the next one grow.
HARD_NEWTON = 6
#: A kink of the schedule is landed on if it lies more than this [s] after the step's start ...
KINK_MARGIN = 1e-12
#: ... and a step that would end within this fraction of itself before t_end goes to t_end.
END_SLIVER = 1e-3


def step_to_take(t, dt, t_end, breaks):
    """The step [s] from t [s] of a run to ``t_end``: ``dt``, cut to end at t_end and at the first
    kink of the schedule inside it (``breaks``, increasing times [s]); one that would leave a
    sliver (END_SLIVER of itself) before t_end is taken to t_end."""
    dt = min(dt, t_end - t)
    for b in breaks:
        if t + KINK_MARGIN < b < t + dt:
            dt = b - t
            break
    if t_end - (t + dt) < END_SLIVER * dt:
        dt = t_end - t
    return dt


def error_estimate(error_constant, dt, change):
    """A scheme's local error estimate c dt^2 ``change`` [m] (Scheme.estimate, which documents it)."""
    return error_constant * dt * dt * change


def error_ratio(estimate, tol, length, largest):
    """err = ``estimate`` / (``tol`` max(``length``, ``largest``)): the step's local error estimate
    [m] over its tolerance, relative to the membrane's size (its reference size [m] or, if
    larger, its largest coordinate now [m])."""
    return estimate / (tol * max(length, largest))


def shrunk_step(dt, err, order, dt_min):
    """The step [s] to retake a step of ``dt`` rejected at error ratio ``err`` > 1 by a scheme of
    ``order``."""
    return max(dt_min, dt * max(MAX_SHRINK, SAFETY * err ** (-1.0 / (order + 1))))


def next_step(dt, err, order, iterations, dt_min, dt_max):
    """The step [s] after an accepted one of ``dt`` at error ratio ``err`` (0: no estimate) whose
    Newton took ``iterations``, by a scheme of ``order``, within [dt_min, dt_max]."""
    grow = MAX_GROWTH if err == 0.0 else min(MAX_GROWTH, SAFETY * err ** (-1.0 / (order + 1)))
    if iterations > HARD_NEWTON:
        grow = min(grow, 1.0)
    return min(dt_max, max(dt_min, dt * grow))


#: The rules above for compiled code (inlined; Python calls the functions themselves).
step_to_take_compiled = inlined(step_to_take)
error_estimate_compiled = inlined(error_estimate)
error_ratio_compiled = inlined(error_ratio)
shrunk_step_compiled = inlined(shrunk_step)
next_step_compiled = inlined(next_step)
