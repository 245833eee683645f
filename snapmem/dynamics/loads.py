"""Loads in time: any callable t -> {name: value}, or :func:`schedule` of piecewise-linear
(t, value) points per load."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from snapmem.errors import SnapmemError

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
        return float(np.interp(t, self.times, self.values))


def schedule(**loads) -> Callable[[float], dict]:
    """A load schedule t -> {name: value} from per-load constants, callables or (t, value) lists.

    Examples
    --------
    >>> loads = schedule(pressure=[(0, 0), (5, 0), (20, 150)], voltage=300.0)
    >>> loads(10.0)
    {'pressure': 50.0, 'voltage': 300.0}
    """
    parts = {}
    for name, spec in loads.items():
        if callable(spec):
            parts[name] = spec
        elif np.ndim(spec) == 0:
            parts[name] = (lambda c: lambda t: c)(float(spec))
        else:
            pts = np.asarray(spec, dtype=float)
            parts[name] = PiecewiseLinear(tuple(pts[:, 0]), tuple(pts[:, 1]))

    def at(t: float) -> dict:
        return {name: f(t) for name, f in parts.items()}

    at.breakpoints = sorted({float(x) for f in parts.values() for x in getattr(f, "times", ())})
    return at


def as_schedule(loads) -> Callable[[float], dict]:
    """The schedule t -> {name: value} of ``loads``: None (no loads), a callable t -> mapping, or a
    mapping of per-load constants, callables or (t, value) lists (:func:`schedule`)."""
    if loads is None:
        return schedule()
    if callable(loads):
        return loads
    return schedule(**dict(loads))

