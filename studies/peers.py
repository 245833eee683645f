"""Peers: snapmem against the classical scipy ODE shooting approach on the same curves, at equal error.

    python studies/peers.py [--quick] [--repeats 5] [--out results/peers.csv]

Two curves, each computed over the same range by every method in the same run:

* plate (R = 7.5, H = 0.5, Mooney-Rivlin c1 = 0.4, c2 = 0.1): p_hat from rest to 0.08
  against the apex deflection;
* torus (Rb = 10, Rs = 2, H = 0.1, Mooney-Rivlin c1 = 0.4375, c2 = 0.0625): p_hat against the
  outer radius from 12.05 to 17.4, through the limit point (p_hat = 0.04091 at r_o = 15.54).

What each method computes:

* ``ode``: ``snapmem.reference.membrane_ode`` (solve_ivp DOP853 + root finders) at relative tolerance rtol
  (setting): 30 points, continuation in the apex stretch (plate, from 1.002 to its value at
  p_hat = 0.08) or the outer radius (torus), each point's pressure from the secant prediction of
  the two before. No stability.
* ``snapmem_path``: ``snapmem.reference.paths`` on N nodes (setting), the same 30 points: the plate at the
  pressures of the ODE's 30 apex stretches (on the reference curve), one Newton solve each
  (``load_path``); the torus at the same 30 outer radii, the pressure the unknown
  (``coordinate_path``, from the state at p_hat = 0.005 as the ODE seeds its continuation).
  No stability.
* ``snapmem_richardson``: ``snapmem_path`` on two or three meshes (``meshes``; each twice as
  fine) and Richardson's extrapolation (``snapmem.reference.paths.extrapolate``) of the plate's
  deflection at each pressure (two meshes: h^2; three: h^2 and h^2 log h, the apex's error,
  whose observed order rises from 1.82 to 1.87 on 25 to 769 nodes) or the torus's pressure at each outer radius
  (h^2; h^4). Timed as a whole (every mesh).
* ``snapmem``: ``snapmem.continuation.tracer.trace`` on N nodes: pseudo-arclength in pressure with its
  own points (17 to 36 of them) and the stability of every point (inertia, eigenvalues nearest
  zero), the limit point located. More work than the ODE does.

Error of a curve: the largest |p - p_ref(shape)| over its points, divided by the range's
pressure scale (0.08 for the plate, the limit pressure for the torus), where p_ref is a cubic
spline through a converged reference (the ODE at rtol = 1e-13 on 241 points graded towards the
start; the run prints a bound on its interpolation error) and the shape is the apex deflection
(plate) or the outer radius (torus), both monotone along the branch. Every setting is run
(``table = run``, median of ``--repeats``) until its error is below a third of the smallest
target. For each error target and each snapmem method, the cheapest snapmem setting and the
cheapest ODE setting that meet it are then timed again, interleaved (round-robin over all the
chosen settings, ``--repeats`` rounds), and the ratio of the medians reported
(``table = equal_error``).
"""

from __future__ import annotations

import argparse
import os
import time

import numpy as np
import pandas as pd
from scipy.interpolate import CubicSpline

from snapmem import build_scene, equilibrium, solve
from snapmem.continuation.tracer import trace
from snapmem.reference.membrane_ode import ODEOptions, PlateODE, TorusODE
from snapmem.reference.paths import coordinate_path, extrapolate, load_path
from snapmem.io.results import write_table
from snapmem.threads import blas_single_thread

P_END, R_FIRST, R_END, M_POINTS, LAM_FIRST = 0.08, 12.05, 17.4, 30, 1.002
TORUS_SEED = 0.005                      # the ODE's seed pressure mu H / (20 Rs), below r_o = 12.05
TRACE_NODES = (25, 50, 100, 200, 400, 800, 1600, 3200)
PATH_NODES = {"plate": (13, 25, 49, 97, 193, 385, 769, 1537, 3073),   # the mesh size halves
              "torus": (12, 24, 48, 96, 192, 384, 768, 1536, 3072)}
RTOLS = (1e-3, 1e-4, 1e-5, 1e-6, 1e-7, 1e-8, 1e-9, 1e-10)
SNAPMEM_METHODS = ("snapmem", "snapmem_path", "snapmem_richardson")


def ode_options(rtol: float) -> ODEOptions:
    """Shooting options at one accuracy level: tolerances and pole offset scaled together."""
    return ODEOptions(rtol=rtol, atol=1e-2 * rtol, pole_offset=min(1e-2, np.sqrt(rtol)), xtol=1e-2 * rtol)


def plate_apex_range(options: ODEOptions = ODEOptions()):
    return LAM_FIRST, PlateODE(options=options).at_pressure(P_END).measures["apex_stretch"]


def ode_controls(curve: str, points: int, lam_end: float, graded: bool = False) -> np.ndarray:
    """The ODE's continuation parameter at its points: apex stretch (plate) or outer radius (torus)."""
    u = np.linspace(0.0, 1.0, points) ** (2 if graded else 1)
    return LAM_FIRST + (lam_end - LAM_FIRST) * u if curve == "plate" else R_FIRST + (R_END - R_FIRST) * u


