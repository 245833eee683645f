"""Paper Fig. 9: computational cost. (a) Wall time of each validation curve (plate, balloon, torus:
traced through their limit points with stability at every point) against the node count; (b) wall
time of dynamic runs against a fixed time step (the pump's 30 s cycle and the paper's torus_snap).
Writes fig9a_static_cost.csv, fig9b_dynamic_cost.csv and PNGs. The 3D FEM comparison of the
paper's Fig. 9a is studies/sfepy_balloon.py (optional: it needs SfePy).
"""

import time

import pandas as pd

from snapmem import build_scene
from snapmem.continuation.tracer import trace
from snapmem.dynamics.driver import DynamicsOptions
from snapmem.viz.plotting import plot_xy
from snapmem.catalog.robots import run
from snapmem.study import parse_args, save

UNTIL = {"plate": {"deflection": 7.5}, "balloon": {"stretch": 4.0}, "torus": {"u_max": 10.0}}


def main(argv=None):
    args = parse_args(__doc__, argv, extra=lambda p: p.add_argument(
        "--redraw", action="store_true", help="only redraw the PNGs from the CSVs in --out"))
    if args.redraw:
        return draw(*(pd.read_csv(args.out / f"{name}.csv") for name in ("fig9a_static_cost", "fig9b_dynamic_cost")),
                    args.out)
    sizes = [51, 101] if args.quick else [51, 101, 201, 401, 801]
    rows = []
    for name, until in UNTIL.items():
        trace(build_scene(name, nodes=sizes[0]), "pressure", until=until)    # untimed: the kernels' first load
        for n in sizes:
            t0 = time.perf_counter()
            branch = trace(build_scene(name, nodes=n), "pressure", until=until)
            rows.append({"scene": name, "nodes": n, "wall_time_s": time.perf_counter() - t0,
                         "points": len(branch.table), "newton_iterations": branch.stats["newton_iterations"]})
    a = pd.DataFrame(rows)
    save(args, "fig9a_static_cost", a)
    rows = []
    steps = [0.1, 0.05] if args.quick else [0.2, 0.1, 0.05, 0.02, 0.01]
    for scene, nodes in (("pump", 31 if args.quick else 61), ("torus_snap", 60 if args.quick else 200)):
        run(scene, nodes=nodes, t_end=1.0)                                     # untimed: the kernels' first load
        for dt in steps:
            t0 = time.perf_counter()
            traj = run(scene, nodes=nodes, t_end=30.0 if scene == "pump" else 100.0,
                       options=DynamicsOptions(scheme="euler", dt=dt, adaptive=False, dt_max=dt))
            rows.append({"scene": scene, "nodes": nodes, "dt": dt, "wall_time_s": time.perf_counter() - t0,
                         "steps": traj.meta.get("steps"), "status": traj.meta.get("status")})
    b = pd.DataFrame(rows)
    save(args, "fig9b_dynamic_cost", b)
    return draw(a, b, args.out)


def draw(a, b, out):
    plot_xy(a, "nodes", "wall_time_s", out / "fig9a_static_cost.png", group="scene", logx=True, logy=True,
            title="Fig. 9a: wall time of a traced curve", legend_title="scene")
    plot_xy(b, "dt", "wall_time_s", out / "fig9b_dynamic_cost.png", group="scene", logx=True, logy=True,
            title="Fig. 9b: dynamics, implicit Euler", legend_title="scene")
    return a, b


if __name__ == "__main__":
    main()
