"""BLAS runs single-threaded inside snapmem's drivers.

snapmem's heavy work is LAPACK's band routines, which are sequential, and its parallelism is whole
processes (sweeps). Threaded BLAS only slows the small dense products around them: on this 2-core
machine, shared with other work, numpy's QR of a 3200 x 6 block took 13.9 ms with OpenBLAS's
threads and 1.9 ms without (a traced torus at N = 1600 spent 9 of its 14 s there). Drivers
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
    """One controller for the process: building it scans the loaded libraries (0.4 ms, which the
    profile of a 23 ms ball_throw showed); limiting through it costs 0.01 ms. Made on first use,
    after numpy's and scipy's BLAS are loaded (importing snapmem loads both)."""
    global _controller
    if _controller is None:
        _controller = ThreadpoolController()
    return _controller


@contextmanager
def blas_single_thread():
    """Limit BLAS to one thread for the duration (re-entrant; 0.01 ms at the outermost level)."""
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
