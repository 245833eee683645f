"""Benchmark: the whole balloon curve (N = 101, stretch 1 to 4, stability at every point, the limit
point located), median wall time of repeated runs, with steps and Newton iterations.

    python studies/bench_balloon_curve.py [--repeats 15] [--out results/bench_balloon_curve.csv]
"""

from __future__ import annotations

import argparse
import time

import numpy as np
import pandas as pd

from snapmem import build_scene, exact
from snapmem.continuation import trace
from snapmem.results import write_table


def run_once(nodes: int, E_hat: float):
    scene = build_scene("balloon", nodes=nodes, E_hat=E_hat)
    t0 = time.perf_counter()
    branch = trace(scene, "pressure", until={"stretch": 4.0})
    return time.perf_counter() - t0, branch


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=15)
    parser.add_argument("--nodes", type=int, default=101)
    parser.add_argument("--quick", action="store_true", help="3 repeats")
    parser.add_argument("--out", default="results/bench_balloon_curve.csv")
    args = parser.parse_args(argv)
    repeats = 3 if args.quick else args.repeats
    run_once(args.nodes, 0.0)                       # warm-up: imports, numba cache
    rows = []
    for E_hat in (0.0, 0.1538, 0.2308, 0.3077):
        times = []
        for _ in range(repeats):
            t, branch = run_once(args.nodes, E_hat)
            times.append(t)
        lp = branch.limit_points().iloc[0]
        _, p_exact = exact.balloon_limit_point(E_hat=E_hat)
        rows.append({"E_hat": E_hat, "nodes": args.nodes, "median_s": float(np.median(times)),
                     "min_s": float(np.min(times)), "points": len(branch.table), "steps": branch.stats["steps"],
                     "rejected": branch.stats["rejected"], "newton_iterations": branch.stats["newton_iterations"],
                     "assemblies": branch.stats["evaluations"], "p_limit": float(lp["pressure"]),
                     "p_limit_rel_error": float(lp["pressure"] / p_exact - 1)})
    table = pd.DataFrame(rows)
    write_table(table, args.out, {"study": "bench_balloon_curve", "repeats": repeats})
    with pd.option_context("display.width", 200, "display.float_format", "{:.4g}".format):
        print(table.to_string(index=False))
    return table


if __name__ == "__main__":
    main()
