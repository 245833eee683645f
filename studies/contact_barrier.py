"""Contact barrier study: how the IPC barrier's width dhat and pressure scale kappa move the
robots' answers and their cost.

For each (dhat, kappa) on a grid around the robots' defaults (ball 1e-3 m and 1e4 Pa, gripper
5e-4 m and 1e5 Pa): the ball at rest on the balloon at 500 Pa (static), the first second of
ball_drop (impact, bounce, rebound; steps and Newton iterations), and gripper_rod held at
2500 Pa (its contact force on the rod at the end). Each answer is also given relative to the
grid's finest barrier (smallest dhat, largest kappa), the closest to hard contact.

    python studies/contact_barrier.py [--quick] [--out results/]

Writes contact_barrier.csv and contact_barrier.png.
"""

from __future__ import annotations

import itertools
import time

import pandas as pd

from snapmem import build_scene
from snapmem.viz import style
from snapmem.catalog.robots import events, resting, run
from snapmem.study import parse_args, save


def case(dhat: float, kappa: float, nodes: int, t_drop: float, t_grip: float) -> dict:
    row = {"dhat": dhat, "kappa": kappa}
    rest = resting(build_scene("ball_drop", nodes=nodes, dhat=dhat, kappa=kappa), 500.0)
    row["rest_height"] = float(rest[-1]) + 0.1                        # above the plate [m]
    wall = time.perf_counter()
    drop = run("ball_drop", nodes=nodes, dhat=dhat, kappa=kappa, t_end=t_drop)
    row["drop_wall_s"] = time.perf_counter() - wall
    row.update({f"drop_{k}": v for k, v in events(drop).items()})
    row.update(drop_steps=drop.meta["steps"], drop_newton=drop.meta["newton_iterations"],
               drop_min_gap=float(drop["min_gap"].min()))
    # the gripper's barrier scales with its own defaults (5e-4 m, 1e5 Pa): same ratios to them
    g_dhat, g_kappa = dhat / 2.0, kappa * 10.0
    wall = time.perf_counter()
    grip = run("gripper_rod", nodes=nodes + 19, dhat=g_dhat, kappa=g_kappa, t_end=t_grip)
    row.update(gripper_dhat=g_dhat, gripper_kappa=g_kappa, gripper_wall_s=time.perf_counter() - wall,
               gripper_force=float(grip["rod_force"][-1]), gripper_newton=grip.meta["newton_iterations"],
               gripper_min_gap=float(grip["min_gap"].min()))
    return row


def main(argv=None):
    args = parse_args(__doc__, argv)
    nodes = 21 if args.quick else 61
    dhats = (1e-3, 3e-3) if args.quick else (3e-4, 1e-3, 3e-3)
    kappas = (1e4,) if args.quick else (1e3, 1e4, 1e5)
    t_drop, t_grip = (0.8, 27.0) if args.quick else (1.0, 30.0)
    rows = []
    for dhat, kappa in itertools.product(dhats, kappas):
        rows.append(case(dhat, kappa, nodes, t_drop, t_grip))
        print(", ".join(f"{k} {v:.4g}" for k, v in rows[-1].items()), flush=True)
    table = pd.DataFrame(rows)
    finest = table.sort_values(["dhat", "kappa"], ascending=[True, False]).iloc[0]
    for col in ("rest_height", "drop_impact", "drop_bounce", "drop_rebound", "drop_rebound_height", "gripper_force"):
        table[f"{col}_rel"] = table[col] / finest[col] - 1.0
    save(args, "contact_barrier", table, nodes=nodes, t_drop=t_drop, t_grip=t_grip)

    fig, axes = style.axes(size=(3.6, 3.2), ncols=3)
    for kappa, sub in table.groupby("kappa"):
        label = style.value_label("kappa", kappa) + " (gripper x10)"
        axes[0].plot(sub["dhat"], 100 * sub["rest_height_rel"], "o-", label=label)
        axes[1].plot(sub["dhat"], 100 * sub["gripper_force_rel"], "o-", label=label)
        axes[2].plot(sub["dhat"], sub["drop_newton"], "o-", label=label)
    for ax, title, ylabel in zip(axes, ("ball at rest", "gripper on the rod", "ball_drop, first second"),
                                 (r"$b_h$: change from the finest barrier [%]",
                                  r"$F$: change from the finest barrier [%]", "Newton iterations")):
        ax.set_xlabel(style.label("dhat") + " (gripper: $\\hat d/2$)")
        ax.set_ylabel(ylabel)
        ax.set_title(title)
        style.log_axis(ax, "x")
    style.legend(axes[2])
    fig.tight_layout()
    style.save(fig, args.out / "contact_barrier.png")
    return table


if __name__ == "__main__":
    main()
