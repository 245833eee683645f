"""The ball actuator (paper Fig. 8, case 2: ``ball_throw``) with a viscoelastic membrane: the ball's
apex height against the relaxation time of one non-equilibrium network.

The balloon (Mooney-Rivlin equilibrium network, mu = 422.5 kPa) gets one neo-Hookean network of
modulus ``viscous_mu`` = mu / 2 and relaxation time tau (snapmem.model.viscous). Each run starts
from the ball resting on the balloon inflated to 500 Pa with the networks relaxed there, and the
pressure rises at the scene's rate until the balloon snaps and throws the ball. Short tau: the
networks relax during the rise and the snap, so the run tends to the elastic one with the
equilibrium law (the dashed line, tau -> 0); long tau: they stay glassy about the inflated start
(a stiffer response to the rise); in between, the dashpots dissipate part of the snap's energy
(column ``dissipated_J``). Where the glassy membrane's snap pressure is not reached by the run's
end (t_end = 2 s), snap_time and apex are NaN.

Writes results/viscous_ball.csv and results/viscous_ball.png.
"""

import time

import numpy as np
import pandas as pd

from snapmem.catalog.robots import events, experiment
from snapmem.dynamics.driver import simulate
from snapmem.study import parse_args, save

MU = 4.225e5          # the ball scenes' shear modulus [Pa] (snapmem.catalog.robot_scenes.MU_MR)


def run(nodes, **params):
    ex = experiment("ball_throw", nodes=nodes, **params)
    wall = time.perf_counter()
    traj = simulate(ex.scene, ex.loads, ex.t_end, rho=ex.rho, damping=ex.damping, q0=ex.q0, v0=ex.v0,
                    options=ex.options, damp_bodies=ex.damp_bodies)
    wall = time.perf_counter() - wall
    found = events(traj)
    dissipated = float(traj["dissipation"][-1]) if "dissipation" in traj.data else 0.0
    return {"snap_time": found["snap"], "apex": found["ball_apex"], "dissipated_J": dissipated,
            "status": traj.meta["status"], "wall_time_s": wall, "real_time_factor": traj.meta["t_end"] / wall}


def main(argv=None):
    args = parse_args(__doc__, argv)
    nodes = 31 if args.quick else 61
    taus = (1e-2, 1.0) if args.quick else tuple(np.geomspace(1e-4, 1e1, 11))
    viscous_mu = 0.5 * MU
    rows = [{"tau": 0.0, "case": "elastic (equilibrium network)", **run(nodes)}]
    for tau in taus:
        rows.append({"tau": float(tau), "case": "viscoelastic", **run(nodes, viscous_mu=viscous_mu, relaxation_time=tau)})
    table = pd.DataFrame(rows)
    save(args, "viscous_ball", table, nodes=nodes, viscous_mu=viscous_mu)
    plot(table, args.out / "viscous_ball.png")
    print(table.to_string(index=False))
    return table


def plot(table, path):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    visco = table[table["case"] == "viscoelastic"]
    fig, ax = plt.subplots(figsize=(6.0, 4.0))
    ax.semilogx(visco["tau"], visco["apex"], "o-", color="C0", label="viscoelastic, viscous_mu = mu / 2")
    elastic = table[table["case"] == "elastic (equilibrium network)"]
    ax.axhline(float(elastic["apex"].iloc[0]), ls="--", color="k", lw=1.0,
               label=r"elastic, equilibrium network ($\tau \to 0$)")
    unsnapped = visco[visco["apex"].isna()]
    if len(unsnapped):
        ax.text(0.02, 0.5, f"no snap by t_end for tau >= {unsnapped['tau'].min():.2g} s\n(glassy membrane: "
                "the snap pressure is not reached)", transform=ax.transAxes, fontsize=8, va="center")
    ax.set_xlabel(r"relaxation time $\tau$ [s]")
    ax.set_ylabel(r"ball apex height $z_{apex}$ [m]")
    ax.set_title("ball actuator (ball_throw) with a viscoelastic membrane")
    ax.legend(fontsize=8, loc="best")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


if __name__ == "__main__":
    main()
