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
import snapmem._lazy as _lazy

pd = _lazy.module("pandas")  # imported at first use (start-up)

from snapmem.catalog.loads import loads_needed
from snapmem.catalog.scenes import SCENES, get_spec
from snapmem.continuation import CONTROLS
from snapmem.dynamics import SCHEMES
from snapmem.errors import FIGURE_SUFFIXES, SnapmemError, SolverError, check_int, check_output, check_real, parse_number
from snapmem.io.interrupts import HeldInterrupts, sigterm_as_interrupt
from snapmem.io.progress import Progress, bar
from snapmem.model.parameters import check_memory
from snapmem.sweeps.grid import parse_axis, parse_value

#: The controls that move a load (fold curves and hysteresis loops; not volume).
LOAD_CONTROLS = tuple(control for control in CONTROLS if control != "volume")


def real(text: str) -> float:
    """An option's value as a number, typed in ASCII decimal notation (argparse type; see
    :func:`snapmem.errors.parse_number`)."""
    return float(parse_number("value", text))


def integer(text: str) -> int:
    """An option's value as an integer in ASCII digits (argparse type)."""
    value = parse_number("value", text)
    if not isinstance(value, int):
        raise ValueError(text)
    return value


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
        if name.strip() in out:
            raise SnapmemError(f"--set {name.strip()!r}: given twice ({out[name.strip()]!r} and {value.strip()!r}); "
                               "give each parameter once")
        out[name.strip()] = value.strip()
    return out


def merge_option(params: dict, name: str, value, option: str) -> dict:
    """``params`` with ``name`` = ``value`` from its own ``option`` (if given); a ``--set`` of the
    same parameter as well is a conflict, refused rather than resolved by order."""
    if value is None:
        return params
    if name in params:
        raise SnapmemError(f"--set {name}={params[name]} and {option} {value}: set {name} one way, not both")
    return {**params, name: value}


#: Output options of each command and the file endings they take (empty: any).
OUTPUTS = {"trace": {"out": (), "points": (), "plot": FIGURE_SUFFIXES},
           "fold": {"out": (), "plot": FIGURE_SUFFIXES},
           "hysteresis": {"out": (), "plot": FIGURE_SUFFIXES},
           "simulate": {"out": (".npz",)},
           "replay": {"out": (".gif", ".mp4")},
           "bench": {"out": ()},
           "sweep": {"out": ()}}


def check_outputs(args) -> None:
    """Every output path of the command checked before any work (folder exists and is writable,
    not a folder itself, the right ending), so that a run never fails only at its end."""
    for option, suffixes in OUTPUTS.get(args.command, {}).items():
        value = getattr(args, option, None)
        if value is not None:
            check_output(f"--{option}", value, suffixes)


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
    check_memory(f"trace {scene.name}", scene.meridian.nodes, check_int("--max-steps", args.max_steps, minimum=1))
    until = parse_until(args.until) if args.until else {"stretch_max": 4.0}
    options = ContinuationOptions(max_steps=args.max_steps, stop_at_first_limit=args.stop_at_first_limit,
                                  save_at=tuple(check_real("--save-at", v, minimum=-1e30, maximum=1e30)
                                                for v in args.save_at or ()))
    start = None
    if args.restart:
        saved = restart_file(args.restart, scene)
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

    if args.switch:
        return _trace_switch(args, scene, control, until, options)
    with HeldInterrupts() as held:                     # Ctrl-C / SIGTERM end the branch, which is kept
        branch = trace(scene, control, until=until, options=options, start=start, progress=progress,
                       events=[_stop_when_interrupted(held)])
    display.close()
    if args.sensitivity:
        branch.points = _sensitivities(branch, args.scene, params, control, args.sensitivity)
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
                        title=f"{scene.name}: {branch.status}", control=control,
                        si=scene.mu != 1.0)
    print(f"status: {branch.status}")
    print(f"points: {len(branch.table)}  steps: {branch.stats['steps']}  rejected: {branch.stats['rejected']}  "
          f"newton_iterations: {branch.stats['newton_iterations']}")
    for _, row in branch.points.iterrows():
        print(f"{row['kind']}: {control if control != 'volume' else 'pressure'} = "
              f"{row['control'] if control != 'volume' else row['pressure']:.10g}  u_max = {row['u_max']:.6g}  "
              f"stretch_max = {row['stretch_max']:.6g}  located = {row['located']}")
    if branch.points.empty:
        print("no critical points")
    for column in (c for c in branch.points.columns if c.startswith(f"d{control}_d")):
        print(f"{column}: " + ", ".join(f"{v:.6g}" for v in branch.points[column]))
    if held.received is not None:
        raise KeyboardInterrupt                        # exit 130, after the branch so far is written
    done = branch.outcome is Outcome.TARGET_REACHED or (branch.outcome is Outcome.FIRST_LIMIT
                                                         and args.stop_at_first_limit)
    if not done:                                       # exit 1: distinguishable from success
        print(f"target not reached: {', '.join(f'{k} = {v:g}' for k, v in until.items())} ({branch.status})")
    return 0 if done else 1


