"""Benchmark: real-time factor of every robotic scene and of torus_snap at converged accuracy.

Each scene runs at its default tolerance and at 4x tighter; the run counts as converged when its
events (snap times, ball impact/bounce/rebound and launch/apex, torus radius:
snapmem.catalog.robots.events) agree with the tighter run within 1%. torus_snap's final outer radius is
also compared with a mesh-converged one (2x and 4x the nodes, Richardson). Real-time factor = simulated time / wall time (median of --repeats runs); also on the
process's CPU time, which a busy shared machine disturbs less.

    python studies/bench_robots.py [--quick] [--repeats 3] [--out results/bench_robots.csv]
"""

from __future__ import annotations

import argparse
import dataclasses
import time

import numpy as np
import pandas as pd

from snapmem.dynamics.driver import simulate
from snapmem.io.results import write_table
from snapmem.catalog.robots import ROBOTIC_SCENES, events, experiment

QUICK = {"nodes": 21}


def timed(name, tol_factor, t_end, params, tol=None):
    ex = experiment(name, **params)
    options = dataclasses.replace(ex.options, tol=(tol or ex.options.tol) * tol_factor)
    t0, c0 = time.perf_counter(), time.process_time()
    traj = simulate(ex.scene, ex.loads, t_end or ex.t_end, rho=ex.rho, damping=ex.damping, q0=ex.q0, v0=ex.v0,
                    options=options, damp_bodies=ex.damp_bodies)
    return time.perf_counter() - t0, time.process_time() - c0, traj, options.tol


def mesh_convergence(name, ev):
    """torus_snap's final outer radius against a mesh-converged one: runs at 2x and 4x the nodes,
    Richardson-extrapolated at order 2 (the measured N : 2N : 4N differences fall by 4.0)."""
    nodes = experiment(name).scene.meridian.nodes
    radii = [events(timed(name, 1.0, None, {"nodes": k * nodes})[2])["outer_radius"] for k in (2, 4)]
    limit = radii[1] + (radii[1] - radii[0]) / 3.0
    return {"outer_radius_2N": radii[0], "outer_radius_4N": radii[1], "outer_radius_extrapolated": limit,
            "outer_radius_rel_error": abs(ev["outer_radius"] - limit) / limit}


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="21 nodes, short runs, one repeat")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--scenes", nargs="*", default=list(ROBOTIC_SCENES) + ["torus_snap"])
    parser.add_argument("--tol", type=float, help="local error tolerance of every scene (default: each scene's)")
    parser.add_argument("--out", default="results/bench_robots.csv")
    args = parser.parse_args(argv)
    params = QUICK if args.quick else {}
    repeats = 1 if args.quick else args.repeats
    rows = []
    for name in args.scenes:
        t_end = 1.0 if args.quick and name != "torus_snap" else None
        walls, cpus, traj, tol = zip(*[timed(name, 1.0, t_end, params, args.tol) for _ in range(repeats)])
        _, _, tight, tight_tol = timed(name, 0.25, t_end, params, args.tol)
        ev, ev_tight = events(traj[-1]), events(tight)
        worst = max(abs(ev[k] - ev_tight[k]) / max(abs(ev_tight[k]), 1e-12) for k in ev)
        meta = traj[-1].meta
        wall, cpu = float(np.median(walls)), float(np.median(cpus))
        mesh = mesh_convergence(name, ev) if name == "torus_snap" and not args.quick else {}
        rows.append({"scene": name, "nodes": meta["nodes"], "scheme": meta["scheme"], "tol": tol[-1],
                     "status": meta["status"], "t_end": meta["t_end"], "wall_s": wall,
                     "real_time_factor": meta["t_end"] / wall, "cpu_s": cpu,
                     "real_time_factor_cpu": meta["t_end"] / cpu, "steps": meta["steps"], "rejected": meta["rejected"],
                     "newton_iterations": meta["newton_iterations"], "min_gap": float(np.min(traj[-1]["min_gap"])),
                     "events_rel_diff_4x_tighter": worst, "converged_1pct": bool(worst < 0.01),
                     **{f"event_{k}": v for k, v in ev.items()}, **mesh})
        if mesh:
            print(f"{name}: final outer radius {ev['outer_radius']:.5g}, {mesh['outer_radius_rel_error']:.3%} from the "
                  f"mesh-converged {mesh['outer_radius_extrapolated']:.5g}", flush=True)
        print(f"{name}: {rows[-1]['real_time_factor']:.3g}x real time ({meta['t_end'] / cpu:.3g}x on CPU time), {wall:.3g} s, "
              f"{meta['newton_iterations']} Newton iterations, events within {worst:.2%} of 4x tighter", flush=True)
    table = pd.DataFrame(rows)
    write_table(table, args.out, {"study": "bench_robots", "repeats": repeats, "quick": args.quick})
    with pd.option_context("display.width", 250, "display.float_format", "{:.4g}".format):
        print(table.drop(columns=[c for c in table.columns if c.startswith("event_")]).to_string(index=False))
    return table


if __name__ == "__main__":
    main()
