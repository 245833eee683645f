"""The ``snapmem`` command: a thin layer over the package.

Every command builds a scene from ``--set NAME=VALUE`` pairs and calls one driver. Bad input
is one line on stderr and exit code 2; ``--debug`` shows the traceback instead.
"""

from __future__ import annotations

import argparse
import logging
import sys
from pathlib import Path

import numpy as np
import pandas as pd

from snapmem.catalog.loads import loads_needed
from snapmem.catalog.scenes import SCENES, get_spec
from snapmem.continuation import CONTROLS
from snapmem.dynamics import SCHEMES
from snapmem.errors import SnapmemError, SolverError
from snapmem.io.interrupts import HeldInterrupts, sigterm_as_interrupt
from snapmem.io.progress import Progress, bar
from snapmem.sweeps.grid import parse_axis, parse_value

#: The controls that move a load (fold curves and hysteresis loops; not volume).
LOAD_CONTROLS = tuple(control for control in CONTROLS if control != "volume")


class _Parser(argparse.ArgumentParser):
    def error(self, message):          # one line, exit 2, like every other bad input
        raise SnapmemError(message)


def parse_sets(pairs: list[str]) -> dict:
    """``["R=10", "nodes=51"]`` -> ``{"R": "10", "nodes": "51"}`` (values checked by the scene)."""
    out = {}
    for pair in pairs or []:
        name, sep, value = pair.partition("=")
        if not sep or not name.strip() or not value.strip():
            raise SnapmemError(f"--set {pair!r}: must be NAME=VALUE, e.g. --set nodes=201")
        out[name.strip()] = value.strip()
    return out


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
    params = parse_sets(args.set)
    if args.pressure is not None:
        params["pressure"] = args.pressure
    scene = get_spec(args.scene).build(**params)
    eq = equilibrium(scene)
    for name, value in {"pressure": scene.resolve_loads(eq.loads)["pressure"], **eq.measures()}.items():
        print(f"{name}: {value:.10g}" if isinstance(value, float) else f"{name}: {value}")
    for line in eq.report.lines():
        print(line)
    return 0 if eq.converged else 1


def parse_until(pairs: list[str]) -> dict:
    """``["stretch=4"]`` -> ``{"stretch": 4.0}``."""
    out = {}
    for name, value in parse_sets(pairs).items():
        try:
            out[name] = float(value)
        except ValueError:
            raise SnapmemError(f"--until {name}={value!r}: the value must be a number") from None
        if not np.isfinite(out[name]):
            raise SnapmemError(f"--until {name}={value!r}: the value must be a finite number (a target the "
                               "branch can reach)")
    return out


def trace_outputs(out, points, plot) -> dict:
    """The files ``snapmem trace`` writes, by option; SnapmemError if two are the same file."""
    from snapmem.io.results import distinct_outputs, sidecar
    files = {"--out": [out], "--out's parameters": [out and sidecar(out)],
             "--out's states": [out and Path(out).with_suffix(".npz")],
             "--points": [points], "--points' parameters": [points and sidecar(points)], "--plot": [plot]}
    distinct_outputs(files)
    return files


def _stop_when_interrupted(held):
    """A trace event that ends the branch after the step on which SIGINT or SIGTERM came
    (``held``: a :class:`~snapmem.io.interrupts.HeldInterrupts`), so the branch so far is kept."""
    from snapmem.continuation import Outcome
    from snapmem.continuation.events import Event, Found, Stop

    class Interrupted(Event):
        def check(self, step):
            if held.received is not None:
                return Found(stop=Stop(Outcome.STOPPED, f"interrupted after {len(step.points)} points"))
            return None

    return Interrupted()


