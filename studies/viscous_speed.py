"""Speed of the robot scenes with a viscoelastic membrane (issue 15): real-time factor (simulated
time / wall time) of every robot scene, elastic and with one neo-Hookean network, on the general
step (the Python Newton on the scene's assembly, as viscous scenes ran before) and on the compiled step, measured in one run, with the accuracy check of each
viscous run: its events (snapmem.catalog.robots.events) against a run at a 4x tighter tolerance.

The network: ``viscous_mu`` = mu / 4 (mu the scene's shear modulus) and ``relaxation_time`` =
t_end / 10, a time inside the run. Each timing is the median of ``--repeats`` runs (after one
untimed run that loads the compiled kernels), elastic and compiled viscous runs interleaved; the
general step is timed once (it is the slow one).

With ``--before TREE`` (a source tree of an earlier snapmem, e.g. ``git archive <commit>``
unpacked) the same runs are timed on that tree too, interleaved with this tree's, each tree in a worker
process (this script with ``--worker`` on the tree's snapmem): every repetition runs elastic and
viscous on this tree, then elastic and viscous on that one, so the machine's load falls on both
alike. Real-time factors come from the median wall time (``rtf_*``) and the median CPU time of
the process (``rtf_*_cpu``: without the time it waited for a core, steadier on a shared machine). The
table gives the load average (1 min) at each scene's start and end: the machine is shared; and
``reference_ms``, the median time of :func:`reference_loop` (a fixed pure-Python loop) run by the
process that timed, right after each of this tree's viscous runs: the machine's own state during
them (about 7 ms fast, 11-12 ms slow; it changes within seconds), so that runs of different
moments compare.

Writes results/viscous_speed.csv.

    PYTHONPATH=$PWD python studies/viscous_speed.py [--repeats 5] [--before /tmp/before_tree]
"""

import argparse
import json
import os
import subprocess
import sys
import time
from contextlib import contextmanager

import numpy as np
import pandas as pd

#: Timings are of compiled kernels: one not in numba's cache yet (after a change) compiles at its
#: first call here instead of running as Python (snapmem._lazy's first-use policy), also in the
#: worker processes, which inherit the environment.
os.environ.setdefault("SNAPMEM_COLD", "compile")

from snapmem.catalog.robots import events, experiment
from snapmem.dynamics.compiled_step import CompiledStep
from snapmem.dynamics.driver import simulate

SCENES = ("pump", "gripper_rod", "gripper_shell", "ball_drop", "ball_throw", "torus_snap")
ACCURACY = 0.01          # events within 1% of the 4x tighter run


@contextmanager
def general_path():
    """The time step without the compiled solve (as viscous scenes ran before the compiled step covered
    them): Newton in Python on the scene's assembly, whose kernels stay compiled."""
    of = CompiledStep.of
    CompiledStep.of = classmethod(lambda cls, scene: None)
    try:
        yield
    finally:
        CompiledStep.of = of


def viscous_parameters(name: str) -> dict:
    ex = experiment(name)
    mu = float(ex.scene.density_terms[0].law.mu)
    return {"viscous_mu": 0.25 * mu, "relaxation_time": 0.1 * ex.t_end}


def timed(name, tol_factor=1.0, **params):
    """(wall time [s], the process's CPU time [s], the trajectory) of one run of scene ``name``.

    The CPU time leaves out the time the process waited for a core: on the shared machine it is
    the steadier measure (the wall time is what the must-show's real-time factor means)."""
    ex = experiment(name, **params)
    options = ex.options if tol_factor == 1.0 else ex.options.__class__(
        **{**ex.options.__dict__, "tol": ex.options.tol * tol_factor})
    wall, cpu = time.perf_counter(), time.process_time()
    traj = simulate(ex.scene, ex.loads, ex.t_end, rho=ex.rho, damping=ex.damping, q0=ex.q0, v0=ex.v0,
                    options=options, damp_bodies=ex.damp_bodies)
    return time.perf_counter() - wall, time.process_time() - cpu, traj


def reference_loop() -> float:
    """Time [s] of a fixed pure-Python loop that no snapmem code enters: how fast the machine runs
    at this moment. The project's shared 2-core machine has a fast state (about 7 ms here) and a
    slow one (11-12 ms) that comes for seconds to hours, and every timing slows with it. Taken
    right after a timed run, in its process (a core idle before it reads slow as it wakes)."""
    start = time.perf_counter()
    total = 0.0
    for i in range(200_000):
        total += i * 0.5
    return time.perf_counter() - start


def event_error(traj, tight) -> float:
    """Largest relative difference of the run's events from the tighter run's (NaN events must agree)."""
    a, b = events(traj), events(tight)
    worst = 0.0
    for key, ref in b.items():
        value = a.get(key, np.nan)
        if np.isnan(ref) or np.isnan(value):
            worst = worst if np.isnan(ref) and np.isnan(value) else np.inf
            continue
        worst = max(worst, abs(value - ref) / max(abs(ref), 1e-12))
    return worst


