"""The ``snapmem`` command: a thin layer over the package.

Every command builds a scene from ``--set NAME=VALUE`` pairs and calls one driver. Bad input
is one line on stderr and exit code 2; ``--debug`` shows the traceback instead.
"""

from __future__ import annotations

import argparse
import atexit
import logging
import os
import sys
from pathlib import Path

import numpy as np
import snapmem._lazy as _lazy

pd = _lazy.module("pandas")  # imported at first use (start-up)

from snapmem.catalog.scenes import SCENES, get_spec
from snapmem.continuation import CONTROLS
from snapmem.dynamics import SCHEMES
from snapmem.errors import SnapmemError, SolverError, check_int, check_real
from snapmem.io.interrupts import sigterm_as_interrupt
from snapmem.io.progress import Progress, bar
from snapmem.sweeps.grid import parse_axis, parse_value

from snapmem.commands.branches import cmd_fold, cmd_hysteresis, cmd_trace
from snapmem.commands.common import LOAD_CONTROLS, check_outputs, integer, merge_option, parse_sets, real



class _Parser(argparse.ArgumentParser):
    def error(self, message):          # one line, exit 2, like every other bad input
        raise SnapmemError(message)


def cmd_scenes(args) -> int:
    for spec in SCENES.values():
        print(f"{spec.name}: {spec.doc}")
        for p in spec.parameters:
            default = "(derived)" if p.default is None else p.default
            unit = f" [{p.unit}]" if p.unit else ""
            print(f"    {p.name} = {default}{unit}  {p.doc}")
    return 0


def cmd_equilibrium(args) -> int:
    from snapmem.statics import equilibrium
    params = merge_option(parse_sets(args.set), "pressure", args.pressure, "--pressure")
    scene = get_spec(args.scene).build(**params)
    eq = equilibrium(scene)
    for name, value in {"pressure": scene.resolve_loads(eq.loads)["pressure"], **eq.measures()}.items():
        print(f"{name}: {value:.10g}" if isinstance(value, float) else f"{name}: {value}")
    for line in eq.report.lines():
        print(line)
    return 0 if eq.converged else 1


def cmd_sweep(args) -> int:
    from snapmem.sweeps.sweep import make_job, sweep
    from snapmem.sweeps.grid import check_design_count
    fixed = merge_option(parse_sets(args.set), "pressure", args.pressure, "--pressure")
    axes = {}
    for text in args.grid:
        name, values = parse_axis(text)
        if name in axes:
            raise SnapmemError(f"--grid {name!r}: given twice")
        axes[name] = values
        check_design_count(axes)                     # at once, before the product is made
    job = make_job(args.job, args.scene, fixed, axes)
    workers, timeout = (None if text is None else parse_value(name, text, number=True)
                        for name, text in (("workers", args.workers), ("timeout", args.timeout)))
    table = sweep(job, axes, args.out, workers=workers, scheduler=args.scheduler, timeout=timeout,
                  progress=not args.quiet)
    counts = table["status"].value_counts()
    print(f"{args.out}: {len(table)} rows; " + ", ".join(f"{s} {n}" for s, n in sorted(counts.items())))
    return 0


def _restart_state(path, scene_name: str, scene, t_end: float) -> dict:
    """The end state of the run saved at ``path`` (``simulate --out``), to continue it to ``t_end``
    on ``scene``: it must be a run of the same scene with the same parameters, ending before t_end."""
    import json
    from snapmem.dynamics.trajectory import Trajectory
    if not Path(path).is_file():
        raise SnapmemError(f"--restart {path}: no such file")
    saved = Trajectory.load(path)
    resume = saved.meta.get("resume")
    if resume is None:
        raise SnapmemError(f"--restart {path}: the file holds no end state to continue (a trajectory saved by "
                           "'snapmem simulate --out' of this version)")
    if saved.meta.get("scene") != scene_name:
        raise SnapmemError(f"--restart {path}: a run of {saved.meta.get('scene')!r}, not of {scene_name!r}")
    before, now = saved.meta.get("parameters", {}), json.loads(json.dumps(scene.parameters, default=str))
    changed = sorted(k for k in set(before) | set(now) if before.get(k) != now.get(k))
    if changed:
        raise SnapmemError(f"--restart {path}: give the saved run's parameters; these differ: "
                           + ", ".join(f"{k} ({before.get(k)!r} saved, {now.get(k)!r} now)" for k in changed))
    if not t_end > resume["t"]:
        raise SnapmemError(f"--t-end {t_end:g}: a restart continues the saved run past its end, t = {resume['t']:g} s")
    return resume