def cmd_trace(args) -> int:
    from snapmem.continuation import ContinuationOptions, Outcome, load_points, trace
    from snapmem.io.results import OutputSet
    files = trace_outputs(args.out, args.points, args.plot)
    params = parse_sets(args.set)
    control = args.control
    scene = get_spec(args.scene).build(loads_needed(control), **params)
    until = parse_until(args.until) if args.until else {"stretch_max": 4.0}
    options = ContinuationOptions(max_steps=args.max_steps, stop_at_first_limit=args.stop_at_first_limit,
                                  save_at=tuple(float(v) for v in args.save_at or ()))
    start = None
    if args.restart:
        saved = load_points(args.restart)
        index = args.start_index
        if not -len(saved["lam"]) <= index < len(saved["lam"]):
            raise SnapmemError(f"--start-index {index}: the file has {len(saved['lam'])} points")
        loads = dict(scene.loads)
        if saved["meta"]["control"] in ("pressure", "voltage"):
            loads[saved["meta"]["control"]] = float(saved["lam"][index])
        elif saved["meta"]["control"] == "E_hat":
            loads["voltage"] = float(saved["lam"][index]) * scene.thickness * (scene.mu / scene.permittivity) ** 0.5
        elif saved["meta"]["control"] == "volume":
            loads["pressure"] = float(saved["x"][index][-1])
        start = (saved["q"][index], loads)
    display = Progress(file_interval=None)
    counter = {"n": 0}

    def progress(point, row):
        counter["n"] += 1
        display.show(f"trace {scene.name}: step {counter['n']}  {control} = {point.lam:.6g} "
                     f"[{display.elapsed:.1f} s]")

    with HeldInterrupts() as held:                     # Ctrl-C / SIGTERM end the branch, which is kept
        branch = trace(scene, control, until=until, options=options, start=start, progress=progress,
                       events=[_stop_when_interrupted(held)])
    display.close()
    meta = {"command": "trace", "scene": scene.name, "parameters": scene.parameters, "control": control,
            "until": until, "status": branch.status, "stats": branch.stats}
    with OutputSet() as outputs:                      # all of them or none; a signal waits for the set
        if args.out:
            outputs.table(branch.table, args.out, meta)
            branch.save(outputs.stage(files["--out's states"][0]))
        if args.points:
            outputs.table(branch.points, args.points, meta)
        if args.plot:
            from snapmem.viz.plotting import plot_branch
            x = args.x or next(iter(scene.probes), "u_max")
            plot_branch(branch.table, x, control if control != "volume" else "pressure", path=outputs.stage(args.plot),
                        title=f"{scene.name}: {branch.status}")
    print(f"status: {branch.status}")
    print(f"points: {len(branch.table)}  steps: {branch.stats['steps']}  rejected: {branch.stats['rejected']}  "
          f"newton_iterations: {branch.stats['newton_iterations']}")
    for _, row in branch.points.iterrows():
        print(f"{row['kind']}: {control if control != 'volume' else 'pressure'} = "
              f"{row['control'] if control != 'volume' else row['pressure']:.10g}  u_max = {row['u_max']:.6g}  "
              f"stretch_max = {row['stretch_max']:.6g}  located = {row['located']}")
    if branch.points.empty:
        print("no critical points")
    if held.received is not None:
        raise KeyboardInterrupt                        # exit 130, after the branch so far is written
    done = branch.outcome is Outcome.TARGET_REACHED or (branch.outcome is Outcome.FIRST_LIMIT
                                                         and args.stop_at_first_limit)
    if not done:                                       # exit 1: distinguishable from success
        print(f"target not reached: {', '.join(f'{k} = {v:g}' for k, v in until.items())} ({branch.status})")
    return 0 if done else 1


def cmd_fold(args) -> int:
    from snapmem.continuation.folds import fold_curve
    from snapmem.io.results import OutputSet, distinct_outputs, sidecar
    distinct_outputs({"--out": [args.out], "--out's parameters": [args.out and sidecar(args.out)], "--plot": [args.plot]})
    params = parse_sets(args.set)
    name, values = parse_axis(args.vary, option="--vary", number=True)
    values = [float(v) for v in values]
    spec = get_spec(args.scene)
    with_loads = loads_needed(args.control, name)
    spec.resolve(**{**params, name: values[0]})          # unknown names fail before any work
    display = Progress(file_interval=None)
    table = fold_curve(lambda v: spec.build(with_loads, **{**params, name: v}), values, args.control,
                       progress=lambda i, n: display.show(f"fold {args.scene}: {i}/{n} values of {name} "
                                                          f"[{display.elapsed:.1f} s]"))
    display.close()
    table = table.rename(columns={"value": name, "limit": f"{args.control}_limit"})
    meta = {"command": "fold", "scene": args.scene, "parameters": params, "vary": name, "control": args.control}
    with OutputSet() as outputs:
        if args.out:
            outputs.table(table, args.out, meta)
        if args.plot:
            from snapmem.viz.plotting import plot_xy
            plot_xy(table, name, f"{args.control}_limit", outputs.stage(args.plot), title=f"{args.scene}: limit points")
    with pd.option_context("display.width", 200, "display.max_columns", 12):
        print(table[[name, f"{args.control}_limit", "exists", "method", "iterations", "u_max"]].to_string(index=False))
    return 0


