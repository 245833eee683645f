"""Start-up and first-use times of the CLI, two source trees side by side (issue 17).

Each command runs as a whole process (the way a user meets it), ``--runs`` times, alternating the
two trees (before, after, after, before, ...) so that the load other processes put on the machine
falls on both alike. Every run records its wall time, the time inside the process from the first
line of the script to the end of the command (so the interpreter's own start-up is the
difference), and the 1-minute load average when it started.

"Cold" commands run with an empty numba cache (``NUMBA_CACHE_DIR`` set to a fresh directory):
the first use after an install. They run with ``SNAPMEM_BACKGROUND_COMPILE=0`` so that the
background compile a cold run starts at exit does not load the next measurement.

``--components`` also times, inside one process of the ``after`` tree, what ``trace`` and
``simulate`` spend their time on: importing the CLI, the first kernel call (which imports numba
and sets up its compiler, then loads from the cache), the other kernels' first calls (cache loads),
and the rest (the work, pandas, output).

Usage::

    python studies/startup_times.py --before /work/main --after . [--runs 5] [--cold-runs 1]
    python studies/startup_times.py --only scenes,trace --runs 9

Writes results/startup_times.csv (one row per run) and prints the medians.
"""

from __future__ import annotations

import argparse
import csv
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
TRACE = ["trace", "balloon", "--set", "nodes=101", "--until", "stretch_max=4", "--out", "b.csv", "--points", "p.csv"]
SIMULATE = ["simulate", "torus_snap"]

#: name -> (what runs: python code, or CLI arguments as a list; cold: empty numba cache)
COMMANDS = {
    "import_numpy": ("import numpy", False),
    "import_numba": ("import numba", False),
    "import_snapmem": ("import snapmem", False),
    "scenes": (["scenes"], False),
    "simulate": (SIMULATE, False),
    "trace": (TRACE, False),
    "cold_trace": (TRACE, True),
    "cold_simulate": (SIMULATE, True),
}

WRAPPER = """import sys, time
_start = time.perf_counter()
{body}
sys.stderr.write("\\n@inprocess %.6f\\n" % (time.perf_counter() - _start))
"""


#: A CLI command as the installed ``snapmem`` script runs it: the tree's ``snapmem.cli.run`` (main,
#: then a quick exit) where it has one, else ``sys.exit(main())``; the in-process time is written
#: by the last exit handler.
COMMAND = """import sys, time, atexit
_start = time.perf_counter()
atexit.register(lambda: sys.stderr.write("\\n@inprocess %.6f\\n" % (time.perf_counter() - _start)))
import snapmem.cli as cli
sys.argv = ["snapmem", *{args!r}]
if hasattr(cli, "run"):
    cli.run()
sys.exit(cli.main())
"""


def _code(what) -> str:
    if isinstance(what, str):
        return WRAPPER.format(body=what)
    return COMMAND.format(args=list(what))


def run_once(tree: Path, what, cold: bool, workdir: Path) -> tuple[float, float, float]:
    """(wall time [s], in-process time [s], load average) of one whole-process run in ``tree``."""
    env = dict(os.environ, PYTHONPATH=str(tree))
    cache = None
    if cold:
        cache = tempfile.mkdtemp(prefix="numba-cold-")
        env.update(NUMBA_CACHE_DIR=cache, SNAPMEM_BACKGROUND_COMPILE="0")
    load = os.getloadavg()[0]
    start = time.perf_counter()
    done = subprocess.run([sys.executable, "-c", _code(what)], cwd=workdir, env=env, capture_output=True, text=True)
    wall = time.perf_counter() - start
    if cache is not None:
        shutil.rmtree(cache, ignore_errors=True)
    if done.returncode != 0:
        raise RuntimeError(f"{what!r} failed in {tree}:\n{done.stderr[-2000:]}")
    inside = float(done.stderr.rsplit("@inprocess", 1)[1].split()[0])
    return wall, inside, load


