"""BLAS runs single-threaded inside snapmem's drivers.

snapmem's heavy work is LAPACK's band routines, which are sequential, and its parallelism is whole
processes (sweeps). Threaded BLAS only slows the small dense products around them (measured in
docs/performance.md). Drivers
(trace, fold_curve, equilibrium, simulate, hysteresis) run under :func:`single_threaded`; nested
calls pay nothing, and the caller's setting is restored on return.
"""

from __future__ import annotations

import functools
from contextlib import contextmanager

from threadpoolctl import ThreadpoolController

_depth = 0
_controller = None


def _blas():
    """One controller for the process, made on first use (building it scans the loaded libraries,
    which costs more than limiting through it), after numpy's and scipy's BLAS are loaded."""
    global _controller
    if _controller is None:
        _controller = ThreadpoolController()
    return _controller


@contextmanager
def blas_single_thread():
    """Limit BLAS to one thread for the duration (re-entrant: nested calls pay nothing)."""
    global _depth
    if _depth:
        yield
        return
    _depth += 1
    try:
        with _blas().limit(limits=1, user_api="blas"):
            yield
    finally:
        _depth -= 1


def single_threaded(function):
    """Decorator: run ``function`` under :func:`blas_single_thread`."""
    @functools.wraps(function)
    def wrapper(*args, **kwargs):
        with blas_single_thread():
            return function(*args, **kwargs)
    return wrapper