def cmd_simulate(args) -> int:
    import dataclasses
    from snapmem.catalog.robots import EXPERIMENTS, events, experiment
    from snapmem.dynamics.driver import simulate
    from snapmem.io.results import OutputSet
    out = None
    if args.out:                                       # the name Trajectory.save writes ('.npz' appended if missing)
        out = Path(args.out) if Path(args.out).suffix == ".npz" else Path(args.out + ".npz")
    params = parse_sets(args.set)
    if "name" in params:
        raise SnapmemError(f"--set name={params['name']}: the scene is named by the command's scene argument "
                           f"({args.scene!r}); leave name out")
    for option, name in (("--t-end", "t_end"), ("--tol", "tol")):
        if getattr(args, name) is not None and name in params:
            raise SnapmemError(f"--set {name}={params[name]} and {option} {getattr(args, name)}: "
                               f"set {name} one way, not both")
    ex = experiment(args.scene, **params)
    changes = {k: v for k, v in (("scheme", args.scheme),
                                 ("tol", None if args.tol is None else check_real("--tol", args.tol, minimum=1e-8,
                                                                                  maximum=1.0)))
               if v is not None}
    dt_min = ex.options.dt_min
    t_end = check_real("--t-end" if args.t_end is not None else "t_end", ex.t_end if args.t_end is None else args.t_end,
                       minimum=dt_min, maximum=1e9)
    frames = check_int("--frames", args.frames, minimum=0, maximum=10_000_000)
    if frames:
        changes["save_interval"] = t_end / frames
    options = dataclasses.replace(ex.options, **changes)
    resume = _restart_state(args.restart, args.scene, ex.scene, t_end) if args.restart else None
    display = Progress(enabled=not args.quiet)

    def progress(t, t_end):
        done = min(1.0, t / t_end) if t_end > 0 else 1.0
        display.show(f"[{bar(done, 40)}] t = {t:9.4f} / {t_end:g} s  wall {display.elapsed:6.1f} s",
                     force=t >= t_end)

    try:
        traj = simulate(ex.scene, ex.loads, t_end, rho=ex.rho, damping=ex.damping, q0=ex.q0, v0=ex.v0,
                        options=options, damp_bodies=ex.damp_bodies, progress=None if args.quiet else progress,
                        resume=resume)
    finally:
        display.close()
    meta = traj.meta
    wall = meta["wall_time"]
    lines = {"scene": args.scene, "status": meta["status"], "scheme": meta["scheme"], "t_end": meta["t_end"],
             "steps": meta["steps"],
             "rejected": meta["rejected"], "newton_iterations": meta["newton_iterations"], "wall_time": wall,
             "real_time_factor": meta["t_end"] / wall if wall > 0 else float("inf"),
             "volume": float(traj["volume"][-1]), "min_gap": float(np.min(traj["min_gap"]))}
    for key in traj.data:
        if key.endswith(("_force", "_z")):
            lines[f"final_{key}"] = float(traj[key][-1])
    if args.scene in EXPERIMENTS and meta["status"] == "completed" and len(traj["t"]) >= 2:
        lines.update({f"event_{k}": v for k, v in events(traj).items()})     # snap times, ball heights, ...
    if meta.get("interrupted"):
        lines["status"] = f"interrupted ({meta['status']})"
    for name, value in lines.items():
        print(f"{name}: {value:.6g}" if isinstance(value, float) else f"{name}: {value}")
    if out is not None:                                # the frames so far, also when interrupted
        with OutputSet() as outputs:
            traj.save(outputs.stage(out))
        print(f"saved: {out}")
    if meta.get("interrupted"):
        raise KeyboardInterrupt                        # exit 130, after the frames are saved
    return 0 if meta["status"] == "completed" else 1


def cmd_replay(args) -> int:
    from snapmem.dynamics.driver import Trajectory
    from snapmem.viz.replay import animate
    frames = check_int("--frames", args.frames, minimum=1, maximum=100_000)
    fps = check_int("--fps", args.fps, minimum=1, maximum=1000)
    traj = Trajectory.load(args.trajectory)
    out = animate(traj, args.out, frames=frames, fps=fps)
    print(f"wrote: {out}")
    return 0


def cmd_export(args) -> int:
    from snapmem.viz.export import export
    result = export(args.file, args.out, segments=args.segments, format=args.format)
    bodies = ", ".join(f"{name} ({len(paths)} file{'s' if len(paths) > 1 else ''})"
                       for name, paths in result.bodies.items()) or "none"
    print(f"{result.kind}: {len(result.membrane)} surfaces, rigid bodies: {bodies}")
    print(f"wrote: {result.pvd}")
    return 0


def cmd_bench(args) -> int:
    from snapmem.bench import run
    from snapmem.io.results import write_table
    table = run(quick=args.quick)
    write_table(table, args.out, {"command": "bench", "quick": args.quick})
    with pd.option_context("display.width", 220, "display.max_colwidth", 90):
        print(table.to_string(index=False, float_format=lambda v: f"{v:.4g}"))
    return 0


