"""Peers: snapmem against the classical scipy ODE shooting approach on the same curves, at equal error.

    OPENBLAS_NUM_THREADS=1 python studies/peers.py [--quick] [--repeats 3] [--out results/peers.csv]

(On this 2-core machine a multithreaded OpenBLAS makes numpy's QR of the n x 6 blocks in
snapmem's eigenvalue check about 50 times slower from n ~ 2000 up; one thread is faster.)

Two curves, each traced over the same range by both methods in the same run:

* plate (R = 7.5, H = 0.5, Mooney-Rivlin c1 = 0.4, c2 = 0.1): p_hat from rest to 0.08
  against the apex deflection;
* torus (Rb = 10, Rs = 2, H = 0.1, Mooney-Rivlin c1 = 0.4375, c2 = 0.0625): p_hat against the
  outer radius from 12.05 to 17.4, through the limit point (p_hat = 0.04091 at r_o = 15.54).

snapmem: ``snapmem.continuation.trace`` (pseudo-arclength in pressure, stability at every
point) on N nodes. The ODE approach: ``snapmem.membrane_ode`` (solve_ivp DOP853 + root finders,
continuation in the apex stretch or the outer radius, 30 points) at relative tolerance rtol.

Error of a traced curve: the largest |p - p_ref(shape)| over its points, divided by the range's
pressure scale (0.08 for the plate, the limit pressure for the torus), where p_ref is a cubic
spline through a converged reference (the ODE at rtol = 1e-13 on 241 points graded towards
the start; the run prints a bound on its interpolation error) and the shape is the apex
deflection (plate) or the outer radius (torus), both
monotone along the branch. For each error target the cheapest setting of each method that
meets it is timed (median of ``--repeats`` runs) and the ratio of the two times reported.
Rows with ``table = run`` are every measured setting; ``table = equal_error`` the comparison.
"""

from __future__ import annotations

import argparse
import os
import time

import numpy as np
import pandas as pd
from scipy.interpolate import CubicSpline

from snapmem import build_scene, equilibrium
from snapmem.continuation import trace
from snapmem.membrane_ode import ODEOptions, PlateODE, TorusODE
from snapmem.results import write_table

P_END, R_FIRST, R_END, M_POINTS = 0.08, 12.05, 17.4, 30


def ode_options(rtol: float) -> ODEOptions:
    """Shooting options at one accuracy level: tolerances and pole offset scaled together."""
    return ODEOptions(rtol=rtol, atol=1e-2 * rtol, pole_offset=min(1e-2, np.sqrt(rtol)), xtol=1e-2 * rtol)


def plate_apex_range(options: ODEOptions = ODEOptions()):
    return 1.002, PlateODE(options=options).at_pressure(P_END).measures["apex_stretch"]


def ode_curve(curve: str, rtol: float, points: int, lam_end: float, graded: bool = False):
    """(shape, p) arrays of the ODE approach's traced curve (``graded``: points dense at the start)."""
    opt = ode_options(rtol)
    u = np.linspace(0.0, 1.0, points) ** (2 if graded else 1)
    if curve == "plate":
        rows = PlateODE(options=opt).branch(1.002 + (lam_end - 1.002) * u)
        return np.array([r[2] for r in rows]), np.array([r[1] for r in rows])
    rows = TorusODE(options=opt).branch(R_FIRST + (R_END - R_FIRST) * u)
    return np.array([r[0] for r in rows]), np.array([r[2] for r in rows])


def snapmem_curve(curve: str, nodes: int):
    """(shape, p) arrays of snapmem's traced curve (the torus starts from its state at p = 0.005)."""
    if curve == "plate":
        table = trace(build_scene("plate", nodes=nodes), "pressure", until={"pressure": P_END}).table
        return table["deflection"].to_numpy(), table["pressure"].to_numpy()
    scene = build_scene("torus", nodes=nodes)
    start = equilibrium(scene, {"pressure": 0.005})
    table = trace(scene, "pressure", until={"outer_radius": R_END}, start=(start.q, start.loads)).table
    return table["outer_radius"].to_numpy(), table["pressure"].to_numpy()


