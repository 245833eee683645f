"""Speed of the robot scenes with a viscoelastic membrane (issue 15): real-time factor (simulated
time / wall time) of every robot scene, elastic and with one neo-Hookean network, on the general
step (the Python Newton on the scene's assembly, as viscous scenes ran before) and on the compiled step, measured in one run, with the accuracy check of each
viscous run: its events (snapmem.catalog.robots.events) against a run at a 4x tighter tolerance.

The network: ``viscous_mu`` = mu / 4 (mu the scene's shear modulus) and ``relaxation_time`` =
t_end / 10, a time inside the run. Each timing is the median of ``--repeats`` runs (after one
untimed run that loads the compiled kernels), elastic and compiled viscous runs interleaved; the
general step is timed once (it is the slow one).

Writes results/viscous_speed.csv.

    PYTHONPATH=$PWD python studies/viscous_speed.py [--repeats 3]
"""

import argparse
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


def measure(name: str, repeats: int) -> dict:
    t_end = experiment(name).t_end
    visco = viscous_parameters(name)
    timed(name, 1)                                     # load the compiled kernels
    timed(name, 1, **visco)
    elastic_walls, compiled_walls = [], []
    for _ in range(repeats):                          # interleaved: the machine's load falls on both alike
        elastic_walls.append(timed(name, 1)[0])
        wall, traj = timed(name, 1, **visco)
        compiled_walls.append(wall)
    elastic, compiled = float(np.median(elastic_walls)), float(np.median(compiled_walls))
    with general_path():
        numpy_wall, _ = timed(name, 1, **visco)
    _, tight = timed(name, 1, tol_factor=0.25, **visco)
    return {"scene": name, "t_end_s": t_end, **visco,
            "rtf_elastic": t_end / elastic, "rtf_viscous_general": t_end / numpy_wall,
            "rtf_viscous_compiled": t_end / compiled, "steps_viscous": traj.meta["steps"],
            "event_error_vs_4x_tighter": event_error(traj, tight), "status": traj.meta["status"]}


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=7)
    parser.add_argument("--scenes", default=",".join(SCENES))
    parser.add_argument("--out", default="results/viscous_speed.csv")
    args = parser.parse_args()
    rows = []
    for name in args.scenes.split(","):
        rows.append(measure(name, args.repeats))
        print(pd.DataFrame(rows[-1:]).to_string(index=False), flush=True)
    table = pd.DataFrame(rows)
    table.to_csv(args.out, index=False)
    print(table.to_string(index=False))


if __name__ == "__main__":
    main()
