"""The schemes' per-step vector arithmetic, compiled: each a loop with the very operations (and
their order) of the numpy expression it replaces, so every number is the same to the bit (numba
compiles without fastmath: no reordering, no fused multiply-adds).

Why: a robot's step is ~100 us of compiled Newton, and a numpy expression on its ~100-entry
state costs ~0.4 us a ufunc (and a copy for a fancy index): BDF2's anchor is ten of them (4.4 us
measured, the kernel 1.6 us), the error estimate's max |a - b| over the free entries four and an
index (3 us, the kernel ~1 us). A compiled call itself costs ~0.8 us, so a one- or two-ufunc
expression (a velocity (y - q) / h) stays numpy.

Python calls them once a step, so while numba's cache does not hold them they run as Python
(``interpret_uncached``: their compilation, some 0.3-0.4 s together, would be most of a short
cold run's time in them): as their twins, the numpy expressions they replace.
"""

from __future__ import annotations

import numpy as np
from snapmem._lazy import inlined, njit
from snapmem.solvers.rules import _max_abs_numpy, max_abs


@njit(cache=True, nogil=True, interpret_uncached=True)
def bdf2_anchor(q, v, q_previous, v_previous, a0, a1, a2):
    """BDF2's anchor (x_hat, v_hat) = (-(a1 q + a2 q_{n-1}) / a0, -(a1 v + a2 v_{n-1}) / a0)."""
    x_hat, v_hat = np.empty_like(q), np.empty_like(v)
    for i in range(q.size):
        x_hat[i] = -(a1 * q[i] + a2 * q_previous[i]) / a0
        v_hat[i] = -(a1 * v[i] + a2 * v_previous[i]) / a0
    return x_hat, v_hat


@bdf2_anchor.python_twin
def _bdf2_anchor_python(q, v, q_previous, v_previous, a0, a1, a2):
    return -(a1 * q + a2 * q_previous) / a0, -(a1 * v + a2 * v_previous) / a0


@njit(cache=True, nogil=True, interpret_uncached=True)
def largest_change(a, b, free):
    """max |a - b| over the entries ``free`` (NaN if any is NaN), np.abs(a - b)[free].max()."""
    largest = -np.inf
    for i in free:
        d = abs(a[i] - b[i])
        if d != d:
            return d
        if d > largest:
            largest = d
    return largest


@largest_change.python_twin
def _largest_change_python(a, b, free):
    return float(np.max(np.abs(a[free] - b[free]), initial=-np.inf))         # (a maximum is exact; NaN propagates)


@njit(cache=True, nogil=True, interpret_uncached=True)
def largest_entry(a, free):
    """max |a| over the entries ``free`` (NaN if any is NaN), np.abs(a)[free].max()."""
    largest = -np.inf
    for i in free:
        d = abs(a[i])
        if d != d:
            return d
        if d > largest:
            largest = d
    return largest


@largest_entry.python_twin
def _largest_entry_python(a, free):
    return float(np.max(np.abs(a[free]), initial=-np.inf))


#: What a step's outcome (:func:`step_outcome`) is, by scheme: a scheme whose new state is Newton's
#: own with the error of its largest acceleration (implicit Euler) or of its largest change of
#: acceleration (BDF2), or the implicit midpoint rule's. ``NO_OUTCOME``: the compiled time step
#: computes none (snapmem.dynamics.compiled_newton.time_step).
NO_OUTCOME, BACKWARD_ABSOLUTE, BACKWARD_RELATIVE, MIDPOINT = range(4)


