"""Paper Figs 6-8, the soft robots: the pump's 30 s cycle in time (simulated here) and the figures
of studies/robot_curves.py's tables (pump p-V curves, gripper contact force against pressure,
ball heights), drawn from results/robots/*.csv. Run robot_curves.py first.
"""

import pandas as pd

from snapmem.viz import style
from snapmem.viz.plotting import plot_family, plot_xy
from snapmem.catalog.robots import events, run
from snapmem.study import parse_args, save


def main(argv=None):
    args = parse_args(__doc__, argv, extra=lambda p: p.add_argument("--tables", default="results/robots"))
    traj = run("pump", nodes=31 if args.quick else 61)
    cycle = pd.DataFrame({"t": traj["t"], "pressure": traj["load_pressure"], "voltage": traj["load_voltage"],
                          "volume": traj["volume"]})
    ev = events(traj)
    save(args, "fig6_pump_cycle", cycle, snap=ev.get("snap"), snap_back=ev.get("snap_back"))
    fig, axes = style.axes(nrows=2, sharex=True)
    axes[0].plot(cycle["t"], cycle["volume"])
    axes[0].set_ylabel(style.label("volume", si=True))
    for name in ("snap", "snap_back"):
        if ev.get(name) is not None:
            axes[0].axvline(ev[name], ls=":", c="k")
            # at the top of the axes, on the side of the line where the volume is low (clear of the curve)
            axes[0].text(ev[name], 0.97, f" {name.replace('_', ' ')} {ev[name]:.2f} s ", fontsize=7, va="top",
                         ha="right" if name == "snap" else "left", transform=axes[0].get_xaxis_transform())
    axes[1].plot(cycle["t"], cycle["pressure"], label=style.label("pressure", si=True))
    twin = axes[1].twinx()
    twin.plot(cycle["t"], cycle["voltage"], color="C1", ls="--", label=style.label("voltage"))
    twin.set_ylabel(style.label("voltage"))
    twin.grid(False)
    axes[1].set_ylabel(style.label("pressure", si=True))
    axes[1].set_xlabel(style.label("t"))
    axes[1].legend(handles=axes[1].get_lines() + twin.get_lines(), loc="upper left", bbox_to_anchor=(1.12, 1.0))
    axes[0].set_title("Fig. 6c-d: the pump's cycle")
    fig.tight_layout()
    style.save(fig, args.out / "fig6_pump_cycle.png")

    tables = pd.io.common.Path(args.tables)
    pv = pd.read_csv(tables / "pump_pv.csv")
    plot_family(pv, "volume", "pressure", "phi", args.out / "fig6_pump_pv.png", si=True,
                title="Fig. 6b: pump, pressure against volume")

    force = pd.read_csv(tables / "gripper_force.csv")
    force["case"] = [f"$R_w$ = {rw:g} m, $\\phi$ = {phi:g} V" for rw, phi in zip(force["Rw"], force["phi"])]
    for scene, sub in force.groupby("scene"):
        plot_xy(sub, "pressure", "force", args.out / f"fig7_{scene}_force.png", group="case", marker="-", si=True,
                title=f"Fig. 7: {scene.replace('_', ' ')}, contact force")
    plot_xy(pd.read_csv(tables / "ball_drop.csv"), "t", "height", args.out / "fig8_ball_drop.png", group="xi",
            marker="-", si=True, title="Fig. 8: ball dropped on the balloon at 500 Pa")
    plot_xy(pd.read_csv(tables / "ball_rest.csv"), "pressure", "height", args.out / "fig8_ball_rest.png", group="mb",
            si=True, title="Fig. 8: ball at rest on the balloon")
    plot_xy(pd.read_csv(tables / "ball_throw.csv"), "phi", "ball_apex", args.out / "fig8_ball_throw.png", si=True,
            title="Fig. 8: ball thrown by the snapping balloon")
    return cycle


if __name__ == "__main__":
    main()
