"""Error against run time (work-precision) for the static curves, the located limit points and the
dynamic balloon, one line per method or setting; results/error_vs_runtime.csv and PNGs.

References: the balloon's exact formula and its ODE in time (snapmem.reference.exact); the plate and the
torus by Richardson extrapolation of the two finest meshes (the discretisation converges as N^-2).
Every time is the median of three runs on this machine.
"""

import time

import numpy as np
import pandas as pd

from snapmem import build_scene, exact
from snapmem.continuation.tracer import ContinuationOptions, trace
from snapmem.dynamics.driver import DynamicsOptions, schedule, simulate
from snapmem.viz import style
from snapmem.viz.plotting import plot_xy
from snapmem.study import parse_args, save


def timed(fn, repeats=3):
    times, out = [], None
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t0)
    return out, float(np.median(times))


def balloon_rows(sizes):
    rows = []
    for n in sizes:
        branch, t = timed(lambda: trace(build_scene("balloon", nodes=n), "pressure", until={"stretch": 4.0}))
        tab = branch.table
        _, p_lp = exact.balloon_limit_point()
        rows.append({"problem": "balloon curve", "method": "continuation", "setting": n, "wall_time_s": t,
                     "error": float(np.max(np.abs(tab["pressure"] - exact.balloon_pressure(tab["stretch"]))) / p_lp)})
        rows.append({"problem": "balloon limit pressure", "method": "continuation", "setting": n, "wall_time_s": t,
                     "error": abs(branch.limit_points()["pressure"].iloc[0] / p_lp - 1)})
    return rows


def refined_rows(name, sizes, until, save_at):
    """Errors of the curve (the main output at the save_at pressures) and of the first limit pressure
    against Richardson's extrapolation of the two finest of ``sizes`` (the finest are not plotted)."""
    probe = "deflection" if name == "plate" else "u_max"
    values, times = {}, {}
    for n in sizes:
        opts = ContinuationOptions(save_at=save_at)
        branch, t = timed(lambda: trace(build_scene(name, nodes=n), "pressure", until=until, options=opts),
                          repeats=1 if n in sizes[-2:] else 3)
        saved = branch.table[branch.table["save_at"]]
        v = {f"curve {p:g}": float(saved[np.isclose(saved["pressure"], p, rtol=1e-12)][probe].iloc[0]) for p in save_at}
        if not branch.limit_points().empty:
            v["limit pressure"] = float(branch.limit_points()["pressure"].iloc[0])
        values[n], times[n] = v, t
    edges = {n: build_scene(name, nodes=n).meridian.edges.shape[0] for n in sizes[-2:]}
    ratio = (edges[sizes[-1]] / edges[sizes[-2]]) ** 2
    reference = {k: values[sizes[-1]][k] + (values[sizes[-1]][k] - values[sizes[-2]][k]) / (ratio - 1)
                 for k in values[sizes[-1]]}
    rows = []
    for n in sizes[:-2]:
        curve = [abs(values[n][k] / reference[k] - 1) for k in reference if k.startswith("curve")]
        rows.append({"problem": f"{name} curve", "method": "continuation", "setting": n, "wall_time_s": times[n],
                     "error": max(curve)})
        if "limit pressure" in reference:
            rows.append({"problem": f"{name} limit pressure", "method": "continuation", "setting": n,
                         "wall_time_s": times[n], "error": abs(values[n]["limit pressure"] / reference["limit pressure"] - 1)})
    return rows


def dynamic_rows(dts, nodes):
    """Equator stretch of a balloon ramped through its limit point against the ODE (spatial error
    at this N is below the temporal errors shown)."""
    p_max, rate, t_end = 0.02, 0.001, 30.0
    p = lambda t: min(rate * t, p_max)
    ode = exact.balloon_dynamics(p, t_end, xi=0.5)
    scene = build_scene("balloon", nodes=nodes)
    simulate(scene, None, 0.01, options=DynamicsOptions(dt=0.01, adaptive=False))   # load the compiled step first
    rows = []
    for scheme in ("euler", "midpoint", "bdf2"):
        for dt in dts:
            run = lambda: simulate(scene, schedule(pressure=[(0, 0), (p_max / rate, p_max), (t_end, p_max)]), t_end,
                                   rho=1.0, damping=0.5, options=DynamicsOptions(scheme=scheme, dt=dt, adaptive=False))
            traj, t = timed(run, repeats=1)
            lam = traj["r"].max(axis=1) / 10.0
            rows.append({"problem": "dynamic balloon (through the snap)", "method": scheme, "setting": dt,
                         "wall_time_s": t, "error": float(np.max(np.abs(lam - ode(traj["t"])[0])))})
    return rows


def redraw_option(parser):
    parser.add_argument("--redraw", action="store_true", help="only redraw the PNG from the CSV in --out")


def draw(table, path):
    """(a) the static problems by continuation, one point per mesh; (b) the dynamic balloon, one
    point per time step and one line per scheme."""
    fig, (statics, dynamics) = style.axes(nrows=2)
    plot_xy(table[table["method"] == "continuation"], "wall_time_s", "error", group="problem", ax=statics,
            logx=True, logy=True, title="(a) statics, continuation: one point per mesh, N from 11")
    plot_xy(table[table["method"] != "continuation"], "wall_time_s", "error", group="method", ax=dynamics,
            logx=True, logy=True, title="(b) dynamic balloon through its snap: one point per time step")
    dynamics.set_ylabel(r"max$_t\,|\lambda - \lambda_{\mathrm{ODE}}|$")
    style.legend(statics, title="problem")
    style.legend(dynamics, title="scheme")
    fig.tight_layout()
    style.save(fig, path)
    return table


def main(argv=None):
    args = parse_args(__doc__, argv, extra=redraw_option)
    if args.redraw:
        return draw(pd.read_csv(args.out / "error_vs_runtime.csv"), args.out / "error_vs_runtime.png")
    quick = args.quick
    rows = balloon_rows([11, 21, 41] if quick else [11, 21, 41, 81, 161, 321, 641])
    sizes = [11, 21, 41, 81] if quick else [11, 21, 41, 81, 161, 321, 641, 1281]
    rows += refined_rows("plate", sizes, {"deflection": 5.0}, (0.02, 0.05, 0.1))
    rows += refined_rows("torus", sizes, {"u_max": 6.0}, (0.02, 0.03))
    rows += dynamic_rows([0.5, 0.25] if quick else [1.0, 0.5, 0.25, 0.125, 0.0625], 21 if quick else 81)
    table = pd.DataFrame(rows)
    save(args, "error_vs_runtime", table)
    draw(table, args.out / "error_vs_runtime.png")
    print(table.to_string(index=False))
    return table


if __name__ == "__main__":
    main()
