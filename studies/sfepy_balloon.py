"""Peer: SfePy's 3D membrane balloon against snapmem on the same balloon, at equal or better error.

    pip install 'snapmem[sfepy]'        # or: pip install sfepy
    python studies/sfepy_balloon.py [--levels 0 1] [--solver default|pypardiso] [--quick]
                                    [--repeats 21] [--sfepy-repeats 3]
                                    [--sfepy-from results/sfepy_balloon.csv]
                                    [--out results/sfepy_balloon.csv]

SfePy ships ``sfepy/examples/large_deformation/balloon.py``: a Mooney-Rivlin membrane
(``dw_tl_membrane``, c1 = 3e5 Pa, c2 = 3e4 Pa, h0 = 0.01) on the surface of the unit ball, a
very soft neo-Hookean solid (mu = 50 Pa) filling it, the volume prescribed so that the stretch
L = r / r0 runs from 1 to 6 (adaptive time steps, L = 1 + t), and the pressure the multiplier of
the volume constraint. It is run unchanged except for the mesh refinement level (0: 1 081 DOFs,
1: 6 397) and the output directory. It computes the pressure at its steps (11 to 15 of them with
1 < L <= 6), and no stability.

Error of a run: the largest relative deviation |p - p_exact(L)| / p_exact(L) over its steps
with 1 < L <= 6 (SfePy's adaptive stepping may end past 6: ``error_beyond`` is the error there),
p_exact the balloon formula of ``snapmem.reference.exact.balloon_pressure`` (R = 1, H = 0.01, c1 = 3e5,
c2 = 3e4, in Pa). SfePy's time is its ``solve_pde`` wall time (one run: it takes seconds to
minutes): the median of ``--sfepy-repeats`` runs for a level that takes under 20 s (level 0;
its first run also pays the linear solver's first use), one run otherwise (level 1: 36 to 41 s).

snapmem, on ``build_scene("balloon", R=1, H=0.01, c1=3e5, c2=3e4, nodes=N)``, three ways:

* ``snapmem_path``: the same work as SfePy: the pressure at SfePy's own stretch steps (all of
  them, the one past L = 6 included), the equator's radius prescribed and the pressure the
  unknown (``snapmem.reference.paths.coordinate_path`` from the unloaded sphere), no stability;
* ``snapmem_richardson``: that on N and 2N - 1 nodes, the pressures extrapolated at order 2;
* ``snapmem``: ``snapmem.continuation.tracer.trace`` in pressure until the stretch reaches 6 (its own
  42 to 47 points, through the pressure maximum and minimum, stability at every point): more
  work than SfePy does.

Each is timed from ``build_scene`` to the pressures (median of ``--repeats``, the settings of a
level interleaved round-robin) and its error measured as SfePy's. For each SfePy run and each
snapmem method the cheapest setting at equal or better error is reported with the ratio of wall
times (``table = equal_error``).

``--sfepy-from CSV`` reuses the SfePy rows (time, error, stretch steps) of an earlier run's CSV
instead of running SfePy again; the table says so (``sfepy_cached``) and keeps the date of the
SfePy measurement (``measured_at``). The committed CSV comes from one run that times both.

Refinement level 2 (43 048 DOFs) is not in the default: here (SfePy 2026.3, PyPardiso, a loaded
2-core machine) its Newton solver failed on the first step and the adaptive stepping had cut the
step back to a stretch of 1.004 after 15 minutes, when it was stopped.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import logging
import tempfile
import time
from pathlib import Path

import numpy as np
import pandas as pd

from snapmem import build_scene
from snapmem.continuation.tracer import trace
from snapmem.reference.exact import balloon_pressure
from snapmem.reference.paths import coordinate_path, extrapolate
from snapmem.io.results import write_table

BALLOON = {"R": 1.0, "H": 0.01, "c1": 3e5, "c2": 3e4}
NODES = (11, 21, 41, 81, 161, 321, 641)            # the mesh size halves from one to the next
LAM_END = 6.0
SFEPY_REPEAT_BELOW = 20.0           # [s]: a level this fast is run --sfepy-repeats times (level 0), others once


def exact(lam):
    return balloon_pressure(lam, R=BALLOON["R"], H=BALLOON["H"], c1=BALLOON["c1"], c2=BALLOON["c2"])


def curve_error(lam, p) -> tuple[float, float | None]:
    """Largest relative error over 1 < L <= 6, and past 6 (None if no step is)."""
    rel = np.abs(p - exact(lam)) / exact(lam)
    keep, beyond = (lam > 1.0) & (lam <= LAM_END + 1e-9), lam > LAM_END + 1e-9
    return float(rel[keep].max()), (float(rel[beyond].max()) if beyond.any() else None)


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
    measured_at = time.strftime("%Y-%m-%d %H:%M:%S")
    with contextlib.redirect_stdout(io.StringIO()):      # the example prints every step's stretch
        t0 = time.perf_counter()
        pb, state = solve_pde(conf)
        seconds = time.perf_counter() - t0
    ths, ts = extract_time_history(str(out_dir / "unit_ball.h5"), "p e 0")
    p = np.abs(ths["p"][0][:, 0])                     # the multiplier's sign is SfePy's convention
    lam = 1.0 + np.asarray(ts.times)[: p.size]
    keep = (lam > 1.0) & (lam <= LAM_END + 1e-9)           # the common range (SfePy may overshoot)
    error, beyond = curve_error(lam[lam > 1.0], p[lam > 1.0])
    variables = pb.equations.variables                 # unknowns of the solved system: free
    n_dofs = int(getattr(variables, "lcdi", None).n_dof_total if getattr(variables, "lcdi", None)
                 else variables.adi.n_dof_total)       # displacements + the one pressure
    linear = type(getattr(getattr(getattr(pb, "solver", None), "nls", None), "lin_solver", None)).__name__
    return {"method": "sfepy", "setting": level, "solver": linear, "dofs": n_dofs, "points": int(keep.sum()),
            "lam_max": float(lam[keep].max()), "error": error, "seconds": seconds, "error_beyond": beyond,
            "lam_beyond": float(lam.max()) if beyond is not None else None, "measured_at": measured_at,
            "stretches": " ".join(f"{x:.17g}" for x in lam[lam > 1.0])}


def cached_sfepy(path, levels) -> list[dict]:
    """The SfePy rows of an earlier run's table (they must hold their stretch steps)."""
    old = pd.read_csv(path)
    rows = old[(old["table"] == "run") & (old["method"] == "sfepy") & old["setting"].isin(levels)]
    if len(rows) < len(levels) or "stretches" not in rows or rows["stretches"].isna().any():
        raise SystemExit(f"{path}: no SfePy rows with their stretch steps for levels {levels}; run SfePy")
    return [{**r, "setting": int(r["setting"]), "sfepy_cached": True} for r in rows.drop(columns="table").to_dict("records")]