def cmd_sweep(args) -> int:
    from snapmem.sweeps.sweep import make_job, sweep
    fixed = parse_sets(args.set)
    if args.pressure is not None:
        fixed["pressure"] = args.pressure
    axes = {}
    for text in args.grid:
        name, values = parse_axis(text)
        if name in axes:
            raise SnapmemError(f"--grid {name!r}: given twice")
        axes[name] = values
    job = make_job(args.job, args.scene, fixed, axes)
    workers, timeout = (None if text is None else parse_value(name, text, number=True)
                        for name, text in (("workers", args.workers), ("timeout", args.timeout)))
    table = sweep(job, axes, args.out, workers=workers, scheduler=args.scheduler, timeout=timeout,
                  progress=not args.quiet)
    counts = table["status"].value_counts()
    print(f"{args.out}: {len(table)} rows; " + ", ".join(f"{s} {n}" for s, n in sorted(counts.items())))
    return 0


def cmd_simulate(args) -> int:
    import dataclasses
    from snapmem.catalog.robots import EXPERIMENTS, events, experiment
    from snapmem.dynamics.driver import simulate
    from snapmem.io.results import OutputSet
    out = None
    if args.out:                                       # the name Trajectory.save writes ('.npz' appended if missing)
        out = Path(args.out) if Path(args.out).suffix == ".npz" else Path(args.out + ".npz")
    params = parse_sets(args.set)
    ex = experiment(args.scene, **params)
    t_end = ex.t_end if args.t_end is None else float(args.t_end)
    changes = {k: v for k, v in (("scheme", args.scheme), ("tol", args.tol)) if v is not None}
    if args.frames:
        changes["save_interval"] = t_end / args.frames
    options = dataclasses.replace(ex.options, **changes)
    display = Progress(enabled=not args.quiet)

    def progress(t, t_end):
        done = min(1.0, t / t_end) if t_end > 0 else 1.0
        display.show(f"[{bar(done, 40)}] t = {t:9.4f} / {t_end:g} s  wall {display.elapsed:6.1f} s",
                     force=t >= t_end)

    try:
        traj = simulate(ex.scene, ex.loads, t_end, rho=ex.rho, damping=ex.damping, q0=ex.q0, v0=ex.v0,
                        options=options, damp_bodies=ex.damp_bodies, progress=None if args.quiet else progress)
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
    if args.scene in EXPERIMENTS and meta["status"] == "completed":
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
    traj = Trajectory.load(args.trajectory)
    out = animate(traj, args.out, frames=args.frames, fps=args.fps)
    print(f"wrote: {out}")
    return 0


def cmd_hysteresis(args) -> int:
    from snapmem.continuation.hysteresis import hysteresis
    from snapmem.io.results import OutputSet, distinct_outputs, sidecar
    snaps_path = str(Path(args.out).with_suffix("")) + "_snaps.csv" if args.out else None
    distinct_outputs({"--out": [args.out], "--out's parameters": [args.out and sidecar(args.out)],
                      "--out's snaps": [snaps_path], "--out's snaps' parameters": [snaps_path and sidecar(snaps_path)],
                      "--plot": [args.plot]})
    params = parse_sets(args.set)
    scene = get_spec(args.scene).build(loads_needed(args.control), **params)
    loop = hysteresis(scene, args.control, peak=args.peak)
    meta = {"command": "hysteresis", "scene": scene.name, "parameters": scene.parameters, "control": args.control,
            "status": loop.status}
    with OutputSet() as outputs:
        if args.out:
            outputs.table(loop.table, args.out, meta)
            outputs.table(loop.snaps, snaps_path, meta)
        if args.plot:
            from snapmem.viz.plotting import plot_hysteresis
            x = next(iter(scene.probes), "u_max")
            plot_hysteresis(loop.table, loop.snaps, x, args.control, outputs.stage(args.plot),
                            title=f"{scene.name}: hysteresis ({loop.status})")
    print(f"status: {loop.status}")
    for _, row in loop.snaps.iterrows():
        if not row.get("jumped", True):                # a limit point the state did not jump at: no event
            print(f"no {row['event']}: the state did not jump at {args.control} = {row['control_at_limit']:.8g}")
            continue
        print(f"{row['event']}: at {args.control} = {row['control_at_limit']:.8g}, settled at "
              f"{row['control_settled']:.8g}, u_max {row['u_max_before']:.6g} -> {row['u_max_after']:.6g}")
    return 0 if loop.closed else 1