class Worker:
    """The timings of a source tree: this script as a worker process (``--worker``) on that tree's
    snapmem, asked for one run at a time."""

    def __init__(self, tree: str):
        env = {**os.environ, "PYTHONPATH": os.path.abspath(tree)}
        self.process = subprocess.Popen([sys.executable, os.path.abspath(__file__), "--worker"], env=env,
                                        stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)

    def timed(self, name: str, viscous: bool) -> tuple:
        """(wall, CPU time, :func:`reference_loop` right after) [s] of one run of scene ``name``
        (viscous: with :func:`viscous_parameters`) there."""
        self.process.stdin.write(json.dumps({"scene": name, "viscous": viscous}) + "\n")
        self.process.stdin.flush()
        answer = json.loads(self.process.stdout.readline())
        return float(answer["wall"]), float(answer["cpu"]), float(answer["reference"])

    def close(self):
        self.process.stdin.close()
        self.process.wait()


def worker():
    """Answer ``Worker.timed`` requests (one JSON line each) on this process's snapmem until stdin ends."""
    for line in sys.stdin:
        request = json.loads(line)
        params = viscous_parameters(request["scene"]) if request["viscous"] else {}
        wall, cpu, _ = timed(request["scene"], **params)
        print(json.dumps({"wall": wall, "cpu": cpu, "reference": reference_loop()}), flush=True)


class _Here:
    """This process's timings, asked as a :class:`Worker` is."""

    @staticmethod
    def timed(name: str, viscous: bool) -> tuple:
        return (*timed(name, **(viscous_parameters(name) if viscous else {}))[:2], reference_loop())


def measure(name: str, repeats: int, before: Worker | None = None, here: Worker | None = None) -> dict:
    """The table's row of scene ``name``: this tree's runs in this process (or in ``here``, a worker
    on this tree, so that both trees run in processes alike), ``before``'s interleaved with them."""
    t_end = experiment(name).t_end
    visco = viscous_parameters(name)
    load_start = os.getloadavg()[0]
    here = _Here() if here is None else here
    traj = timed(name, **visco)[2]                    # loads the compiled kernels; its steps and events
    trees = {"": here} if before is None else {"": here, "_before": before}
    for tree in trees.values():
        tree.timed(name, False)
        tree.timed(name, True)
    runs = {f"{kind}{suffix}": [] for suffix in trees for kind in ("elastic", "viscous_compiled")}
    for _ in range(repeats):                          # interleaved: the machine's load falls on all alike
        for suffix, tree in trees.items():
            runs["elastic" + suffix].append(tree.timed(name, False)[:2])
            runs["viscous_compiled" + suffix].append(tree.timed(name, True))
    with general_path():
        numpy_wall = timed(name, **visco)[0]
    tight = timed(name, tol_factor=0.25, **visco)[2]
    factors = {}
    for key, times in runs.items():
        if times:                                     # real-time factors of the median wall and CPU times
            walls, cpus = np.array(times).T[:2]
            factors[f"rtf_{key}"] = t_end / float(np.median(walls))
            factors[f"rtf_{key}_cpu"] = t_end / float(np.median(cpus))
    row = {"scene": name, "t_end_s": t_end, **visco, **factors, "rtf_viscous_general": t_end / numpy_wall,
           "steps_viscous": traj.meta["steps"],
           "newton_viscous": traj.meta["newton_iterations"],
           "event_error_vs_4x_tighter": event_error(traj, tight), "status": traj.meta["status"]}
    reference = float(np.median([run[2] for run in runs["viscous_compiled"]]))   # this tree's runs' process
    row.update(load_start=load_start, load_end=os.getloadavg()[0], reference_ms=1e3 * reference)
    return row


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--scenes", default=",".join(SCENES))
    parser.add_argument("--out", default="results/viscous_speed.csv")
    parser.add_argument("--before", default=None, help="an earlier source tree to time alongside (interleaved)")
    parser.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.worker:
        worker()
        return
    before = here = None
    if args.before is not None:         # both trees in worker processes alike
        before, here = Worker(args.before), Worker(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    rows = []
    try:
        for name in args.scenes.split(","):
            rows.append(measure(name, args.repeats, before, here))
            print(pd.DataFrame(rows[-1:]).to_string(index=False), flush=True)
    finally:
        for worker_process in (before, here):
            if worker_process is not None:
                worker_process.close()
    table = pd.DataFrame(rows)
    table.to_csv(args.out, index=False)
    print(table.to_string(index=False))


if __name__ == "__main__":
    main()
