"""First use of the compiled time step: its call tree compiled by two processes at once.

With numba's cache empty (the first ``snapmem simulate`` after an install), the first call of
:func:`~snapmem.dynamics.compiled_newton.time_step` compiles some forty kernels one after the
other, on one core: numba types a kernel's callees as it meets them, and compiles each at that
moment. Most of that time is independent work. :func:`compile_in_two` splits it: a second
process compiles the membrane's assembly (:func:`~snapmem.dynamics.compiled_assembly.assemble`
and what it calls, the largest subtree) into numba's cache while this one compiles the domain
checks, the step limit, the band solve and Newton's rules; then ``time_step`` compiles, finding
every callee compiled (its own or loaded from the cache the other process wrote).

The machine code is what one process would have made (the same numba, the same types): the
numbers are the same bit for bit. The signatures are those ``time_step`` types its callees with,
derived from its arguments by :func:`callee_signatures` (tests/test_precompile.py holds them to
the signatures a compile in one process makes). A wrong one costs a compile, never a number.

``SNAPMEM_PARALLEL_COMPILE=0`` turns it off.
"""

from __future__ import annotations

import os
import pickle
import subprocess
import sys
import tempfile

#: Seconds this process waits for the other one before compiling what is left itself.
WAIT = 120.0


def enabled() -> bool:
    """Whether a cold compile of the time step may use a second process."""
    return os.environ.get("SNAPMEM_PARALLEL_COMPILE", "1") != "0"


def callee_signatures(args: tuple) -> tuple[list, list]:
    """(the other process's share, this process's share): lists of (module, kernel name, numba
    signature) of the kernels :func:`~snapmem.dynamics.compiled_newton.time_step` calls, for its
    arguments ``args`` (in its order: anchor, velocity, h, mass, damping, fallback, P,
    general_law, linear, balls, viscous, network_step, pressure, a_el, tol, size, max_iterations,
    max_cuts)."""
    from numba import typeof, types
    from snapmem.kernels.linalg import REFINE_ON_CANCELLATION
    vector, f8, i8 = types.float64[::1], types.float64, types.int64
    band, matrix = types.float64[::1, :], types.float64[:, ::1]      # the band is Fortran-ordered
    plan, general_law, linear, balls, viscous, network_step = (typeof(a) for a in args[6:12])
    assembly, rules, bordered = ("snapmem.dynamics.compiled_assembly", "snapmem.solvers.rules",
                                 "snapmem.kernels.bordered")
    other = [(assembly, "assemble", (vector, plan, general_law, linear, balls, viscous, f8, f8, vector, vector,
                                     vector, i8))]
    here = [(rules, "inertia_tolerance", (f8, f8, f8)),
            (assembly, "admissible", (vector, plan, general_law, linear, balls)),
            (rules, "max_norm", (vector,)),
            (rules, "converged", (f8, f8, f8, f8, vector)),
            (bordered, "band_solve", (band, vector)) if balls == types.none else
            (bordered, "bordered_solve", (band, matrix, matrix, vector, types.literal(REFINE_ON_CANCELLATION))),
            (assembly, "max_step", (vector, vector, plan, linear, balls)),
            (assembly, "state_ok", (vector, plan, general_law)),
            (rules, "energy_step_accepted", (f8, f8, f8, f8, f8, f8)),
            (rules, "step_length", (f8, vector)),
            (rules, "converged_at_end", (f8, f8, f8))]
    if viscous != types.none:
        P = args[6]
        stretches = (vector, typeof(P.edges), typeof(P.inv_length), typeof(P.inv_mid_radius))
        here += [(assembly, "start_networks", (viscous,)),
                 ("snapmem.kernels.assembly", "edge_stretches", stretches),
                 (assembly, "law_with_networks", (vector, vector, plan, general_law, viscous))]
        if network_step != types.none:
            here += [(assembly, "open_network_step", (viscous, network_step)),
                     (assembly, "close_network_step", (viscous, network_step, typeof(P.weight)))]
    return other, here


def _kernel(module: str, name: str):
    import importlib
    return getattr(importlib.import_module(module), name)


def _compile(jobs: list) -> None:
    for module, name, signature in jobs:
        kernel = _kernel(module, name)
        getattr(kernel, "dispatcher", kernel).compile(signature)


def compile_in_two(args: tuple) -> None:
    """Compile ``time_step``'s callees for ``args`` in two processes (see the module's docstring);
    returns when both shares are compiled. It never fails a run: should the other process fail or
    time out, or another snapmem process be compiling into this cache already (a sweep's workers,
    a background compile), what was not compiled ahead ``time_step`` compiles as usual."""
    from snapmem._lazy import _take_compile_lock
    lock = _take_compile_lock()
    if lock is None:
        return
    path = None
    try:
        other, here = callee_signatures(args)
        handle, path = tempfile.mkstemp(prefix="snapmem-precompile-", suffix=".pickle")
        with os.fdopen(handle, "wb") as file:
            pickle.dump(other, file)
        environment = dict(os.environ, SNAPMEM_BACKGROUND_COMPILE="0", SNAPMEM_PARALLEL_COMPILE="0")
        process = subprocess.Popen([sys.executable, "-c", "import sys; from snapmem.dynamics.precompile import "
                                    "compile_file; compile_file(sys.argv[1])", path],
                                   stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                                   env=environment)
        try:
            _compile(here)
            process.wait(WAIT)
        except subprocess.TimeoutExpired:
            process.kill()
    except Exception:           # (a type that does not pickle, a signature a kernel rejects): compile as usual
        pass
    finally:
        for leftover in (path, lock):
            if leftover is not None and os.path.exists(leftover):
                os.unlink(leftover)


def compile_file(path: str) -> None:
    """The other process: compile the jobs pickled in ``path`` into numba's cache."""
    with open(path, "rb") as file:
        jobs = pickle.load(file)
    _compile(jobs)
