"""First use with an empty numba cache (snapmem._lazy, docs/performance.md "First use").

A cached kernel that is not in the cache runs as Python: the same code, so the same numbers as the
compiled kernel, bit for bit. These tests run a trace both ways and compare every number; check
that such a process imports no numba; that the background compile makes the kernels a later
process loads; and that the Brent iteration and the scipy.linalg shortcut behave as scipy's own.
"""

import json
import math
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]

TRACE = """
import json, sys
import numpy as np
import snapmem._lazy as lazy
from snapmem import build_scene
from snapmem.continuation import trace
out = {{}}
for name, params, control, until in {cases!r}:
    loads = ("voltage",) if control == "E_hat" else ()
    branch = trace(build_scene(name, loads, **params), control, until=until)
    table = branch.table.select_dtypes("number")
    out[name + str(params)] = {{"table": table.to_numpy(float).tolist(), "columns": list(table.columns),
                 "points": branch.points.select_dtypes("number").to_numpy(float).tolist(),
                 "states": [np.asarray(p.x).tolist() for p in branch.states]}}
out["interpreted"] = lazy.interpreted()
out["numba"] = "numba" in sys.modules
print("@json" + json.dumps(out))
"""

#: A linear-in-invariants law (the balloon), Gent (a logarithm), a voltage-controlled torus.
CASES = [("balloon", {"nodes": 31}, "pressure", {"stretch_max": 3.0}),
         ("balloon", {"nodes": 21, "material": "gent"}, "pressure", {"stretch_max": 2.0}),
         ("torus", {"nodes": 21}, "E_hat", {"stretch_max": 1.2})]


def first_use_environment(**environment) -> dict:
    """This process's environment without conftest's SNAPMEM_COLD=compile: first-use policy as a user has it."""
    env = {k: v for k, v in os.environ.items() if k != "SNAPMEM_COLD"}
    env.update(PYTHONPATH=str(ROOT), **environment)
    return env


def run_trace(cases, cold: bool, **environment) -> dict:
    env = first_use_environment(SNAPMEM_BACKGROUND_COMPILE="0", **environment)
    with tempfile.TemporaryDirectory() as cache:
        if cold:
            env["NUMBA_CACHE_DIR"] = cache
        done = subprocess.run([sys.executable, "-c", TRACE.format(cases=cases)], capture_output=True, text=True,
                              env=env, cwd=ROOT, timeout=600)
    assert done.returncode == 0, done.stderr[-3000:]
    return json.loads(done.stdout.rsplit("@json", 1)[1])


def test_kernels_run_as_python_when_uncached_and_give_the_compiled_numbers_bit_for_bit():
    cases = CASES
    cold = run_trace(cases, cold=True)
    compiled = run_trace(cases, cold=False, SNAPMEM_COLD="compile")
    assert not cold["numba"], "a cold trace should not import numba"
    assert {"snapmem.kernels.linalg.band_ldlt", "snapmem.kernels.assembly.edge_assembly"} <= set(cold["interpreted"])
    assert compiled["interpreted"] == [] and compiled["numba"]
    for name, params, *_ in cases:
        a, b = cold[name + str(params)], compiled[name + str(params)]
        assert a["columns"] == b["columns"]
        # NaN == NaN here: compare the bit patterns
        for key in ("table", "points"):
            assert np.array_equal(np.array(a[key]), np.array(b[key]), equal_nan=True), (name, key)
        assert len(a["states"]) == len(b["states"])
        for x, y in zip(a["states"], b["states"]):
            assert np.array_equal(np.array(x), np.array(y)), name


