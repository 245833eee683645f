"""Start-up loads nothing it does not use: ``import snapmem``, ``snapmem --help`` and ``snapmem
scenes`` import neither numba (no compiled kernel is loaded) nor pandas nor matplotlib; and the
package's lazily compiled kernels work as numba's (a kernel calling kernels, ``.py_func``)."""

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
HEAVY = ("numba", "llvmlite", "pandas", "matplotlib", "scipy.optimize", "scipy.linalg")

CHECK = """
import sys, io, contextlib
{run}
print(" ".join(m for m in {heavy!r} if m in sys.modules) or "none")
"""


def loaded_after(run: str, **environment) -> str:
    code = CHECK.format(run=run, heavy=HEAVY)
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT,
                          env={"PYTHONPATH": str(ROOT), "PATH": "/usr/bin:/bin", **environment}, timeout=120)
    assert done.returncode == 0, done.stderr
    return done.stdout.strip().splitlines()[-1]


@pytest.mark.parametrize("run", [
    "import snapmem",
    "import snapmem.cli",
    "from snapmem.cli import main\nwith contextlib.redirect_stdout(io.StringIO()): main(['scenes'])",
    "from snapmem.cli import main\nwith contextlib.redirect_stdout(io.StringIO()):\n"
    "    try: main(['--help'])\n    except SystemExit: pass",
    "import snapmem\nsnapmem.build_scene('balloon', nodes=11)",
])
def test_start_up_imports_no_numba_pandas_or_matplotlib(run):
    assert loaded_after(run) == "none"


def test_a_command_loads_numba_when_it_computes():
    # SNAPMEM_COLD=compile: with an empty numba cache the kernels would run as Python (test_startup_cold.py)
    loaded = loaded_after("import snapmem\nsnapmem.equilibrium(snapmem.build_scene('balloon', nodes=11, "
                          "pressure=0.005))", SNAPMEM_COLD="compile").split()
    assert "numba" in loaded and "scipy.linalg" not in loaded and "scipy.optimize" not in loaded


def test_lazy_kernels_compile_on_first_call_and_call_each_other():
    from snapmem import _lazy

    @_lazy.njit(cache=False)
    def square(x):
        return x * x

    @_lazy.njit(cache=False)
    def sum_of_squares(a):
        total = 0.0
        for v in a:
            total += square(v)
        return total

    assert isinstance(sum_of_squares, _lazy.Kernel) and sum_of_squares.signatures == []
    assert sum_of_squares(np.arange(4.0)) == 14.0
    assert sum_of_squares.py_func(np.arange(4.0)) == 14.0
    assert len(sum_of_squares.signatures) == 1
    assert {"sum_of_squares", "square"} <= {k.__name__ for k in _lazy.materialized()}
    assert type(square).__name__ == "CPUDispatcher"          # the callee, rebound for numba to type it


def test_a_trace_imports_neither_scipy_optimize_nor_scipy_linalg():
    # brentq is snapmem.kernels.roots' (scipy's, transcribed); numba gets scipy's BLAS table alone
    loaded = loaded_after("from snapmem.cli import main\nwith contextlib.redirect_stdout(io.StringIO()):\n"
                          "    main(['trace', 'balloon', '--set', 'nodes=21', '--until', 'stretch_max=2'])",
                          SNAPMEM_COLD="compile").split()
    assert "numba" in loaded and "scipy.optimize" not in loaded and "scipy.linalg" not in loaded
