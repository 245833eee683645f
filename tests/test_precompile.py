"""The compiled time step's first compile in two processes (snapmem.dynamics.precompile): the
signatures it compiles ahead are the ones time_step types its callees with, and the numbers of a
simulation compiled that way are those of one compiled in one process, bit for bit.

Both compile the time step from an empty numba cache in a subprocess (tens of seconds): slow."""

import json
import os
import subprocess
import sys
import textwrap

import numpy as np
import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

#: Runs short simulations of three scenes that between them take every branch of
#: callee_signatures (no contact; linear contacts; a ball body with viscous networks) in one
#: process, compiling serially, and prints, for every planned signature, whether that kernel
#: compiled it (and which signatures it compiled).
PLANNED = textwrap.dedent("""
    import json
    import snapmem.dynamics.compiled_step as cs
    from snapmem.catalog.robots import experiment
    from snapmem.dynamics.driver import simulate
    from snapmem.dynamics.precompile import _kernel, callee_signatures
    seen = []
    entry_point = cs._entry_point
    def record(kernel, args):
        seen.append(args)
        return entry_point(kernel, args)
    cs._entry_point = record
    report = []
    for name, params in [("torus_snap", {}), ("gripper_rod", {}),
                         ("ball_drop", {"viscous_mu": 26406.25, "relaxation_time": 0.05})]:
        ex = experiment(name, **params)
        simulate(ex.scene, ex.loads, ex.t_end / 50, rho=ex.rho, damping=ex.damping, q0=ex.q0, v0=ex.v0,
                 options=ex.options, damp_bodies=ex.damp_bodies)
        for args in seen:
            other, here = callee_signatures(args)
            for module, kernel_name, signature in other + here:
                kernel = _kernel(module, kernel_name)
                compiled = [tuple(s) for s in getattr(kernel, "signatures", [])]
                report.append([name, kernel_name, tuple(signature) in compiled, str(signature),
                               [str(s) for s in compiled]])
        seen.clear()
    print(json.dumps(report))
""")


def _cold_environment(tmp_path, **extra) -> dict:
    return dict(os.environ, PYTHONPATH=ROOT, NUMBA_CACHE_DIR=str(tmp_path), SNAPMEM_COLD="compile",
                SNAPMEM_BACKGROUND_COMPILE="0", **extra)


@pytest.mark.slow
def test_the_signatures_compiled_ahead_are_those_time_step_compiles(tmp_path):
    done = subprocess.run([sys.executable, "-c", PLANNED], capture_output=True, text=True, timeout=900,
                          env=_cold_environment(tmp_path, SNAPMEM_PARALLEL_COMPILE="0"))
    assert done.returncode == 0, done.stderr[-3000:]
    report = json.loads(done.stdout.strip().splitlines()[-1])
    assert {row[0] for row in report} == {"torus_snap", "gripper_rod", "ball_drop"}
    missed = [row for row in report if not row[2]]
    assert not missed, missed


#: ``snapmem simulate`` in this process, printing the kernels it compiled itself (numba's events).
SIMULATE = textwrap.dedent("""
    import json, sys
    from numba.core import event
    compiled = []
    class Listener(event.Listener):
        def on_start(self, ev):
            compiled.append(ev.data["dispatcher"].py_func.__qualname__)
        def on_end(self, ev):
            pass
    event.register("numba:compile", Listener())
    from snapmem.cli import main
    try:
        main(sys.argv[1:])
    except SystemExit:
        pass
    print(json.dumps(compiled))
""")


@pytest.mark.slow
def test_a_first_simulate_compiled_in_two_processes_gives_the_numbers_of_one(tmp_path):
    runs, compiled = {}, {}
    for way in ("0", "1"):
        out = tmp_path / f"run{way}.npz"
        done = subprocess.run([sys.executable, "-c", SIMULATE, "simulate", "torus_snap", "--set", "t_end=20",
                               "--out", str(out)], capture_output=True, text=True, timeout=900,
                              env=_cold_environment(tmp_path / f"cache{way}", SNAPMEM_PARALLEL_COMPILE=way))
        assert done.returncode == 0, done.stderr[-3000:]
        runs[way] = np.load(out)
        compiled[way] = json.loads(done.stdout.strip().splitlines()[-1])
    # one process compiled the assembly itself; with two, the other did (this one loaded it)
    assert "assemble" in compiled["0"] and "time_step" in compiled["0"]
    assert "assemble" not in compiled["1"] and "time_step" in compiled["1"]
    serial, parallel = runs["0"], runs["1"]
    arrays = [k for k in serial.files if k != "meta"]
    assert arrays and arrays == [k for k in parallel.files if k != "meta"]
    for key in arrays:
        assert np.array_equal(serial[key], parallel[key], equal_nan=True), key
