"""Numerical stability on stiff and extreme cases: one row per case in results/stress_cases.csv.

Gent near its lock (Jlim 5, 20, 270), thickness ratios H/R from 1e-5 to 0.1, stretches up to 10,
voltage up to and past the electromechanical limit with no pressure, meshes from N = 5 to 100001,
tori up to Rs/Rb = 0.95, contact with barrier widths down to 1e-7 of the body and stiff kappa,
fixed time steps up to 0.5 s through a snap, and a voltage so large no equilibrium exists.
Each case succeeds against a known answer or fails with a clear message (snapmem.stress_cases); every
case runs through snapmem.sweeps.sweep with a time limit, so none can hang.

Every case is ok. One of them, no_equilibrium (E_hat = 1), is ok because its solve reports a
failure: no equilibrium exists there by design (past the electromechanical limit), and its row's
``reason`` column says so ("physical: no equilibrium exists by design ..."); every other row's
``reason`` is empty. The stiffest contact (kappa = 1e9 Pa, dhat = 1e-7 of the rod) converges
since the residual's rounding floor counts the barriers' noise (see snapmem.stress_cases.contact).
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
    columns = ["case", "parameters", "outcome", "reason", "status", "iterations", "step_cuts", "wall_time_s",
               "check", "error", "message"]
    table = table[[c for c in columns if c in table.columns]]
    save(args, "stress_cases", table)
    for leftover in args.out.glob("stress_cases.sweep*"):       # the sweep's own file and sidecars
        leftover.unlink()
    print(table[["case", "parameters", "outcome", "wall_time_s"]].to_string(index=False))
    reasons = table[table["reason"].fillna("") != ""]
    for _, row in reasons.iterrows():
        print(f"{row['case']} {row['parameters']}: {row['reason']}")
    return table


if __name__ == "__main__":
    main()
