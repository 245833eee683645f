"""Benchmarks against the floor of the machine and on whole jobs (snapmem.bench), one run:
results/benchmark.csv and a table on stdout. The same as `snapmem bench`.

    python studies/benchmark.py [--quick] [--out results/benchmark.csv]
"""

import argparse

import pandas as pd

from snapmem.bench import run
from snapmem.io.results import write_table


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true")
    parser.add_argument("--out", default="results/benchmark.csv")
    args = parser.parse_args(argv)
    table = run(quick=args.quick)
    write_table(table, args.out, {"study": "benchmark", "quick": args.quick})
    with pd.option_context("display.width", 220, "display.max_colwidth", 90):
        print(table.to_string(index=False, float_format=lambda v: f"{v:.4g}"))
    return table


if __name__ == "__main__":
    main()
