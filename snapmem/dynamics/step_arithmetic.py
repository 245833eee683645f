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
from snapmem._lazy import njit


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