def ode_branch(curve: str, rtol: float, points: int, lam_end: float, graded: bool = False):
    """(control, shape, p) arrays of the ODE approach's curve (``graded``: points dense at the start)."""
    opt, controls = ode_options(rtol), ode_controls(curve, points, lam_end, graded)
    if curve == "plate":
        rows = PlateODE(options=opt).branch(controls)
        return controls, np.array([r[2] for r in rows]), np.array([r[1] for r in rows])
    rows = TorusODE(options=opt).branch(controls)
    return controls, np.array([r[0] for r in rows]), np.array([r[2] for r in rows])


def ode_curve(curve: str, rtol: float, points: int, lam_end: float):
    return ode_branch(curve, rtol, points, lam_end)[1:]


def trace_curve(curve: str, nodes: int):
    """(shape, p) arrays of snapmem's traced curve (the torus starts from its state at p = 0.005)."""
    if curve == "plate":
        table = trace(build_scene("plate", nodes=nodes), "pressure", until={"pressure": P_END}).table
        return table["deflection"].to_numpy(), table["pressure"].to_numpy()
    scene = build_scene("torus", nodes=nodes)
    start = equilibrium(scene, {"pressure": TORUS_SEED})
    table = trace(scene, "pressure", until={"outer_radius": R_END}, start=(start.q, start.loads)).table
    return table["outer_radius"].to_numpy(), table["pressure"].to_numpy()


def path_quantity(curve: str, nodes: int, points: np.ndarray):
    """(mesh size, the quantity extrapolated) of one snapmem path: the plate's deflections at the
    pressures ``points``, or the torus's pressures at the outer radii ``points``."""
    scene = build_scene(curve, nodes=nodes)
    h = scene.meridian.size / scene.meridian.edges.shape[0]
    if curve == "plate":
        path = load_path(scene, points)
        deflection = scene.probes["deflection"]
        return h, np.array([deflection(q) for q in path.q])
    seed = solve(scene, {"pressure": TORUS_SEED})
    return h, coordinate_path(scene, 0, points, (seed.q, seed.loads)).loads


def path_curve(curve: str, meshes: tuple, points: np.ndarray):
    """(shape, p) of snapmem's path on one mesh, or extrapolated from two or three."""
    with blas_single_thread():
        sizes, values = zip(*(path_quantity(curve, n, points) for n in meshes))
    value = values[0] if len(meshes) == 1 else extrapolate(sizes, values, log_term=curve == "plate")
    return (value, points) if curve == "plate" else (points, value)


def reference(curve: str, lam_end: float, points: int = 241):
    """Cubic splines p_ref(shape) and p_ref(control) through the converged ODE curve, its shape
    range, and its own interpolation error (the spline through every other point against the
    points left out)."""
    control, shape, p = ode_branch(curve, 1e-13, points, lam_end, graded=True)
    half = CubicSpline(shape[::2], p[::2])
    spline_error = float(np.max(np.abs(half(shape[1::2]) - p[1::2])))
    return CubicSpline(shape, p), CubicSpline(control, p), (shape[0], shape[-1]), spline_error


def curve_error(shape, p, ref, span, scale) -> float:
    inside = (shape >= span[0]) & (shape <= span[1])
    return float(np.max(np.abs(p[inside] - ref(shape[inside])))) / scale


def timed(fn, repeats: int):
    """(median, min) wall time [s] of ``repeats`` calls, and the last result."""
    times, out = [], None
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t0)
    return float(np.median(times)), float(np.min(times)), out


def sweep(curve, method, settings, fn, ref, span, scale, repeats, floor):
    """Time and measure every setting (cheap to accurate) until the error is below ``floor``."""
    rows = []
    for setting in settings:
        seconds, fastest, (shape, p) = timed(lambda: fn(setting), repeats)
        err = curve_error(shape, p, ref, span, scale)
        meshes = "/".join(map(str, setting)) if isinstance(setting, tuple) else ""
        rows.append({"table": "run", "curve": curve, "method": method,
                     "setting": setting[-1] if isinstance(setting, tuple) else setting, "meshes": meshes,
                     "points": int(np.sum((shape >= span[0]) & (shape <= span[1]))), "error": err,
                     "seconds": seconds, "seconds_min": fastest})
        print(f"  {curve:5s} {method:18s} {meshes or setting:>12}  error {err:.2e}  {seconds:8.4f} s", flush=True)
        if err < floor:
            break
    return rows


def interleaved(fns: dict, repeats: int) -> dict:
    """Median wall time [s] of each function, timed round-robin: ``repeats`` rounds of one call each."""
    times = {key: [] for key in fns}
    for _ in range(repeats):
        for key, fn in fns.items():
            t0 = time.perf_counter()
            fn()
            times[key].append(time.perf_counter() - t0)
    return {key: float(np.median(t)) for key, t in times.items()}