def _trace_switch(args, scene, control, until, options) -> int:
    """``trace --switch BRANCH.npz:K``: trace the branch bifurcating at row K of the saved
    branch's critical points, both ways; ``--out`` writes the diagram (CSV with a ``branch``
    column, .points.csv, .npz of states, .json sidecar)."""
    from snapmem.continuation import Diagram, Point, load_points
    from snapmem.continuation.switching import switch_at
    path, sep, row = args.switch.rpartition(":")
    if not sep or not path:
        raise SnapmemError(f"--switch {args.switch!r}: must be BRANCH.npz:K, K a row of its points table")
    try:
        k = int(row)
    except ValueError:
        raise SnapmemError(f"--switch {args.switch!r}: K = {row!r} must be an integer") from None
    saved = load_points(path)
    if saved["meta"]["control"] != control:
        raise SnapmemError(f"--switch: the branch was traced in {saved['meta']['control']!r}; "
                           f"use --control {saved['meta']['control']}")
    critical = [i for i, kind in enumerate(saved["kind"]) if kind in ("LP", "BP")]
    if not -len(critical) <= k < len(critical):
        raise SnapmemError(f"--switch row {k}: the branch has {len(critical)} critical points")
    i = critical[k]
    if saved["kind"][i] != "BP":
        raise SnapmemError(f"--switch row {k}: the point is {str(saved['kind'][i])!r}, not a BP "
                           f"(BP rows: {[j for j, c in enumerate(critical) if saved['kind'][c] == 'BP']})")
    c = Point(np.asarray(saved["x"][i], float), float(saved["lam"][i]), tangent=np.asarray(saved["tangent"][i], float))
    halves = switch_at(scene, control, c, until=until, options=options)
    diagram = Diagram()
    for sign, child in halves:
        diagram.add(child)
        print(f"branch {len(diagram.branches) - 1} (direction {sign:+d}): {child.status}; "
              f"starts at {control} = {child.states[0].lam:.10g}, points: {len(child.table)}")
        for _, r in child.points.iterrows():
            print(f"    {r['kind']}: {control} = {r['control']:.10g}  stretch_max = {r['stretch_max']:.6g}")
    if not halves:
        raise SolverError(f"--switch: no branch could be started at row {k}")
    if args.out:
        diagram.save(args.out)
    return 0


def restart_file(path, scene) -> dict:
    """The arrays of a branch file for ``trace --restart``, checked against ``scene``: a control
    snapmem knows, finite states of the scene's size (a file saved with another node count is
    refused with both counts)."""
    from snapmem.continuation import load_points
    what = f"--restart {str(path)!r}"
    try:
        saved = load_points(path)
    except SnapmemError:
        raise
    except (ValueError, TypeError) as exc:         # meta that is not JSON
        raise SnapmemError(f"{what}: not a snapmem branch file ({exc})") from None
    meta = saved["meta"]
    if not isinstance(meta, dict) or meta.get("control") not in CONTROLS:
        raise SnapmemError(f"{what}: its meta names no control ({', '.join(CONTROLS)}); not a snapmem branch file")
    size = scene.reference_state().size
    lam, q = np.asarray(saved["lam"]), np.asarray(saved.get("q", np.empty(0)))
    if lam.ndim != 1 or lam.size == 0 or lam.dtype.kind not in "fiu":
        raise SnapmemError(f"{what}: 'lam' must be a non-empty 1D array of numbers (shape {lam.shape})")
    if q.ndim != 2 or q.shape[0] != lam.size or q.dtype.kind not in "fiu":
        raise SnapmemError(f"{what}: 'q' must be {lam.size} states (shape {q.shape})")
    if q.shape[1] != size:
        nodes = scene.meridian.nodes
        raise SnapmemError(f"{what}: saved with {q.shape[1] // 2} nodes; scene {scene.name!r} has {nodes} "
                           f"(set --set nodes={q.shape[1] // 2}, or trace anew)")
    if not (np.all(np.isfinite(lam)) and np.all(np.isfinite(q))):
        raise SnapmemError(f"{what}: has non-finite states")
    return saved