def cmd_warmup(args) -> int:
    from snapmem.warmup import warmup

    def report(stage):
        print(f"{stage.name}: {stage.seconds:.2f} s")
        for each in stage.kernels:
            print(f"  {each.kernel}: {each.seconds:.2f} s")
        if not stage.kernels:
            print("  nothing to compile (all in the cache)")
    stages = warmup(everything=args.all, report=report)
    print(f"warmup: {sum(s.seconds for s in stages):.2f} s, {sum(len(s.kernels) for s in stages)} kernels")
    return 0


def scene_arguments(p: argparse.ArgumentParser, controls: tuple | None = None) -> None:
    """The arguments every scene command takes: the scene, ``--set NAME=VALUE`` and, for the
    branch commands, ``--control`` among ``controls``."""
    p.add_argument("scene")
    p.add_argument("--set", action="append", metavar="NAME=VALUE", help="scene parameter (repeatable)")
    if controls is not None:
        p.add_argument("--control", choices=controls, default="pressure")


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(prog="snapmem", description="Snap-through of axisymmetric dielectric-elastomer membranes.")
    parser.add_argument("--debug", action="store_true", help="show tracebacks")
    parser.add_argument("-v", "--verbose", action="store_true", help="log solver progress")
    sub = parser.add_subparsers(dest="command", parser_class=_Parser)
    sub.required = True

    p = sub.add_parser("scenes", help="list scenes with their parameters, defaults and units")
    p.set_defaults(func=cmd_scenes)

    p = sub.add_parser("equilibrium", help="solve one equilibrium, loading from rest")
    scene_arguments(p)
    p.add_argument("--pressure", type=str, help="pressure (inside minus outside), scene units")
    p.set_defaults(func=cmd_equilibrium)

    p = sub.add_parser("sweep", help="run a grid of designs in parallel, one CSV row each; rerun to resume")
    p.add_argument("scene")
    p.add_argument("--grid", action="append", required=True, metavar="NAME=START:STOP:COUNT|NAME=v1,v2,...",
                   help="a grid axis (repeatable; every combination runs)")
    p.add_argument("--set", action="append", metavar="NAME=VALUE", help="fixed scene parameter (repeatable)")
    p.add_argument("--pressure", type=str, help="pressure of every design (or make it a --grid axis)")
    p.add_argument("--out", required=True, help="CSV file; designs already in it are skipped")
    p.add_argument("--job", default="equilibrium", help="what to compute per design (default: equilibrium)")
    p.add_argument("--workers", help="processes (default: the number of cores)")
    p.add_argument("--scheduler", help="'local' (a local Dask cluster) or tcp://HOST:PORT (needs snapmem[dask])")
    p.add_argument("--timeout", help="per-design time limit [s]")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=cmd_sweep)

    p = sub.add_parser("trace", help="trace an equilibrium branch through its limit points")
    scene_arguments(p, controls=CONTROLS)
    p.add_argument("--until", action="append", metavar="NAME=VALUE",
                   help="stop when an output reaches a value (default stretch_max=4)")
    p.add_argument("--out", metavar="BRANCH.csv", help="branch table (+ .json parameters, .npz states)")
    p.add_argument("--points", metavar="POINTS.csv", help="critical points table")
    p.add_argument("--plot", metavar="FIG.png", help="plot of the branch")
    p.add_argument("--x", help="column on the plot's x axis (default: the scene's first probe or u_max)")
    p.add_argument("--save-at", type=real, action="append", metavar="VALUE",
                   help="locate a point exactly at this control value (repeatable)")
    p.add_argument("--stop-at-first-limit", action="store_true")
    p.add_argument("--max-steps", type=integer, default=2000)
    p.add_argument("--restart", metavar="BRANCH.npz", help="start from a point saved by an earlier trace")
    p.add_argument("--start-index", type=integer, default=-1, help="which saved point to restart from (default last)")
    p.add_argument("--switch", metavar="BRANCH.npz:K", help="switch at the BP in row K of the points table of a "
                   "branch saved by trace --out and trace the new branch both ways (--out writes the diagram)")
    p.add_argument("--sensitivity", metavar="NAME,NAME,...",
                   help="add d<control>_d<NAME> at each limit point to the points table (e.g. c2,E_hat)")
    p.set_defaults(func=cmd_trace)

    p = sub.add_parser("fold", help="follow a limit point as a second parameter varies")
    p.add_argument("scene")
    p.add_argument("--vary", required=True, metavar="NAME=START:STOP:COUNT",
                   help="scene parameter to vary, as a range or a list v1,v2,...")
    p.add_argument("--set", action="append", metavar="NAME=VALUE", help="scene parameter (repeatable)")
    p.add_argument("--control", choices=LOAD_CONTROLS, default="pressure")
    p.add_argument("--out", metavar="FOLD.csv")
    p.add_argument("--plot", metavar="FIG.png")
    p.add_argument("--points", metavar="SPECIAL.csv",
                   help="cusps (CP) and turning points (TP) of the fold curve, one row each")
    p.set_defaults(func=cmd_fold)

    p = sub.add_parser("hysteresis", help="up, snap, down, snap back: a hysteresis loop in one call")
    scene_arguments(p, controls=LOAD_CONTROLS)
    p.add_argument("--peak", type=real, help="control value reached after the snap (default 1.05 x the limit)")
    p.add_argument("--out", metavar="LOOP.csv", help="the loop's branches (+ LOOP_snaps.csv)")
    p.add_argument("--plot", metavar="FIG.png")
    p.set_defaults(func=cmd_hysteresis)

    p = sub.add_parser("bench", help="benchmarks: Newton against the banded solve, whole jobs, designs per second")
    p.add_argument("--quick", action="store_true", help="small sizes, for a quick check")
    p.add_argument("--out", default="results/benchmark.csv", metavar="BENCH.csv")
    p.set_defaults(func=cmd_bench)

    p = sub.add_parser("simulate", help="simulate a scene in time with its schedule (dynamics, contact)")
    scene_arguments(p)
    p.add_argument("--t-end", type=real, help="end time [s] (default: the scene's)")
    p.add_argument("--scheme", choices=SCHEMES, help="time integrator")
    p.add_argument("--tol", type=real, help="local error tolerance per step (fraction of the size)")
    p.add_argument("--frames", type=integer, default=0, help="save about this many frames (default: every step)")
    p.add_argument("--out", metavar="TRAJ.npz", help="save the trajectory (compressed, no pickle)")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.add_argument("--restart", metavar="TRAJ.npz", help="continue a run saved by 'simulate --out' (same scene "
                   "and --set) from its end to --t-end (the absolute end time)")
    p.set_defaults(func=cmd_simulate)

    p = sub.add_parser("replay", help="animate a saved trajectory to .gif or .mp4")
    p.add_argument("trajectory", metavar="TRAJ.npz")
    p.add_argument("--out", required=True, metavar="FILE.gif|FILE.mp4")
    p.add_argument("--frames", type=integer, default=120)
    p.add_argument("--fps", type=integer, default=20)
    p.set_defaults(func=cmd_replay)

    p = sub.add_parser("warmup", help="compile ahead the kernels of trace and simulate (once after install)")
    p.add_argument("--all", action="store_true", help="also every robot experiment's kernels")
    p.set_defaults(func=cmd_warmup)
    p = sub.add_parser("export", help="3D surfaces for ParaView: a trajectory or branch as .vtu files and a .pvd")
    p.add_argument("file", metavar="FILE.npz", help="from 'simulate --out' or 'trace --out'")
    p.add_argument("--format", choices=("vtk",), default="vtk")
    p.add_argument("--out", required=True, metavar="DIR", help="folder for the files")
    p.add_argument("--segments", type=integer, default=64, help="angles the meridian is swept through (default 64)")
    p.set_defaults(func=cmd_export)

    for command in sub.choices.values():            # --debug and -v also after the command's name
        command.add_argument("--debug", action="store_true", default=argparse.SUPPRESS, help="show tracebacks")
        command.add_argument("-v", "--verbose", action="store_true", default=argparse.SUPPRESS,
                             help="log solver progress")
    return parser


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    debug = "--debug" in argv
    try:
        args = build_parser().parse_args(argv)
        check_outputs(args)
        logging.basicConfig(level=logging.INFO if args.verbose else logging.WARNING,
                            format="%(levelname)s %(name)s: %(message)s")
        with sigterm_as_interrupt():                   # kill PID ends a run as Ctrl-C does: exit 130
            return args.func(args)
    except (SnapmemError, SolverError) as exc:
        if debug:
            raise
        print(f"snapmem: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("snapmem: interrupted", file=sys.stderr)
        return 130
    except SystemError as exc:              # Ctrl-C inside a compiled kernel comes back as SystemError
        if not isinstance(exc.__cause__ or exc.__context__, KeyboardInterrupt) or debug:
            raise
        print("snapmem: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:                 # output piped into head and closed: not an error
        sys.stderr.close()
        return 0


def run() -> None:
    """The ``snapmem`` command: :func:`main`, then a quick exit.

    Freeing a process's modules at exit (numba's compiled code and LLVM among them) takes about
    0.2 s of a 0.9 s ``snapmem simulate torus_snap``. Every output is written and closed by the
    time :func:`main` returns, so the process ends at once instead, after flushing its streams and
    running its exit handlers (logging, process pools, the first-use background compile)."""
    code = main()
    atexit._run_exitfuncs()
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError):          # closed, or a pipe its reader closed
            pass
    os._exit(int(code or 0))


if __name__ == "__main__":
    run()
