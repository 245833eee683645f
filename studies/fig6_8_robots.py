"""Paper Figs 6-8, the soft robots: the pump's 30 s cycle in time (simulated here) and the figures
of studies/robot_curves.py's tables (pump p-V curves, gripper contact force against pressure,
ball heights), drawn from results/robots/*.csv. Run robot_curves.py first.
"""

import pandas as pd

from snapmem.viz.plotting import plot_branch, plot_xy, _pyplot
from snapmem.catalog.robots import events, run
from snapmem.study import parse_args, save


def main(argv=None):
    args = parse_args(__doc__, argv, extra=lambda p: p.add_argument("--tables", default="results/robots"))
    traj = run("pump", nodes=31 if args.quick else 61)
    cycle = pd.DataFrame({"t": traj["t"], "pressure": traj["load_pressure"], "voltage": traj["load_voltage"],
                          "volume": traj["volume"]})
    ev = events(traj)
    save(args, "fig6_pump_cycle", cycle, snap=ev.get("snap"), snap_back=ev.get("snap_back"))
    plt = _pyplot()
    fig, axes = plt.subplots(2, 1, figsize=(6, 5.5), sharex=True)
    axes[0].plot(cycle["t"], cycle["volume"])
    axes[0].set_ylabel("volume [m^3]")
    for name in ("snap", "snap_back"):
        if ev.get(name) is not None:
            axes[0].axvline(ev[name], ls=":", c="k")
            axes[0].text(ev[name], cycle["volume"].max() * 0.9, f" {name} {ev[name]:.2f} s", fontsize=8)
    axes[1].plot(cycle["t"], cycle["pressure"], label="pressure [Pa]")
    axes[1].plot(cycle["t"], cycle["voltage"] / 3.0, label="voltage / 3 [V]")
    axes[1].set_xlabel("t [s]")
    axes[1].legend(fontsize=8)
    axes[0].set_title("Fig. 6c-d: the pump's cycle")
    fig.tight_layout()
    fig.savefig(args.out / "fig6_pump_cycle.png", dpi=120)
    plt.close(fig)

    tables = pd.io.common.Path(args.tables)
    pv = pd.read_csv(tables / "pump_pv.csv")
    fig, ax = plt.subplots(figsize=(6, 4.2))
    for phi, sub in pv.groupby("phi"):
        plot_branch(sub, "volume", "pressure", ax=ax, label=f"phi = {phi:g} V")
    ax.set_title("Fig. 6b: pump, pressure against volume", fontsize=10)
    fig.tight_layout()
    fig.savefig(args.out / "fig6_pump_pv.png", dpi=120)
    plt.close(fig)

    force = pd.read_csv(tables / "gripper_force.csv")
    force["case"] = force["scene"].str.replace("gripper_", "") + " Rw=" + force["Rw"].astype(str) + " phi=" + force["phi"].astype(str)
    for scene, sub in force.groupby("scene"):
        plot_xy(sub, "pressure", "force", args.out / f"fig7_{scene}_force.png", group="case", marker="-",
                title=f"Fig. 7: {scene}, contact force [N] against pressure [Pa]")
    plot_xy(pd.read_csv(tables / "ball_drop.csv"), "t", "height", args.out / "fig8_ball_drop.png", group="xi",
            marker="-", title="Fig. 8: ball drop at 500 Pa, height above the plate [m]")
    plot_xy(pd.read_csv(tables / "ball_rest.csv"), "pressure", "height", args.out / "fig8_ball_rest.png", group="mb",
            title="Fig. 8: ball at rest, height above the plate [m]")
    plot_xy(pd.read_csv(tables / "ball_throw.csv"), "phi", "ball_apex", args.out / "fig8_ball_throw.png",
            title="Fig. 8: thrown ball, apex above the plate [m]")
    return cycle


if __name__ == "__main__":
    main()