def methods(curve: str, lam_end: float, ref_of_control) -> dict:
    """method -> (settings, cheap to accurate; function of a setting returning (shape, p))."""
    controls = ode_controls(curve, M_POINTS, lam_end)
    points = ref_of_control(controls) if curve == "plate" else controls       # the ODE's 30 points
    nodes = PATH_NODES[curve]
    return {
        "snapmem": (TRACE_NODES, lambda n: trace_curve(curve, n)),
        "snapmem_path": (nodes, lambda n: path_curve(curve, (n,), points)),
        "snapmem_richardson": ([nodes[i:i + 2] for i in range(len(nodes) - 1)]
                               + [nodes[i:i + 3] for i in range(len(nodes) - 2)],
                               lambda meshes: path_curve(curve, meshes, points)),
        "ode": (RTOLS, lambda rtol: ode_curve(curve, rtol, M_POINTS, lam_end)),
    }


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="error targets 1e-3, 1e-4 only, 1 repeat")
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--out", default="results/peers.csv")
    args = parser.parse_args(argv)
    repeats = 1 if args.quick else args.repeats
    targets = (1e-3, 1e-4) if args.quick else (1e-3, 1e-4, 1e-5, 1e-6)
    trace_curve("plate", 21)                           # warm-up: imports, numba caches
    lam_end = plate_apex_range()[1]
    rows, meta, runners = [], {}, {}
    for curve in ("plate", "torus"):
        ref, ref_of_control, span, spline_error = reference(curve, lam_end)
        scale = P_END if curve == "plate" else float(np.max(ref(np.linspace(*span, 2001))))
        meta[f"{curve}_reference_error_bound"] = spline_error / scale      # of the half-density spline
        print(f"{curve}: reference spline error (half density) {spline_error / scale:.1e}", flush=True)
        floor = min(targets) / 3
        for method, (settings, fn) in methods(curve, lam_end, ref_of_control).items():
            families = [[s for s in settings if len(s) == k] for k in (2, 3)] if method == "snapmem_richardson" \
                else [settings]                          # two meshes, then three, each until the floor
            for family in families:
                rows += sweep(curve, method, family, fn, ref, span, scale, repeats, floor)
            runners[(curve, method)] = fn
    runs = pd.DataFrame(rows)

    def setting_of(row):
        return tuple(int(n) for n in row.meshes.split("/")) if row.meshes else row.setting

    chosen = []                                        # (curve, target, snapmem method, its row, the ODE's row)
    for curve in ("plate", "torus"):
        for target in targets:
            ok = runs[(runs.curve == curve) & (runs.error <= target)]
            best = {m: ok[ok.method == m].sort_values("seconds").head(1) for m in SNAPMEM_METHODS + ("ode",)}
            o = None if best["ode"].empty else best["ode"].iloc[0]
            for method in SNAPMEM_METHODS:
                chosen.append((curve, target, method, None if best[method].empty else best[method].iloc[0], o))
    fns = {}
    for curve, _, method, s, o in chosen:
        for m, row in ((method, s), ("ode", o)):
            if row is not None:
                key = (curve, m, row.meshes or row.setting)
                fns[key] = (lambda fn=runners[(curve, m)], x=setting_of(row): fn(x))
    print(f"interleaved timing of the {len(fns)} chosen settings, {repeats} rounds", flush=True)
    medians = interleaved(fns, repeats)
    summary = []
    for curve, target, method, s, o in chosen:
        s_sec = None if s is None else medians[(curve, method, s.meshes or s.setting)]
        o_sec = None if o is None else medians[(curve, "ode", o.setting)]
        summary.append({"table": "equal_error", "curve": curve, "target": target, "snapmem_method": method,
                        "snapmem_nodes": None if s is None else int(s.setting),
                        "snapmem_meshes": None if s is None else (s.meshes or str(int(s.setting))),
                        "snapmem_error": None if s is None else s.error, "snapmem_seconds": s_sec,
                        "ode_rtol": None if o is None else o.setting,
                        "ode_error": None if o is None else o.error, "ode_seconds": o_sec,
                        "ratio_ode_over_snapmem": None if s is None or o is None else o_sec / s_sec})
    table = pd.concat([runs, pd.DataFrame(summary)], ignore_index=True)
    write_table(table, args.out, {"study": "peers", "repeats": repeats, "targets": targets,
                                  "plate": {"R": 7.5, "H": 0.5, "c1": 0.4, "c2": 0.1, "p_end": P_END},
                                  "torus": {"Rb": 10, "Rs": 2, "H": 0.1, "c1": 0.4375, "c2": 0.0625,
                                            "r_o_range": [R_FIRST, R_END], "seed_pressure": TORUS_SEED},
                                  "ode_points": M_POINTS, "path_points": M_POINTS,
                                  "reference": "ODE rtol 1e-13, 241 graded points, cubic spline",
                                  "equal_error_timing": "interleaved round-robin, median",
                                  "OPENBLAS_NUM_THREADS": os.environ.get("OPENBLAS_NUM_THREADS"),
                                  "date": time.strftime("%Y-%m-%d %H:%M:%S"), **meta})
    with pd.option_context("display.width", 250, "display.float_format", "{:.3g}".format):
        print(pd.DataFrame(summary).drop(columns="table").to_string(index=False))
    return table


if __name__ == "__main__":
    main()
