"""Speed of the robot scenes with a viscoelastic membrane (issue 15): real-time factor (simulated
time / wall time) of every robot scene, elastic and with one neo-Hookean network, on the general
step (the Python Newton on the scene's assembly, as viscous scenes ran before) and on the compiled step, measured in one run, with the accuracy check of each
viscous run: its events (snapmem.catalog.robots.events) against a run at a 4x tighter tolerance.

The network: ``viscous_mu`` = mu / 4 (mu the scene's shear modulus) and ``relaxation_time`` =
t_end / 10, a time inside the run. Each timing is the median of ``--repeats`` runs (after one
untimed run that loads the compiled kernels), elastic and compiled viscous runs interleaved; the
general step is timed once (it is the slow one).

With ``--before TREE`` (a source tree of an earlier snapmem, e.g. ``git archive <commit>``
unpacked) the same runs are timed on that tree too, in a worker process (this script with
``--worker`` on that tree's snapmem), interleaved with this tree's: every repetition runs elastic
and viscous here, then elastic and viscous there, so the machine's load falls on both alike. The
table gives the load average (1 min) at each scene's start and end: the machine is shared.

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


def timed(name, repeats, tol_factor=1.0, **params):
    """(median wall time [s], the last trajectory) of ``repeats`` runs of scene ``name``."""
    ex = experiment(name, **params)
    options = ex.options if tol_factor == 1.0 else ex.options.__class__(
        **{**ex.options.__dict__, "tol": ex.options.tol * tol_factor})
    walls, traj = [], None
    for _ in range(repeats):
        wall = time.perf_counter()
        traj = simulate(ex.scene, ex.loads, ex.t_end, rho=ex.rho, damping=ex.damping, q0=ex.q0, v0=ex.v0,
                        options=options, damp_bodies=ex.damp_bodies)
        walls.append(time.perf_counter() - wall)
    return float(np.median(walls)), traj


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


class Before:
    """The timings of an earlier tree: this script as a worker (``--worker``) on that tree's snapmem,
    asked for one run at a time."""

    def __init__(self, tree: str):
        env = {**os.environ, "PYTHONPATH": os.path.abspath(tree)}
        self.process = subprocess.Popen([sys.executable, os.path.abspath(__file__), "--worker"], env=env,
                                        stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)

    def wall(self, name: str, viscous: bool) -> float:
        """Wall time [s] of one run of scene ``name`` (viscous: with :func:`viscous_parameters`) there."""
        self.process.stdin.write(json.dumps({"scene": name, "viscous": viscous}) + "\n")
        self.process.stdin.flush()
        return float(json.loads(self.process.stdout.readline())["wall"])

    def close(self):
        self.process.stdin.close()
        self.process.wait()


def worker():
    """Answer ``Before.wall`` requests (one JSON line each) on this process's snapmem until stdin ends."""
    for line in sys.stdin:
        request = json.loads(line)
        params = viscous_parameters(request["scene"]) if request["viscous"] else {}
        print(json.dumps({"wall": timed(request["scene"], 1, **params)[0]}), flush=True)


def measure(name: str, repeats: int, before: Before | None = None) -> dict:
    t_end = experiment(name).t_end
    visco = viscous_parameters(name)
    load_start = os.getloadavg()[0]
    timed(name, 1)                                     # load the compiled kernels
    timed(name, 1, **visco)
    if before is not None:
        before.wall(name, False)
        before.wall(name, True)
    elastic_walls, compiled_walls, before_walls = [], [], ([], [])
    for _ in range(repeats):                          # interleaved: the machine's load falls on all alike
        elastic_walls.append(timed(name, 1)[0])
        wall, traj = timed(name, 1, **visco)
        compiled_walls.append(wall)
        if before is not None:
            before_walls[0].append(before.wall(name, False))
            before_walls[1].append(before.wall(name, True))
    elastic, compiled = float(np.median(elastic_walls)), float(np.median(compiled_walls))
    with general_path():
        numpy_wall, _ = timed(name, 1, **visco)
    _, tight = timed(name, 1, tol_factor=0.25, **visco)
    row = {"scene": name, "t_end_s": t_end, **visco,
           "rtf_elastic": t_end / elastic, "rtf_viscous_general": t_end / numpy_wall,
           "rtf_viscous_compiled": t_end / compiled, "steps_viscous": traj.meta["steps"],
           "newton_viscous": traj.meta["newton_iterations"],
           "event_error_vs_4x_tighter": event_error(traj, tight), "status": traj.meta["status"]}
    if before is not None:
        row.update(rtf_elastic_before=t_end / float(np.median(before_walls[0])),
                   rtf_viscous_compiled_before=t_end / float(np.median(before_walls[1])))
    row.update(load_start=load_start, load_end=os.getloadavg()[0])
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
    before = None if args.before is None else Before(args.before)
    rows = []
    try:
        for name in args.scenes.split(","):
            rows.append(measure(name, args.repeats, before))
            print(pd.DataFrame(rows[-1:]).to_string(index=False), flush=True)
    finally:
        if before is not None:
            before.close()
    table = pd.DataFrame(rows)
    table.to_csv(args.out, index=False)
    print(table.to_string(index=False))


if __name__ == "__main__":
    main()
