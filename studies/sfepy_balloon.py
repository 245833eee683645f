"""Peer: SfePy's 3D membrane balloon against snapmem on the same balloon, at equal or better error.

    pip install 'snapmem[sfepy]'        # or: pip install sfepy
    python studies/sfepy_balloon.py [--levels 0 1] [--solver default|pypardiso] [--quick]
                                    [--repeats 5] [--out results/sfepy_balloon.csv]

SfePy ships ``sfepy/examples/large_deformation/balloon.py``: a Mooney-Rivlin membrane
(``dw_tl_membrane``, c1 = 3e5 Pa, c2 = 3e4 Pa, h0 = 0.01) on the surface of the unit ball, a
very soft neo-Hookean solid (mu = 50 Pa) filling it, the volume prescribed so that the stretch
L = r / r0 runs from 1 to 6 (adaptive time steps, L = 1 + t), and the pressure the multiplier of
the volume constraint. It is run unchanged except for the mesh refinement level (0: 1 081 DOFs,
1: 6 397) and the output directory.

Error of a run: the largest relative deviation |p - p_exact(L)| / p_exact(L) over its steps
with 1 < L <= 6 (SfePy's adaptive stepping may end past 6: ``error_beyond`` is the error there),
p_exact the balloon formula of ``snapmem.exact.balloon_pressure`` (R = 1, H = 0.01, c1 = 3e5,
c2 = 3e4, in Pa). snapmem traces the same balloon (``build_scene("balloon", R=1, H=0.01,
c1=3e5, c2=3e4, nodes=N)``) in pressure until the stretch reaches 6 (the continuation passes the
pressure maximum and minimum), its error measured the same way at every traced point; for each
SfePy run the smallest N (odd, from a list) at equal or better error is timed (median of
``--repeats``) and the ratio of wall times reported. SfePy's time is its ``solve_pde`` wall time
(one run: it takes seconds to minutes).

Refinement level 2 (43 048 DOFs) is not in the default: here (SfePy 2026.3, PyPardiso, a loaded
2-core machine) its Newton solver failed on the first step and the adaptive stepping had cut the
step back to a stretch of 1.004 after 15 minutes, when it was stopped.
"""

from __future__ import annotations

import argparse
import logging
import tempfile
import time
from pathlib import Path

import numpy as np
import pandas as pd

from snapmem import build_scene
from snapmem.continuation import trace
from snapmem.exact import balloon_pressure
from snapmem.results import write_table

BALLOON = {"R": 1.0, "H": 0.01, "c1": 3e5, "c2": 3e4}
NODES = (11, 21, 41, 81, 161, 321, 641)
LAM_END = 6.0


def exact(lam):
    return balloon_pressure(lam, R=BALLOON["R"], H=BALLOON["H"], c1=BALLOON["c1"], c2=BALLOON["c2"])


def run_sfepy(level: int, workdir: Path, solver: str) -> dict:
    """Run SfePy's balloon example at one refinement level; its error against the exact curve.

    ``solver`` 'default' keeps the example's ``ls.auto_direct`` (MUMPS, UMFPACK or SuperLU,
    whichever is installed first); 'pypardiso' replaces it by ``ls.pypardiso`` (MKL PARDISO).
    """
    from sfepy.applications import solve_pde
    from sfepy.base.conf import ProblemConf, get_standard_keywords
    from sfepy.postprocess.time_history import extract_time_history
    import sfepy.examples.large_deformation.balloon as example

    out_dir = workdir / f"level{level}"
    options = {"output_dir": str(out_dir), "refinement_level": level}
    conf = ProblemConf.from_file(example.__file__, *get_standard_keywords(), override={"options": options})
    if solver == "pypardiso":
        for struct in conf.solvers.values():
            if struct.name == "ls":
                struct.kind = "ls.pypardiso"
    t0 = time.perf_counter()
    pb, state = solve_pde(conf)
    seconds = time.perf_counter() - t0
    ths, ts = extract_time_history(str(out_dir / "unit_ball.h5"), "p e 0")
    p = np.abs(ths["p"][0][:, 0])                     # the multiplier's sign is SfePy's convention
    lam = 1.0 + np.asarray(ts.times)[: p.size]
    keep = (lam > 1.0) & (lam <= LAM_END + 1e-9)           # the common range (SfePy may overshoot)
    rel = np.abs(p[keep] - exact(lam[keep])) / exact(lam[keep])
    beyond = lam > LAM_END + 1e-9
    rel_beyond = np.abs(p[beyond] - exact(lam[beyond])) / exact(lam[beyond])
    variables = pb.equations.variables                 # unknowns of the solved system: free
    n_dofs = int(getattr(variables, "lcdi", None).n_dof_total if getattr(variables, "lcdi", None)
                 else variables.adi.n_dof_total)       # displacements + the one pressure
    linear = type(getattr(getattr(getattr(pb, "solver", None), "nls", None), "lin_solver", None)).__name__
    return {"method": "sfepy", "setting": level, "solver": linear, "dofs": n_dofs, "points": int(keep.sum()),
            "lam_max": float(lam[keep].max()), "error": float(rel.max()), "seconds": seconds,
            "error_beyond": float(rel_beyond.max()) if rel_beyond.size else None,
            "lam_beyond": float(lam.max()) if rel_beyond.size else None}


