"""What every study script shares: its command line, where it writes, and families of branches.

A study script states parameters, calls one driver from here or from the package, writes a CSV
(with a JSON sidecar of its parameters) and draws from that CSV. Nothing else lives in a script.
"""

from __future__ import annotations

import argparse
import logging
import time
from pathlib import Path
from typing import Callable, Iterable

import snapmem._lazy as _lazy

pd = _lazy.module("pandas")  # imported at first use (start-up)

from snapmem.continuation.tracer import ContinuationOptions, trace
from snapmem.io.results import write_table
from snapmem.model.scene import Scene

log = logging.getLogger(__name__)

RESULTS = Path(__file__).resolve().parents[1] / "results"


def parse_args(doc: str, argv=None, extra: Callable[[argparse.ArgumentParser], None] | None = None):
    """``--quick`` (a small setting for tests) and ``--out`` (the results folder)."""
    parser = argparse.ArgumentParser(description=doc.strip().splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="small meshes and few values (for tests)")
    parser.add_argument("--out", default=str(RESULTS), help="folder for CSV and PNG (default: results/)")
    if extra is not None:
        extra(parser)
    args = parser.parse_args(argv)
    args.out = Path(args.out)
    args.out.mkdir(parents=True, exist_ok=True)
    args.started = time.perf_counter()
    return args


def save(args, name: str, table: pd.DataFrame, **meta) -> Path:
    """Write ``table`` to ``<out>/<name>.csv`` with its parameters (and the run time) beside it."""
    path = args.out / f"{name}.csv"
    write_table(table, path, {"study": name, "quick": args.quick,
                              "wall_time_s": round(time.perf_counter() - args.started, 3), **meta})
    return path


def family(build: Callable[[float], Scene], values: Iterable[float], name: str, control: str,
           until: dict, options: ContinuationOptions = ContinuationOptions()) -> pd.DataFrame:
    """Trace one branch per value of a parameter; one table with a column ``name`` for the value.

    The critical points of each branch are rows with ``point`` = 'LP' or 'BP' as usual.
    """
    tables = []
    for value in values:
        branch = trace(build(value), control, until=until, options=options)
        log.info("%s = %g: %s (%d points)", name, value, branch.status, len(branch.table))
        t = branch.table.copy()
        t.insert(0, name, value)
        t["status"] = branch.status
        tables.append(t)
    return pd.concat(tables, ignore_index=True)