def _sensitivities(branch, scene_name: str, params: dict, control: str, names: str):
    """The points table with d<control>_d<name> columns (``--sensitivity c2,E_hat,...``)."""
    from snapmem.continuation.sensitivity import branch_sensitivities
    spec = get_spec(scene_name)
    with_loads = loads_needed(control)
    wanted = [n.strip() for n in names.split(",") if n.strip()]
    if not wanted:
        raise SnapmemError(f"--sensitivity {names!r}: give parameter names separated by commas, e.g. c2,E_hat")
    return branch_sensitivities(branch, lambda name, v: spec.build(with_loads, **{**params, name: v}), wanted)


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
    scene_at = lambda v: spec.build(with_loads, **{**params, name: v})        # noqa: E731
    table, folds = fold_curve(scene_at, values, args.control, return_folds=True,
                              progress=lambda i, n: display.show(f"fold {args.scene}: {i}/{n} values of {name} "
                                                                 f"[{display.elapsed:.1f} s]"))
    display.close()
    if args.points:
        _fold_points(scene_at, values, folds, args, name, params)
    table = table.rename(columns={"value": name, "limit": f"{args.control}_limit"})
    meta = {"command": "fold", "scene": args.scene, "parameters": params, "vary": name, "control": args.control}
    with OutputSet() as outputs:
        if args.out:
            outputs.table(table, args.out, meta)
        if args.plot:
            from snapmem.viz.plotting import plot_xy
            plot_xy(table, name, f"{args.control}_limit", outputs.stage(args.plot), title=f"{args.scene}: limit points",
                    si=spec.build(with_loads, **{**params, name: values[0]}).mu != 1.0)
    with pd.option_context("display.width", 200, "display.max_columns", 12):
        shown = [c for c in (name, f"{args.control}_limit", "exists", "method", "iterations", "u_max", "status")
                 if c in table.columns]
        print(table[shown].to_string(index=False))
    return 0


def _fold_points(scene_at, values, folds, args, name, params) -> None:
    """``fold --points SPECIAL.csv``: the cusps (CP) and turning points (TP) of the fold curve,
    a column named after the varied parameter holding its value."""
    from snapmem.continuation.folds import fold_special_points
    from snapmem.io.results import write_table
    special, iterations = fold_special_points(scene_at, values, folds, args.control)
    special = special.rename(columns={"value": name, "limit": f"{args.control}_limit"})
    write_table(special, args.points, {"command": "fold --points", "scene": args.scene, "parameters": params,
                                       "vary": name, "control": args.control, "newton_iterations": iterations})
    for _, row in special.iterrows():
        print(f"{row['kind']}: {name} = {row[name]:.8g}  {args.control}_limit = {row[f'{args.control}_limit']:.8g}  "
              f"stretch_max = {row['stretch_max']:.6g}")
    if special.empty:
        print("no cusp or turning point of the fold curve in this range")


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


def cmd_hysteresis(args) -> int:
    from snapmem.continuation.hysteresis import hysteresis
    from snapmem.io.results import OutputSet, distinct_outputs, sidecar
    snaps_path = str(Path(args.out).with_suffix("")) + "_snaps.csv" if args.out else None
    distinct_outputs({"--out": [args.out], "--out's parameters": [args.out and sidecar(args.out)],
                      "--out's snaps": [snaps_path], "--out's snaps' parameters": [snaps_path and sidecar(snaps_path)],
                      "--plot": [args.plot]})
    params = parse_sets(args.set)
    scene = get_spec(args.scene).build(loads_needed(args.control), **params)
    peak = None if args.peak is None else check_real("--peak", args.peak, minimum=-1e30, maximum=1e30)
    loop = hysteresis(scene, args.control, peak=peak)
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
                            title=f"{scene.name}: hysteresis ({loop.status})", si=scene.mu != 1.0)
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
    p.add_argument("scene")
    p.add_argument("--set", action="append", metavar="NAME=VALUE", help="scene parameter (repeatable)")
    p.add_argument("--control", choices=LOAD_CONTROLS, default="pressure")
    p.add_argument("--peak", type=real, help="control value reached after the snap (default 1.05 x the limit)")
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
    p.add_argument("--t-end", type=real, help="end time [s] (default: the scene's)")
    p.add_argument("--scheme", choices=SCHEMES, help="time integrator")
    p.add_argument("--tol", type=real, help="local error tolerance per step (fraction of the size)")
    p.add_argument("--frames", type=integer, default=0, help="save about this many frames (default: every step)")
    p.add_argument("--out", metavar="TRAJ.npz", help="save the trajectory (compressed, no pickle)")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
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


if __name__ == "__main__":
    sys.exit(main())
