"""The branch commands of ``snapmem``: ``trace`` (with ``--switch``, ``--restart`` and
``--sensitivity``), ``fold`` (with ``--points``) and ``hysteresis``."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import snapmem._lazy as _lazy

pd = _lazy.module("pandas")  # imported at first use (start-up)

from snapmem.catalog.loads import loads_needed, same_load
from snapmem.catalog.scenes import get_spec
from snapmem.continuation import CONTROLS
from snapmem.errors import SnapmemError, SolverError, check_int, check_real
from snapmem.io.interrupts import HeldInterrupts
from snapmem.io.progress import Progress
from snapmem.io.table import stored
from snapmem.model.parameters import check_memory
from snapmem.sweeps.grid import parse_axis

from snapmem.commands.common import parse_sets, parse_until


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
    from snapmem.continuation import ContinuationOptions, Outcome, trace
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
    # the tables as the tracer left them (rows, until something reads them as DataFrames): writing
    # and printing them needs no pandas
    table, points = stored(branch, "table"), stored(branch, "points")
    with OutputSet() as outputs:                      # all of them or none; a signal waits for the set
        if args.out:
            outputs.table(table, args.out, meta)
            branch.save(outputs.stage(files["--out's states"][0]))
        if args.points:
            outputs.table(points, args.points, meta)
        if args.plot:
            from snapmem.viz.plotting import plot_branch
            x = args.x or next(iter(scene.probes), "u_max")
            plot_branch(branch.table, x, control if control != "volume" else "pressure", path=outputs.stage(args.plot),
                        title=f"{scene.name}: {branch.status}", control=control,
                        si=scene.mu != 1.0)
    print(f"status: {branch.status}")
    print(f"points: {len(table)}  steps: {branch.stats['steps']}  rejected: {branch.stats['rejected']}  "
          f"newton_iterations: {branch.stats['newton_iterations']}")
    for _, row in points.iterrows():
        print(f"{row['kind']}: {control if control != 'volume' else 'pressure'} = "
              f"{row['control'] if control != 'volume' else row['pressure']:.10g}  u_max = {row['u_max']:.6g}  "
              f"stretch_max = {row['stretch_max']:.6g}  located = {row['located']}")
    if points.empty:
        print("no critical points")
    for column in (c for c in points.columns if c.startswith(f"d{control}_d")):
        print(f"{column}: " + ", ".join(f"{v:.6g}" for v in points[column]))
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
              f"starts at {control} = {child.states[0].lam:.10g}, points: {len(child.table)}"
              + ("; mirrored: the exchange image of the other half (identical membranes), not computed"
                 if child.stats.get("mirror_of") else ""))
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
    if same_load(args.control, name):
        raise SnapmemError(f"--vary {name} with --control {args.control}: the control sets {name} at every point, "
                           f"so every value would give the same limit; vary another parameter (e.g. E_hat with "
                           f"--control pressure, or a geometry or material parameter)")
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
    table = _named_after(table, name, args.control)
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


def _named_after(table, name: str, control: str):
    """A fold table's columns as the CSV has them: ``value`` named after the varied parameter,
    ``limit`` as ``<control>_limit``. A varied load (E_hat, voltage, or pressure beside another
    control) is also a measure of each point, with the same values: its column once."""
    return table.drop(columns=[name], errors="ignore").rename(columns={"value": name, "limit": f"{control}_limit"})


def _fold_points(scene_at, values, folds, args, name, params) -> None:
    """``fold --points SPECIAL.csv``: the cusps (CP) and turning points (TP) of the fold curve,
    a column named after the varied parameter holding its value."""
    from snapmem.continuation.folds import fold_special_points
    from snapmem.io.results import write_table
    special, iterations = fold_special_points(scene_at, values, folds, args.control)
    special = _named_after(special, name, args.control)
    write_table(special, args.points, {"command": "fold --points", "scene": args.scene, "parameters": params,
                                       "vary": name, "control": args.control, "newton_iterations": iterations})
    for _, row in special.iterrows():
        print(f"{row['kind']}: {name} = {row[name]:.8g}  {args.control}_limit = {row[f'{args.control}_limit']:.8g}  "
              f"stretch_max = {row['stretch_max']:.6g}")
    if special.empty:
        print("no cusp or turning point of the fold curve in this range")



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