def path_pressures(nodes: int, lam: np.ndarray) -> np.ndarray:
    """snapmem's pressures at the stretches ``lam``: the equator's radius prescribed."""
    scene = build_scene("balloon", nodes=nodes, **BALLOON)
    equator = 2 * (nodes // 2)                         # r of the middle node (nodes odd)
    return coordinate_path(scene, equator, lam * BALLOON["R"], (scene.reference_state(), {"pressure": 0.0})).loads


def path_run(meshes: tuple, lam: np.ndarray) -> np.ndarray:
    """Pressures at ``lam`` on one mesh, or extrapolated from two (h = pi R / (N - 1))."""
    values = [path_pressures(n, lam) for n in meshes]
    return values[0] if len(meshes) == 1 else extrapolate([1.0 / (n - 1) for n in meshes], values)


def trace_run(nodes: int):
    table = trace(build_scene("balloon", nodes=nodes, **BALLOON), "pressure", until={"stretch": LAM_END}).table
    keep = table["stretch"].to_numpy() > 1.0
    return table["stretch"].to_numpy()[keep], table["pressure"].to_numpy()[keep]


def interleaved(fns: dict, repeats: int) -> dict:
    """(median wall time [s], last result) of each function, timed round-robin, ``repeats`` rounds."""
    times, out = {key: [] for key in fns}, {}
    for _ in range(repeats):
        for key, fn in fns.items():
            t0 = time.perf_counter()
            out[key] = fn()
            times[key].append(time.perf_counter() - t0)
    return {key: (float(np.median(times[key])), out[key]) for key in fns}


def snapmem_rows(sfepy_rows, nodes, repeats) -> list[dict]:
    """Every snapmem setting, timed interleaved: the trace once; the paths at each SfePy level's steps."""
    rows = []
    traced = interleaved({n: (lambda n=n: trace_run(n)) for n in nodes}, max(1, repeats // 4))
    for n, (seconds, (lam, p)) in traced.items():
        rows.append({"method": "snapmem", "setting": n, "dofs": 2 * n - 3, "points": int(lam.size),
                     "lam_max": float(lam.max()), "error": curve_error(lam, p)[0], "seconds": seconds})
    for s in sfepy_rows:
        lam = np.array([float(x) for x in s["stretches"].split()])
        settings = [(n,) for n in nodes] + [pair for pair in zip(nodes, nodes[1:])]
        timed = interleaved({m: (lambda m=m: path_run(m, lam)) for m in settings}, repeats)
        for m, (seconds, p) in timed.items():
            error, beyond = curve_error(lam, p)
            rows.append({"method": "snapmem_path" if len(m) == 1 else "snapmem_richardson", "setting": m[-1],
                         "meshes": "/".join(map(str, m)), "sfepy_level": s["setting"], "dofs": 2 * m[-1] - 2,
                         "points": int(np.sum(lam <= LAM_END + 1e-9)), "lam_max": float(lam.max()),
                         "error": error, "error_beyond": beyond, "seconds": seconds})
    return rows


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--levels", type=int, nargs="+", default=[0, 1], help="SfePy mesh refinement levels")
    parser.add_argument("--solver", choices=("default", "pypardiso"), default="default",
                        help="SfePy's linear solver: the example's own, or MKL PARDISO (pip install pypardiso)")
    parser.add_argument("--quick", action="store_true", help="level 0 only, run once, 3 repeats of snapmem, N <= 41")
    parser.add_argument("--repeats", type=int, default=21)
    parser.add_argument("--sfepy-repeats", type=int, default=3,
                        help=f"runs of each SfePy level that takes under {SFEPY_REPEAT_BELOW:g} s (median reported)")
    parser.add_argument("--sfepy-from", help="reuse the SfePy rows of this earlier CSV instead of running SfePy")
    parser.add_argument("--out", default="results/sfepy_balloon.csv")
    args = parser.parse_args(argv)
    levels, repeats, nodes = ([0], 3, NODES[:3]) if args.quick else (args.levels, args.repeats, NODES)
    sfepy_repeats = 1 if args.quick else args.sfepy_repeats
    if args.sfepy_from:
        sfepy_rows, version = cached_sfepy(args.sfepy_from, levels), "cached"
        print(f"SfePy NOT re-run: its rows are those of {args.sfepy_from}, measured at "
              + ", ".join(str(r["measured_at"]) for r in sfepy_rows), flush=True)
    else:
        try:
            import sfepy
        except ImportError:
            raise SystemExit("sfepy is not installed: pip install 'snapmem[sfepy]' (it may build from source)")
        logging.getLogger("sfepy").setLevel(logging.WARNING)
        from sfepy.base.base import output
        output.set_output(quiet=True)                  # its per-iteration log, hundreds of lines
        version, sfepy_rows = sfepy.__version__, []
        with tempfile.TemporaryDirectory() as tmp:
            for level in levels:
                runs = [run_sfepy(level, Path(tmp), args.solver)]
                while runs[0]["seconds"] < SFEPY_REPEAT_BELOW and len(runs) < sfepy_repeats:
                    runs.append(run_sfepy(level, Path(tmp), args.solver))
                times = [r["seconds"] for r in runs]
                row = {**runs[0], "seconds": float(np.median(times)), "sfepy_runs": len(runs),
                       "sfepy_seconds_all": " ".join(f"{t:.3f}" for t in times), "sfepy_cached": False}
                print(f"sfepy level {level}: {row['dofs']} DOFs, {row['points']} steps, error {row['error']:.2e}, "
                      f"{row['seconds']:.2f} s (median of {times})", flush=True)
                sfepy_rows.append(row)
    trace_run(nodes[0]), path_run(nodes[:1], np.array([1.5, 2.0]))       # warm-up: imports, numba caches
    runs = pd.DataFrame(snapmem_rows(sfepy_rows, nodes, repeats) + sfepy_rows).assign(table="run")
    summary = []
    for s in sfepy_rows:
        for method in ("snapmem", "snapmem_path", "snapmem_richardson"):
            mine = runs[(runs.method == method) & (runs.error <= s["error"])]
            if method != "snapmem":
                mine = mine[mine.sfepy_level == s["setting"]]
            best = mine.loc[mine.seconds.idxmin()] if len(mine) else None
            summary.append({"table": "equal_error", "method": "sfepy/snapmem", "setting": s["setting"],
                            "dofs": s["dofs"], "points": s["points"], "error": s["error"], "seconds": s["seconds"],
                            "snapmem_method": method,
                            "snapmem_nodes": None if best is None else int(best.setting),
                            "snapmem_meshes": None if best is None else (best.meshes if isinstance(best.get("meshes"), str)
                                                                          else str(int(best.setting))),
                            "snapmem_points": None if best is None else int(best.points),
                            "snapmem_error": None if best is None else best.error,
                            "snapmem_seconds": None if best is None else best.seconds,
                            "ratio_sfepy_over_snapmem": None if best is None else s["seconds"] / best.seconds,
                            "sfepy_cached": s["sfepy_cached"], "measured_at": s["measured_at"]})
    table = pd.concat([runs, pd.DataFrame(summary)], ignore_index=True)
    write_table(table, args.out, {"study": "sfepy_balloon", "sfepy": version, "balloon": BALLOON,
                                  "levels": levels, "repeats": repeats, "sfepy_repeats": sfepy_repeats,
                                  "solver": args.solver, "snapmem_nodes": nodes,
                                  "sfepy_from": args.sfepy_from, "date": time.strftime("%Y-%m-%d %H:%M:%S"),
                                  "error": "max over steps 1 < L <= 6 of |p - p_exact(L)| / p_exact(L)"})
    with pd.option_context("display.width", 250, "display.float_format", "{:.3g}".format):
        print(runs.drop(columns=["table", "stretches"], errors="ignore").to_string(index=False))
        print(pd.DataFrame(summary).drop(columns="table").to_string(index=False))
    return table


if __name__ == "__main__":
    main()
