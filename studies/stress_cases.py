"""Numerical stability on stiff and extreme cases: one row per case in results/stress_cases.csv.

Gent near its lock (Jlim 5, 20, 270), thickness ratios H/R from 1e-5 to 0.1, stretches up to 10,
voltage up to and past the electromechanical limit with no pressure, meshes from N = 5 to 100001,
tori up to Rs/Rb = 0.95, contact with barrier widths down to 1e-7 of the body and stiff kappa,
fixed time steps up to 0.5 s through a snap, and a voltage so large no equilibrium exists.
Each case succeeds against a known answer or fails with a clear message (snapmem.stress_cases); every
case runs through snapmem.sweeps.sweep with a time limit, so none can hang.

Every case is ok except two that fail clearly by design or for a numerical reason:
no_equilibrium (no equilibrium exists; it must be reported) and contact with kappa = 1e9 Pa and
dhat = 1e-7 of the rod (the barrier's stiffness times the round-off of a node's radius is a
force noise above Newton's tolerance; see snapmem.stress_cases.contact).
"""

from snapmem import stress
from snapmem.study import parse_args, save
from snapmem.sweeps.sweep import sweep


def main(argv=None):
    args = parse_args(__doc__, argv, extra=lambda p: p.add_argument("--timeout", type=float, default=600.0))
    path = args.out / "stress_cases.sweep.csv"
    if path.exists():
        path.unlink()                  # a fresh run: the table is regenerated, not resumed
    table = sweep(stress.run_case, stress.designs(args.quick), path, timeout=args.timeout, workers=2)
    columns = ["case", "parameters", "outcome", "status", "iterations", "step_cuts", "wall_time_s", "check",
               "error", "message"]
    table = table[[c for c in columns if c in table.columns]]
    save(args, "stress_cases", table)
    for leftover in args.out.glob("stress_cases.sweep*"):       # the sweep's own file and sidecars
        leftover.unlink()
    print(table[["case", "parameters", "outcome", "wall_time_s"]].to_string(index=False))
    return table


if __name__ == "__main__":
    main()
