"""Regenerate every figure and table of results/ in one command, with a progress display.

Each study runs as its own process (as a user would run it), its output kept in
results/logs/<study>.log; results/study_times.csv records how long each took.

    python studies/run_all.py [--quick] [--only NAME ...]
"""

import argparse
import subprocess
import sys
import time
from pathlib import Path

import pandas as pd

HERE = Path(__file__).resolve().parent
RESULTS = HERE.parent / "results"

# (script, extra arguments): the paper's figures first, then the evidence studies
STUDIES = [
    ("fig3_validation", ["--out", "results"]),
    ("fig4_electro_balloon", ["--out", "results"]),
    ("fig5_electro_torus", ["--out", "results"]),
    ("torus_limit_maps", ["--out", "results"]),
    ("torus_limit_convergence", ["--out", "results"]),
    ("balloon_atlas", ["--out", "results"]),
    ("robot_curves", ["--out", "results/robots"]),
    ("fig6_8_robots", ["--out", "results", "--tables", "results/robots"]),
    ("fig9_timing", ["--out", "results"]),
    ("error_vs_runtime", ["--out", "results"]),
    ("stress_cases", ["--out", "results"]),
    ("contact_barrier", ["--out", "results"]),
]


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="every study's small setting")
    parser.add_argument("--only", nargs="*", help="run only these studies")
    args = parser.parse_args(argv)
    chosen = [(s, a) for s, a in STUDIES if not args.only or s in args.only]
    logs = RESULTS / "logs"
    logs.mkdir(parents=True, exist_ok=True)
    rows, start = [], time.perf_counter()
    for i, (script, extra) in enumerate(chosen, 1):
        print(f"[{i}/{len(chosen)}] {script} ...", end="", flush=True)
        t0 = time.perf_counter()
        with open(logs / f"{script}.log", "w") as log:
            code = subprocess.call([sys.executable, str(HERE / f"{script}.py"), *extra,
                                    *(["--quick"] if args.quick else [])],
                                   cwd=HERE.parent, stdout=log, stderr=subprocess.STDOUT)
        seconds = time.perf_counter() - t0
        rows.append({"study": script, "seconds": round(seconds, 2), "exit_code": code})
        print(f" {'done' if code == 0 else f'FAILED (exit {code}, see results/logs/{script}.log)'} in {seconds:.1f} s"
              f"  [total {time.perf_counter() - start:.0f} s]", flush=True)
    pd.DataFrame(rows).to_csv(RESULTS / "study_times.csv", index=False)
    failed = [r["study"] for r in rows if r["exit_code"] != 0]
    print(f"all studies: {time.perf_counter() - start:.0f} s" + (f"; failed: {', '.join(failed)}" if failed else ""))
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
