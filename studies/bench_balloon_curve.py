"""Benchmark: the whole balloon curve (N = 101, stretch 1 to 4, stability at every point, the limit
point located) for the paper's four E_hat: median wall time of repeated runs (snapmem.bench),
with steps, Newton iterations and the located limit pressure against the exact one.

    python studies/bench_balloon_curve.py [--repeats 15] [--out results/bench_balloon_curve.csv]
"""

import argparse

import pandas as pd

from snapmem import exact
from snapmem.bench import balloon_curve
from snapmem.io.results import write_table


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=15)
    parser.add_argument("--nodes", type=int, default=101)
    parser.add_argument("--quick", action="store_true", help="3 repeats")
    parser.add_argument("--out", default="results/bench_balloon_curve.csv")
    args = parser.parse_args(argv)
    repeats = 3 if args.quick else args.repeats
    rows = []
    for E_hat in (0.0, 0.1538, 0.2308, 0.3077):
        row = {"E_hat": E_hat, "nodes": args.nodes, **balloon_curve(args.nodes, repeats, E_hat)}
        row["p_limit_rel_error"] = row["p_limit"] / exact.balloon_limit_point(E_hat=E_hat)[1] - 1
        rows.append(row)
    table = pd.DataFrame(rows)
    write_table(table, args.out, {"study": "bench_balloon_curve", "repeats": repeats})
    with pd.option_context("display.width", 200, "display.float_format", "{:.4g}".format):
        print(table.to_string(index=False))
    return table


if __name__ == "__main__":
    main()