def test_an_uncached_kernel_runs_as_python_until_the_budget_then_compiles(tmp_path, monkeypatch):
    pytest.importorskip("numba")
    from snapmem import _lazy
    (tmp_path / "budget_kernels.py").write_text(
        "from snapmem._lazy import njit\n\n\n@njit(cache=True)\ndef halve(x):\n    return 0.5 * x\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.setenv("SNAPMEM_BACKGROUND_COMPILE", "0")
    monkeypatch.setattr(_lazy, "_spent", [0.0])
    monkeypatch.setattr(_lazy, "_seen", {})
    monkeypatch.setitem(_lazy._policy, "compile", False)
    import budget_kernels
    kernel = budget_kernels.halve
    assert not _lazy._in_cache(kernel)
    assert kernel(3.0) == 1.5 and kernel._dispatcher is None
    assert _lazy.interpreted() == ["budget_kernels.halve"]
    assert _lazy._seen[("budget_kernels", "halve")] == {(("s", "builtins", "float"),)}
    monkeypatch.setattr(_lazy, "INTERPRET_BUDGET", 0.0)       # spent: the next call compiles
    assert kernel(3.0) == 1.5 and kernel._dispatcher is not None and kernel.signatures
    assert _lazy._in_cache(kernel)                            # numba wrote its index beside the module
    monkeypatch.delitem(sys.modules, "budget_kernels")


def test_argument_descriptions_rebuild_values_of_the_same_numba_type():
    numba = pytest.importorskip("numba")
    from snapmem import _lazy
    values = [np.zeros(4), np.zeros((3, 2), dtype=np.int64), np.zeros((4, 4), order="F"), np.zeros((5, 4))[::2],
              np.arange(3.0)[::-1], 1.5, 3, True, np.float64(2.0), None, (np.zeros(2), 1.0)]
    frozen = np.zeros(3)
    frozen.flags.writeable = False
    values.append(frozen)
    for value in values:
        description = _lazy._describe(value)
        again = _lazy._tupled(json.loads(json.dumps(_lazy._plain(description))))
        assert numba.typeof(_lazy._example(again)) == numba.typeof(value), value


@pytest.mark.slow
def test_the_background_compile_fills_the_cache_for_the_next_process():
    env = first_use_environment()
    code = ("import sys\nfrom snapmem import build_scene\nfrom snapmem.continuation import trace\n"
            "import snapmem._lazy as lazy\n"
            "trace(build_scene('balloon', nodes=21), 'pressure', until={'stretch_max': 2.0})\n"
            "print(len(lazy.interpreted()), 'numba' in sys.modules)")
    with tempfile.TemporaryDirectory() as cache:
        env.update(NUMBA_CACHE_DIR=cache, SNAPMEM_BACKGROUND_COMPILE="0")
        first = subprocess.run([sys.executable, "-c", code + "\nimport json, os\n"
                                "jobs = [[m, n, [list(map(lazy._plain, d)) for d in ds]] for (m, n), ds in lazy._seen.items()]\n"
                                "json.dump(jobs, open(os.path.join(os.environ['NUMBA_CACHE_DIR'], 'jobs.json'), 'w'))"],
                               capture_output=True, text=True, env=env, cwd=ROOT, timeout=600)
        assert first.returncode == 0, first.stderr[-2000:]
        assert first.stdout.split()[1] == "False"
        compiling = subprocess.run([sys.executable, "-c", "import sys; from snapmem._lazy import compile_jobs; "
                                    "compile_jobs(sys.argv[1])", os.path.join(cache, "jobs.json")],
                                   capture_output=True, text=True, env=env, cwd=ROOT, timeout=900)
        assert compiling.returncode == 0, compiling.stderr[-2000:]
        second = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, cwd=ROOT,
                                timeout=600)
        assert second.returncode == 0, second.stderr[-2000:]
        assert second.stdout.split() == ["0", "True"]          # all loaded from the cache, none as Python


def test_brentq_is_scipys_bit_for_bit():
    from scipy.optimize import brentq as scipy_brentq
    from snapmem.kernels.roots import brentq
    rng = np.random.default_rng(7)
    functions = [lambda x, c: np.polyval(c, x), lambda x, c: math.tanh(c[0] * (x - c[1])) + 0.3 * c[2],
                 lambda x, c: math.exp(c[0] * x) - 1.5 - c[1] ** 2, lambda x, c: (x - c[0]) ** 3 * 1e-8,
                 lambda x, c: math.sin(5 * x + c[0])]
    for k in range(600):
        c = rng.normal(size=5)
        a, b = sorted(rng.uniform(-3, 3, 2))
        for options in ({}, {"xtol": 1e-13 * (b - a), "rtol": 4 * np.finfo(float).eps, "maxiter": 60}, {"maxiter": 4}):
            outcomes = []
            for solver in (scipy_brentq, brentq):
                calls = []

                def f(x):
                    calls.append(x)
                    return functions[k % len(functions)](x, c)
                try:
                    outcomes.append((solver(f, a, b, **options), None, calls))
                except (ValueError, RuntimeError) as error:
                    outcomes.append((None, type(error), calls))
            assert outcomes[0] == outcomes[1], (k, options)


def test_brentq_rejects_what_scipy_rejects():
    from snapmem.kernels.roots import brentq
    with pytest.raises(ValueError, match="different signs"):
        brentq(lambda x: x * x + 1.0, -1.0, 1.0)
    with pytest.raises(ValueError, match="xtol"):
        brentq(lambda x: x, -1.0, 1.0, xtol=0.0)
    with pytest.raises(ValueError, match="NaN"):
        brentq(lambda x: math.nan if x > 0 else -1.0, -1.0, 1.0)
    assert brentq(lambda x: x - 0.25, 0.0, 1.0) == pytest.approx(0.25, abs=2e-12)


def test_numba_loads_without_importing_all_of_scipy_linalg_which_later_imports_whole():
    code = ("import sys\nimport snapmem\n"
            "snapmem.equilibrium(snapmem.build_scene('balloon', nodes=11, pressure=0.005))\n"
            "print('scipy.linalg' in sys.modules, 'scipy.linalg.cython_blas' in sys.modules)\n"
            "import numba.np.arraymath, numpy as np, scipy.linalg\n"
            "print(numba.np.arraymath._HAVE_BLAS, scipy.linalg.cython_blas is sys.modules['scipy.linalg.cython_blas'],"
            " float(scipy.linalg.eigh(np.diag([2.0, 1.0]))[0][0]))")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, timeout=600,
                          env=dict(os.environ, PYTHONPATH=str(ROOT), SNAPMEM_COLD="compile"))
    assert done.returncode == 0, done.stderr[-2000:]
    assert done.stdout.split() == ["False", "True", "True", "True", "1.0"]