def cmd_bench(args) -> int:
    from snapmem.bench import run
    from snapmem.io.results import write_table
    table = run(quick=args.quick)
    write_table(table, args.out, {"command": "bench", "quick": args.quick})
    with pd.option_context("display.width", 220, "display.max_colwidth", 90):
        print(table.to_string(index=False, float_format=lambda v: f"{v:.4g}"))
    return 0


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(prog="snapmem", description="Snap-through of axisymmetric dielectric-elastomer membranes.")
    parser.add_argument("--debug", action="store_true", help="show tracebacks")
    parser.add_argument("-v", "--verbose", action="store_true", help="log solver progress")
    sub = parser.add_subparsers(dest="command", parser_class=_Parser)
    sub.required = True

    p = sub.add_parser("scenes", help="list scenes with their parameters, defaults and units")
    p.set_defaults(func=cmd_scenes)

    p = sub.add_parser("equilibrium", help="solve one equilibrium, loading from rest")
    p.add_argument("scene")
    p.add_argument("--set", action="append", metavar="NAME=VALUE", help="scene parameter (repeatable)")
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
    p.add_argument("scene")
    p.add_argument("--set", action="append", metavar="NAME=VALUE", help="scene parameter (repeatable)")
    p.add_argument("--control", choices=CONTROLS, default="pressure")
    p.add_argument("--until", action="append", metavar="NAME=VALUE",
                   help="stop when an output reaches a value (default stretch_max=4)")
    p.add_argument("--out", metavar="BRANCH.csv", help="branch table (+ .json parameters, .npz states)")
    p.add_argument("--points", metavar="POINTS.csv", help="critical points table")
    p.add_argument("--plot", metavar="FIG.png", help="plot of the branch")
    p.add_argument("--x", help="column on the plot's x axis (default: the scene's first probe or u_max)")
    p.add_argument("--save-at", type=float, action="append", metavar="VALUE",
                   help="locate a point exactly at this control value (repeatable)")
    p.add_argument("--stop-at-first-limit", action="store_true")
    p.add_argument("--max-steps", type=int, default=2000)
    p.add_argument("--restart", metavar="BRANCH.npz", help="start from a point saved by an earlier trace")
    p.add_argument("--start-index", type=int, default=-1, help="which saved point to restart from (default last)")
    p.set_defaults(func=cmd_trace)

    p = sub.add_parser("fold", help="follow a limit point as a second parameter varies")
    p.add_argument("scene")
    p.add_argument("--vary", required=True, metavar="NAME=START:STOP:COUNT",
                   help="scene parameter to vary, as a range or a list v1,v2,...")
    p.add_argument("--set", action="append", metavar="NAME=VALUE", help="scene parameter (repeatable)")
    p.add_argument("--control", choices=LOAD_CONTROLS, default="pressure")
    p.add_argument("--out", metavar="FOLD.csv")
    p.add_argument("--plot", metavar="FIG.png")
    p.set_defaults(func=cmd_fold)

    p = sub.add_parser("hysteresis", help="up, snap, down, snap back: a hysteresis loop in one call")
    p.add_argument("scene")
    p.add_argument("--set", action="append", metavar="NAME=VALUE", help="scene parameter (repeatable)")
    p.add_argument("--control", choices=LOAD_CONTROLS, default="pressure")
    p.add_argument("--peak", type=float, help="control value reached after the snap (default 1.05 x the limit)")
    p.add_argument("--out", metavar="LOOP.csv", help="the loop's branches (+ LOOP_snaps.csv)")
    p.add_argument("--plot", metavar="FIG.png")
    p.set_defaults(func=cmd_hysteresis)

    p = sub.add_parser("bench", help="benchmarks: Newton against the banded solve, whole jobs, designs per second")
    p.add_argument("--quick", action="store_true", help="small sizes, for a quick check")
    p.add_argument("--out", default="results/benchmark.csv", metavar="BENCH.csv")
    p.set_defaults(func=cmd_bench)

    p = sub.add_parser("simulate", help="simulate a scene in time with its schedule (dynamics, contact)")
    p.add_argument("scene")
    p.add_argument("--set", action="append", metavar="NAME=VALUE", help="scene parameter (repeatable)")
    p.add_argument("--t-end", type=float, help="end time [s] (default: the scene's)")
    p.add_argument("--scheme", choices=SCHEMES, help="time integrator")
    p.add_argument("--tol", type=float, help="local error tolerance per step (fraction of the size)")
    p.add_argument("--frames", type=int, default=0, help="save about this many frames (default: every step)")
    p.add_argument("--out", metavar="TRAJ.npz", help="save the trajectory (compressed, no pickle)")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=cmd_simulate)

    p = sub.add_parser("replay", help="animate a saved trajectory to .gif or .mp4")
    p.add_argument("trajectory", metavar="TRAJ.npz")
    p.add_argument("--out", required=True, metavar="FILE.gif|FILE.mp4")
    p.add_argument("--frames", type=int, default=120)
    p.add_argument("--fps", type=int, default=20)
    p.set_defaults(func=cmd_replay)
    return parser


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    debug = "--debug" in argv
    try:
        args = build_parser().parse_args(argv)
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


if __name__ == "__main__":
    sys.exit(main())