def reference(curve: str, lam_end: float, points: int = 241):
    """Cubic spline p_ref(shape) through the converged ODE curve, its shape range, and its own
    interpolation error (the spline through every other point against the points left out)."""
    shape, p = ode_curve(curve, 1e-13, points, lam_end, graded=True)
    half = CubicSpline(shape[::2], p[::2])
    spline_error = float(np.max(np.abs(half(shape[1::2]) - p[1::2])))
    return CubicSpline(shape, p), (shape[0], shape[-1]), spline_error


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
        rows.append({"table": "run", "curve": curve, "method": method, "setting": setting,
                     "points": int(np.sum((shape >= span[0]) & (shape <= span[1]))), "error": err,
                     "seconds": seconds, "seconds_min": fastest})
        print(f"  {curve:5s} {method:7s} {setting:>8g}  error {err:.2e}  {seconds:8.3f} s", flush=True)
        if err < floor:
            break
    return rows


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="error targets 1e-3, 1e-4 only, 1 repeat")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--out", default="results/peers.csv")
    args = parser.parse_args(argv)
    repeats = 1 if args.quick else args.repeats
    targets = (1e-3, 1e-4) if args.quick else (1e-3, 1e-4, 1e-5, 1e-6)
    snapmem_curve("plate", 21)                         # warm-up: imports, numba caches
    lam_end = plate_apex_range()[1]
    rows, meta = [], {}
    for curve in ("plate", "torus"):
        ref, span, spline_error = reference(curve, lam_end)
        scale = P_END if curve == "plate" else float(np.max(ref(np.linspace(*span, 2001))))
        meta[f"{curve}_reference_error_bound"] = spline_error / scale      # of the half-density spline
        print(f"{curve}: reference spline error (half density) {spline_error / scale:.1e}", flush=True)
        floor = min(targets) / 3
        rows += sweep(curve, "snapmem", (25, 50, 100, 200, 400, 800, 1600, 3200),
                      lambda n: snapmem_curve(curve, n), ref, span, scale, repeats, floor)
        rows += sweep(curve, "ode", (1e-3, 1e-4, 1e-5, 1e-6, 1e-7, 1e-8, 1e-9, 1e-10),
                      lambda r: ode_curve(curve, r, M_POINTS, lam_end), ref, span, scale, repeats, floor)
    runs = pd.DataFrame(rows)
    summary = []
    for (curve, target) in [(c, t) for c in ("plate", "torus") for t in targets]:
        best = {}
        for method in ("snapmem", "ode"):
            ok = runs[(runs.curve == curve) & (runs.method == method) & (runs.error <= target)]
            best[method] = ok.loc[ok.seconds.idxmin()] if len(ok) else None
        s, o = best["snapmem"], best["ode"]
        summary.append({"table": "equal_error", "curve": curve, "target": target,
                        "snapmem_nodes": None if s is None else int(s.setting),
                        "snapmem_error": None if s is None else s.error,
                        "snapmem_seconds": None if s is None else s.seconds,
                        "ode_rtol": None if o is None else o.setting,
                        "ode_error": None if o is None else o.error,
                        "ode_seconds": None if o is None else o.seconds,
                        "ratio_ode_over_snapmem": None if s is None or o is None else o.seconds / s.seconds})
    table = pd.concat([runs, pd.DataFrame(summary)], ignore_index=True)
    write_table(table, args.out, {"study": "peers", "repeats": repeats, "targets": targets,
                                  "plate": {"R": 7.5, "H": 0.5, "c1": 0.4, "c2": 0.1, "p_end": P_END},
                                  "torus": {"Rb": 10, "Rs": 2, "H": 0.1, "c1": 0.4375, "c2": 0.0625,
                                            "r_o_range": [R_FIRST, R_END]},
                                  "ode_points": M_POINTS, "reference": "ODE rtol 1e-13, 241 graded points, cubic spline",
                                  "OPENBLAS_NUM_THREADS": os.environ.get("OPENBLAS_NUM_THREADS"),
                                  **meta})
    with pd.option_context("display.width", 200, "display.float_format", "{:.3g}".format):
        print(pd.DataFrame(summary).drop(columns="table").to_string(index=False))
    return table


if __name__ == "__main__":
    main()
