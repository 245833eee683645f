"""Loads in time: any callable t -> {name: value}, or :func:`schedule` of piecewise-linear
(t, value) points per load.

A schedule's parts (:class:`PiecewiseLinear`, :class:`Constant`) are data, so that the compiled
run (snapmem.dynamics.compiled_run) evaluates them itself, by the same :func:`interpolate`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from snapmem._lazy import inlined
from snapmem.errors import SnapmemError


def interpolate(t, times, values):
    """The piecewise-linear function through (times, values) at t, constant outside them: numpy's
    ``np.interp(t, times, values)`` for one t, its arithmetic and its choices (the slope form
    slope (t - t_j) + v_j on the interval t_j <= t < t_{j+1}; v_j itself at t = t_j; the other
    end's form where that one gives NaN), so that the same number comes out; tests hold the two
    equal. Written once for Python (:meth:`PiecewiseLinear.__call__`) and the compiled run
    (:data:`interpolate_compiled`). ``times`` non-decreasing, at least one."""
    n = len(times)
    if n == 1:
        return values[0]
    if t != t:
        return t
    if t < times[0]:
        return values[0]
    if t >= times[n - 1]:
        return values[n - 1]
    low, high = 0, n - 1                          # times[low] <= t < times[high]
    while high - low > 1:
        middle = (low + high) // 2
        if times[middle] <= t:
            low = middle
        else:
            high = middle
    if times[low] == t:
        return values[low]
    slope = (values[low + 1] - values[low]) / (times[low + 1] - times[low])
    value = slope * (t - times[low]) + values[low]
    if value != value:                            # NaN in one direction: the other
        value = slope * (t - times[low + 1]) + values[low + 1]
        if value != value and values[low] == values[low + 1]:
            value = values[low]
    return value


#: :func:`interpolate` for compiled code (inlined; Python calls the function itself).
interpolate_compiled = inlined(interpolate)

@dataclass(frozen=True)
class PiecewiseLinear:
    """A piecewise-linear function of time through (t, value) points, constant outside them.

    Attributes
    ----------
    times : tuple of float
        Increasing times [s].
    values : tuple of float
        Values at those times (load units).
    """

    times: tuple
    values: tuple

    def __post_init__(self):
        t = np.asarray(self.times, dtype=float)
        if t.size == 0 or t.size != len(self.values) or np.any(np.diff(t) < 0):
            raise SnapmemError(f"schedule times {list(self.times)}: need one value per time, times non-decreasing")

    def __call__(self, t: float) -> float:
        return float(interpolate(t, self.times, self.values))


@dataclass(frozen=True)
class Constant:
    """A load held at ``value`` (load units) at every time."""

    value: float

    def __call__(self, t: float) -> float:
        return self.value


def schedule(**loads) -> Callable[[float], dict]:
    """A load schedule t -> {name: value} from per-load constants, callables or (t, value) lists.

    Examples
    --------
    >>> loads = schedule(pressure=[(0, 0), (5, 0), (20, 150)], voltage=300.0)
    >>> loads(10.0)
    {'pressure': 50.0, 'voltage': 300.0}

    The schedule's ``parts`` map each name to its :class:`PiecewiseLinear`, :class:`Constant` or
    callable; its ``breakpoints`` are the times of every kink (steps land on them).
    """
    parts = {}
    for name, spec in loads.items():
        if callable(spec):
            parts[name] = spec
        elif np.ndim(spec) == 0:
            parts[name] = Constant(float(spec))
        else:
            pts = np.asarray(spec, dtype=float)
            parts[name] = PiecewiseLinear(tuple(pts[:, 0]), tuple(pts[:, 1]))

    def at(t: float) -> dict:
        return {name: f(t) for name, f in parts.items()}

    at.breakpoints = sorted({float(x) for f in parts.values() for x in getattr(f, "times", ())})
    at.parts = parts
    return at


def as_schedule(loads) -> Callable[[float], dict]:
    """The schedule t -> {name: value} of ``loads``: None (no loads), a callable t -> mapping, or a
    mapping of per-load constants, callables or (t, value) lists (:func:`schedule`)."""
    if loads is None:
        return schedule()
    if callable(loads):
        return loads
    return schedule(**dict(loads))