def components(tree: Path, workdir: Path) -> list[tuple[str, str, float]]:
    """In-process split of ``trace`` and ``simulate`` in ``tree`` (warm cache): see the module doc."""
    probe = """import sys, time, json
t0 = time.perf_counter()
import snapmem._lazy as L
firsts = []
call = L.Kernel.__call__
def timed(self, *args):
    if self._dispatcher is None and not self._decided:
        t = time.perf_counter(); out = call(self, *args); firsts.append((self.__qualname__, time.perf_counter() - t))
        return out
    return call(self, *args)
L.Kernel.__call__ = timed
from snapmem.cli import main
t1 = time.perf_counter()
main(%r)
t2 = time.perf_counter()
print("@components", json.dumps([t1 - t0, t2 - t1, firsts, "pandas" in sys.modules, "scipy.linalg" in sys.modules]))
"""
    rows = []
    env = dict(os.environ, PYTHONPATH=str(tree))
    for name, args in (("trace", TRACE), ("simulate", SIMULATE)):
        done = subprocess.run([sys.executable, "-c", probe % (args,)], cwd=workdir, env=env, capture_output=True,
                              text=True)
        import json
        cli, command, firsts, pandas, linalg = json.loads(done.stdout.rsplit("@components", 1)[1])
        first = firsts[0][1] if firsts else 0.0
        others = sum(s for _, s in firsts[1:])
        rows += [(name, "import snapmem.cli", cli),
                 (name, f"first kernel call ({firsts[0][0] if firsts else '-'}: numba import, compiler set-up, load)",
                  first),
                 (name, f"first calls of {max(len(firsts) - 1, 0)} more kernels (cache loads)", others),
                 (name, f"the rest (work, output; pandas loaded: {pandas}, scipy.linalg: {linalg})",
                  command - first - others)]
    return rows


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--before", type=Path, default=Path("/work/main"), help="the tree to compare against")
    parser.add_argument("--after", type=Path, default=ROOT, help="the tree measured (default: this one)")
    parser.add_argument("--runs", type=int, default=5, help="runs per tree of each warm command")
    parser.add_argument("--cold-runs", type=int, default=1, help="runs per tree of each cold command")
    parser.add_argument("--only", default=",".join(COMMANDS), help="comma-separated command names")
    parser.add_argument("--components", action="store_true", help="also split trace and simulate in-process")
    parser.add_argument("--out", type=Path, default=ROOT / "results" / "startup_times.csv")
    args = parser.parse_args(argv)
    trees = {"before": args.before.resolve(), "after": args.after.resolve()}
    rows = []
    with tempfile.TemporaryDirectory(prefix="startup-") as work:
        workdir = Path(work)
        for tree in trees.values():            # fill each tree's numba cache before the warm runs
            for what in (TRACE, SIMULATE):
                run_once(tree, what, False, workdir)
        for name in args.only.split(","):
            what, cold = COMMANDS[name]
            runs = args.cold_runs if cold else args.runs
            for r in range(runs):
                order = ("before", "after") if r % 2 == 0 else ("after", "before")
                for label in order:
                    wall, inside, load = run_once(trees[label], what, cold, workdir)
                    rows.append({"command": name, "tree": label, "run": r, "wall_s": round(wall, 4),
                                 "inprocess_s": round(inside, 4), "load1": round(load, 2)})
                    print(f"{name:15s} {label:6s} run {r}: {wall:7.3f} s whole, {inside:7.3f} s in-process, "
                          f"load {load:.2f}", flush=True)
        split = components(trees["after"], workdir) if args.components else []
    args.out.parent.mkdir(parents=True, exist_ok=True)
    with open(args.out, "w", newline="") as file:
        writer = csv.DictWriter(file, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    print(f"\nmedians ({args.out}); before = {trees['before']}, after = {trees['after']}")
    print(f"{'command':15s} {'before':>8s} {'after':>8s} {'in-process after':>17s} {'load':>10s}")
    for name in dict.fromkeys(r["command"] for r in rows):
        med = {label: statistics.median(r["wall_s"] for r in rows if r["command"] == name and r["tree"] == label)
               for label in trees}
        inside = statistics.median(r["inprocess_s"] for r in rows if r["command"] == name and r["tree"] == "after")
        loads = [r["load1"] for r in rows if r["command"] == name]
        print(f"{name:15s} {med['before']:8.3f} {med['after']:8.3f} {inside:17.3f} {min(loads):4.1f}-{max(loads):<4.1f}")
    for name, part, seconds in split:
        print(f"  {name:9s} {seconds:7.3f} s  {part}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
