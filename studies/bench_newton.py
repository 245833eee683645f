"""Benchmark: one Newton iteration against the banded LAPACK solve of the same matrix alone.

A Newton iteration is what snapmem.newton.newton does per iteration: one assembly (energy
gradient and banded K at the trial point), one band LU factorisation and one solve. The floor
is LAPACK's dgbsv on the same band matrix (a copy made outside the timing). Both are timed in
the same run as medians of repeated calls, and reported as a ratio.

    python studies/bench_newton.py [--quick] [--out results/bench_newton.csv]
"""

from __future__ import annotations

import argparse
import time

import numpy as np
import pandas as pd
from scipy.linalg.lapack import dgbsv

from snapmem import build_scene
from snapmem.results import write_table


def interleaved_medians(fns, min_time=0.3, min_repeats=7):
    """Median wall time of each function, timed alternately so that load from other processes
    on this shared machine affects every one of them alike."""
    times = [[] for _ in fns]
    start = time.perf_counter()
    while len(times[0]) < min_repeats or (time.perf_counter() - start < min_time and len(times[0]) < 2000):
        for fn, ts in zip(fns, times):
            t0 = time.perf_counter()
            fn()
            ts.append(time.perf_counter() - t0)
    return [float(np.median(ts)) for ts in times]


def newton_iteration_vs_solve(nodes: int, scene_name: str = "balloon") -> dict:
    scene = build_scene(scene_name, nodes=nodes, pressure=0.01)
    rng = np.random.default_rng(0)
    q = scene.reference_state() * 1.2
    q[scene.free] += rng.normal(scale=1e-3, size=scene.n_free)
    loads = scene.resolve_loads(None)

    def iteration():
        ev = scene.evaluate(q, loads, order=2)
        lu = ev.stiffness.lu()
        return lu.solve(-ev.residual)

    K = scene.evaluate(q, loads).stiffness
    b = K.b
    ab = np.array(K.ab, order="F")
    rhs = rng.normal(size=K.n)

    def bare_solve():
        return dgbsv(b, b, ab, rhs)      # copies ab (overwrite_ab=0): the solve alone, inputs intact

    t_iter, t_solve = interleaved_medians([iteration, bare_solve])
    return {"scene": scene_name, "nodes": nodes, "dofs": scene.n_free, "bandwidth": b,
            "iteration_s": t_iter, "solve_s": t_solve, "ratio": t_iter / t_solve,
            "iteration_us_per_dof": 1e6 * t_iter / scene.n_free}


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="N = 101 and 1001 only")
    parser.add_argument("--out", default="results/bench_newton.csv")
    args = parser.parse_args(argv)
    sizes = [101, 1001] if args.quick else [101, 1001, 10001, 100001]
    rows = [newton_iteration_vs_solve(n, s) for s in ("balloon", "torus") for n in sizes]
    table = pd.DataFrame(rows)
    write_table(table, args.out, {"study": "bench_newton", "sizes": sizes})
    with pd.option_context("display.width", 160, "display.float_format", "{:.4g}".format):
        print(table.to_string(index=False))
    return table


if __name__ == "__main__":
    main()