def run_snapmem(nodes: int, repeats: int) -> dict:
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        scene = build_scene("balloon", nodes=nodes, **BALLOON)
        table = trace(scene, "pressure", until={"stretch": LAM_END}).table
        times.append(time.perf_counter() - t0)
    lam, p = table["stretch"].to_numpy(), table["pressure"].to_numpy()
    keep = lam > 1.0
    rel = np.abs(p[keep] - exact(lam[keep])) / exact(lam[keep])
    return {"method": "snapmem", "setting": nodes, "dofs": 2 * nodes - 3, "points": int(keep.sum()),
            "lam_max": float(lam.max()), "error": float(rel.max()), "seconds": float(np.median(times))}


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--levels", type=int, nargs="+", default=[0, 1], help="SfePy mesh refinement levels")
    parser.add_argument("--solver", choices=("default", "pypardiso"), default="default",
                        help="SfePy's linear solver: the example's own, or MKL PARDISO (pip install pypardiso)")
    parser.add_argument("--quick", action="store_true", help="level 0 only, 1 repeat")
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--out", default="results/sfepy_balloon.csv")
    args = parser.parse_args(argv)
    levels, repeats = ([0], 1) if args.quick else (args.levels, args.repeats)
    try:
        import sfepy
    except ImportError:
        raise SystemExit("sfepy is not installed: pip install 'snapmem[sfepy]' (it may build from source)")
    logging.getLogger("sfepy").setLevel(logging.WARNING)
    run_snapmem(NODES[0], 1)                                  # warm-up: imports, numba caches
    rows = [run_snapmem(n, repeats) for n in NODES]
    with tempfile.TemporaryDirectory() as tmp:
        for level in levels:
            row = run_sfepy(level, Path(tmp), args.solver)
            print(f"sfepy level {level}: {row['dofs']} DOFs, error {row['error']:.2e}, "
                  f"{row['seconds']:.1f} s", flush=True)
            rows.append(row)
    runs = pd.DataFrame(rows).assign(table="run")
    snap = runs[runs.method == "snapmem"]
    summary = []
    for _, s in runs[runs.method == "sfepy"].iterrows():
        ok = snap[snap.error <= s.error]
        best = ok.loc[ok.seconds.idxmin()] if len(ok) else None
        summary.append({"table": "equal_error", "method": "sfepy/snapmem", "setting": s.setting,
                        "dofs": s.dofs, "error": s.error, "seconds": s.seconds,
                        "snapmem_nodes": None if best is None else int(best.setting),
                        "snapmem_error": None if best is None else best.error,
                        "snapmem_seconds": None if best is None else best.seconds,
                        "ratio_sfepy_over_snapmem": None if best is None else s.seconds / best.seconds})
    table = pd.concat([runs, pd.DataFrame(summary)], ignore_index=True)
    write_table(table, args.out, {"study": "sfepy_balloon", "sfepy": sfepy.__version__, "balloon": BALLOON,
                                  "levels": levels, "repeats": repeats, "solver": args.solver, "snapmem_nodes": NODES,
                                  "error": "max over steps of |p - p_exact(L)| / p_exact(L)"})
    with pd.option_context("display.width", 200, "display.float_format", "{:.3g}".format):
        print(runs.drop(columns="table").to_string(index=False))
        print(pd.DataFrame(summary).drop(columns="table").to_string(index=False))
    return table


if __name__ == "__main__":
    main()
