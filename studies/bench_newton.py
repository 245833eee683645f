"""Benchmark: one Newton iteration against the banded LAPACK solve of the same matrix alone
(snapmem.bench.newton_floor: interleaved medians in one run, printed as a ratio).

    python studies/bench_newton.py [--quick] [--out results/bench_newton.csv]
"""

import argparse

import pandas as pd

from snapmem.bench import newton_floor
from snapmem.io.results import write_table


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="N = 101 and 1001 only")
    parser.add_argument("--out", default="results/bench_newton.csv")
    args = parser.parse_args(argv)
    sizes = [101, 1001] if args.quick else [101, 1001, 10001, 100001]
    table = pd.DataFrame([newton_floor(n, s) for s in ("balloon", "torus") for n in sizes])
    write_table(table, args.out, {"study": "bench_newton", "sizes": sizes})
    with pd.option_context("display.width", 160, "display.float_format", "{:.4g}".format):
        print(table.to_string(index=False))
    return table


if __name__ == "__main__":
    main()