@njit(cache=True, nogil=True, interpret_uncached=True)
def step_outcome(kind, y, q, v, h, step, a_previous, free, n_node_dofs):
    """Everything a step yields from its solve's solution y, in one pass, for a scheme of ``kind``:
    (q_{n+1}, v_{n+1}, a, change, largest), with (q, v) the anchor the solve was taken from (x_hat,
    v_hat) and h its step [s].

    - backward (Euler, BDF2): q_{n+1} = y, v_{n+1} = (y - x_hat) / h, a = (v_{n+1} - v_hat) / ``step``;
    - midpoint: q_{n+1} = 2 y - q_n, v_{n+1} = 2 (y - q_n) / h - v_n, a = (v_{n+1} - v_n) / ``step``;

    and the error control's two maxima: change, :func:`largest_change` of a and a_previous over
    ``free`` (:func:`largest_entry` of a for BACKWARD_ABSOLUTE), and largest, max |q_{n+1}| over the
    first ``n_node_dofs`` entries (snapmem.solvers.rules.max_abs). The schemes' own formulas
    (snapmem.dynamics.schemes), loop by loop."""
    v_new, a = np.empty_like(y), np.empty_like(y)
    if kind == MIDPOINT:
        q_new = np.empty_like(y)
        for i in range(y.size):
            q_new[i] = 2.0 * y[i] - q[i]
            v_new[i] = 2.0 * (y[i] - q[i]) / h - v[i]
            a[i] = (v_new[i] - v[i]) / step
    else:
        q_new = y
        for i in range(y.size):
            v_new[i] = (y[i] - q[i]) / h
            a[i] = (v_new[i] - v[i]) / step
    change = largest_entry(a, free) if kind == BACKWARD_ABSOLUTE else largest_change(a, a_previous, free)
    return q_new, v_new, a, change, max_abs(q_new[:n_node_dofs])


@step_outcome.python_twin
def _step_outcome_python(kind, y, q, v, h, step, a_previous, free, n_node_dofs):
    if kind == MIDPOINT:
        q_new, v_new = 2.0 * y - q, 2.0 * (y - q) / h - v
    else:
        q_new, v_new = y, (y - q) / h
    a = (v_new - v) / step
    if kind == BACKWARD_ABSOLUTE:
        change = _largest_entry_python(a, free)
    else:
        change = _largest_change_python(a, a_previous, free)
    return q_new, v_new, a, change, _max_abs_numpy(q_new[:n_node_dofs])



#: The schemes, by number (each :class:`snapmem.dynamics.schemes.Scheme`'s ``kind``), as the
#: compiled run (snapmem.dynamics.compiled_run) takes them.
EULER, MIDPOINT_RULE, BDF2 = range(3)


def scheme_step(kind, t, dt, past_dt):
    """Every number of a step of scheme ``kind`` (EULER, MIDPOINT_RULE, BDF2) from t by dt [s]:
    the schemes' formulas (snapmem.dynamics.schemes, which documents them), written once for
    the Python schemes and the compiled run. ``past_dt``: the last step [s] (BDF2 only; BDF2
    with no history takes EULER's step).

    Returns (h, load_time, outcome_kind, outcome_step, a0, a1, a2, c_now, c_previous, n_star,
    n_now, n_previous): the step h of the backward-Euler solve [s] and the time of its loads
    [s]; :func:`step_outcome`'s kind and step; BDF2's weights (a0, a1, a2) (w = dt / past_dt,
    a0 = (1 + 2w) / (1 + w), a1 = -(1 + w), a2 = w^2 / (1 + w); (1, -1, 0) for the others); the
    maps of the step on a state at rest (``Scheme.rest_coefficients``): the anchor c_now x_n +
    c_previous x_{n-1} and the new state n_star y + n_now x_n + n_previous x_{n-1}."""
    if kind == EULER:
        return dt, t + dt, BACKWARD_ABSOLUTE, dt, 1.0, -1.0, 0.0, 1.0, 0.0, 1.0, 0.0, 0.0
    if kind == MIDPOINT_RULE:
        h = dt / 2
        return h, t + h, MIDPOINT, dt, 1.0, -1.0, 0.0, 1.0, 0.0, 2.0, -1.0, 0.0
    w = dt / past_dt
    a0, a1, a2 = (1 + 2 * w) / (1 + w), -(1 + w), w * w / (1 + w)
    h = dt / a0
    return h, t + dt, BACKWARD_RELATIVE, h, a0, a1, a2, -(a1 * 1.0) / a0, -(a2 * 1.0) / a0, 1.0, 0.0, 0.0


#: :func:`scheme_step` for compiled code (inlined; Python calls the function itself).
scheme_step_compiled = inlined(scheme_step)
