"""Actuation windows of VHB membranes (balloon, pump plate, torus): the (voltage, stretch) and (pressure, voltage) planes bounded
by electromechanical instability (EMI), breakdown (EB) and rupture (RU), each boundary a
continuation of its event in the second parameter (snapmem.continuation.event_curves), not a scan.

Material, VHB 4910-like:
- Gent, mu = 50 kPa, Jlim = 110, eps = 4.5 eps0 (the values Koh, Keplinger & Suo use for VHB
  in their failure maps: S. J. A. Koh, C. Keplinger, T. Li, S. Bauer & Z. Suo, "Dielectric
  elastomer generators: how much energy can be converted?", IEEE/ASME Trans. Mechatronics 16
  (2011) 33, mu ~ 45-60 kPa, Jlim ~ 90-120, eps ~ 4.5-4.7 eps0);
- breakdown strength E_B = 35 MV/m (area stretch)^0.565 from the stress-free state: Huang, Shian,
  Diebold, Suo & Clarke, "The thickness and stretch dependence of the electrical breakdown
  strength of an acrylic dielectric elastomer", Appl. Phys. Lett. 101 (2012) 122905, measured
  E_B = 51 h^-0.25 lam^0.63 (MV/m, h in mm); under equibiaxial stretch h ~ lam^-2, so
  E_B ~ lam^1.13 = (area stretch)^0.565, rising from tens of MV/m unstretched to ~200 MV/m at
  lam ~ 5, as Plante & Dubowsky report ("Large-scale failure modes of dielectric elastomer
  actuators", Int. J. Solids Struct. 43 (2006) 7727);
- rupture at a total stretch of 6 (chosen below the Gent lock, lam ~ 7.5 equibiaxially at
  Jlim = 110).

Designs (mounted geometry; the law at the total stretch, scene parameter ``prestretch``):
- the balloon, mounted radius 20 mm and thickness 0.2 mm (a prestretched balloon is only the
  smaller, thicker stress-free one: test_prestretch), seeded twice: the voltage raised at a held
  pressure of 300 Pa (EMI), the pressure raised at a held 2 kV (EB, RU);
- the pump plate (R = 0.1 m, mounted H = 0.1 mm) mounted at prestretch 1, 2 and 3, the voltage
  raised at a held pressure of 20 lp^2 Pa, every event on the way continued in the pressure;
- the gripper's torus without its rod (Rb = 0.1 m, Rs = 0.02 m, H = 0.1 mm), the voltage raised
  at 100 Pa and the pressure at 1 kV.
Each event is followed in the other load both ways. Stretch is ``stretch_max``, the largest
principal stretch from the mounted state.
Writes results/actuation_window.csv, results/actuation_window_first.csv and the PNG.
"""

import numpy as np
import pandas as pd

from snapmem import build_scene
from snapmem.continuation.event_curves import failure_window
from snapmem.study import parse_args, save

EPS0 = 8.854e-12
VHB = dict(material="gent", mu=5e4, Jlim=110.0, eps=4.5 * EPS0, E_breakdown=35e6, breakdown_exponent=0.565,
           stretch_limit=6.0)
GEOMETRY = {"balloon": dict(R=0.02, H=2e-4), "pump": {}, "torus": dict(Rb=0.1, Rs=0.02, H=1e-4)}
# name, scene, prestretch, seeds: (control, held value of the other load, its range, events, until)
DESIGNS = [("balloon", "balloon", 1.0, [("voltage", 300.0, (0.0, 700.0), ("EMI", "EB", "RU"), {"stretch_max": 3.0}),
                                         ("pressure", 2000.0, (0.0, 6000.0), ("EB", "RU"), {"stretch_max": 6.5})])]
DESIGNS += [(f"plate lp = {lp:g}", "pump", lp, [("voltage", 20.0 * lp ** 2, (0.0, 200.0 * lp ** 2),
                                                 ("EMI", "EB", "RU", "LT", "LE"), {"stretch_max": 6.0 / lp})])
            for lp in (1.0, 2.0, 3.0)]
DESIGNS += [("torus", "torus", 1.0, [("voltage", 100.0, (0.0, 400.0), ("EMI", "EB", "RU", "LT", "LE"),
                                      {"stretch_max": 3.0}),
                                     ("pressure", 1000.0, (0.0, 3000.0), ("EB", "RU"), {"stretch_max": 6.5})])]
OTHER = {"voltage": "pressure", "pressure": "voltage"}


def main(argv=None):
    args = parse_args(__doc__, argv)
    nodes = 21 if args.quick else 31
    designs = DESIGNS[:2] if args.quick else DESIGNS
    curves, firsts = [], []
    for name, scene, lp, seeds in designs:
        for control, held, v_range, kinds, until in seeds:
            def scene_at(v, scene=scene, lp=lp, control=control):
                loads = {OTHER[control]: v, control: 0.0}
                return build_scene(scene, nodes=nodes, with_loads=("voltage",), prestretch=lp, **loads, **VHB,
                                   **GEOMETRY[scene])

            table, first = failure_window(scene_at, held, v_range, control, until=until, stretch_max=6.5,
                                          kinds=kinds, ds_max=0.2 if args.quick else 0.1,
                                          max_steps=60 if args.quick else 200,
                                          lam_range=(0.0, np.inf))
            seed = f"{control} at {OTHER[control]} {held:g}"
            curves.append(table.assign(design=name, prestretch=lp, seed=seed))
            firsts.append(first.assign(design=name, prestretch=lp, seed=seed))
    table = pd.concat(curves, ignore_index=True)
    keep = ["design", "prestretch", "seed", "curve", "direction", "v", "lam", "pressure", "voltage", "E_hat",
            "stretch_max", "stable", "breakdown_margin", "rupture_margin", "min_tension", "status"]
    table = table[keep]
    first = pd.concat(firsts, ignore_index=True)[["design", "seed", "kind", "pressure", "voltage", "stretch_max",
                                                   "breakdown_margin", "rupture_margin", "min_tension"]]
    save(args, "actuation_window", table, nodes=nodes, material=VHB)
    save(args, "actuation_window_first", first, nodes=nodes)
    draw(table, args.out / "actuation_window.png")
    print(first.groupby(["design", "seed"], sort=False).head(1).to_string(index=False))
    return table, first


COLOURS = {"EMI": "C0", "EB": "C3", "RU": "C2", "LT": "C1", "LE": "C4"}


def draw(table, path):
    """Two planes per design from the CSV: stable parts of each boundary solid, unstable ones dotted."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    designs = list(dict.fromkeys(table["design"]))
    fig, axes = plt.subplots(len(designs), 2, figsize=(11, 4.2 * len(designs)), squeeze=False)
    for row, name in zip(axes, designs):
        d = table[table["design"] == name]
        for (seed, curve, direction), part in d.groupby(["seed", "curve", "direction"], sort=False):
            colour = "0.55" if curve == "branch" else COLOURS.get(curve, "k")
            stable = part["stable"].astype(bool).to_numpy()
            for ax, (x, y, sx, sy) in zip(row, (("voltage", "stretch_max", 1e-3, 1.0), ("pressure", "voltage", 1.0, 1e-3))):
                xs, ys = part[x].to_numpy() * sx, part[y].to_numpy() * sy
                ax.plot(xs, np.where(stable, ys, np.nan), "-", color=colour, lw=1.8 if curve != "branch" else 1.0)
                ax.plot(xs, np.where(~stable, ys, np.nan), ":", color=colour, lw=1.0)
        for ax, (xl, yl) in zip(row, ((r"voltage $\phi$ [kV]", r"largest stretch $\lambda_{max}$ (mounted)"),
                                      (r"pressure $p$ [Pa]", r"voltage $\phi$ [kV]"))):
            ax.set_xlabel(xl)
            ax.set_ylabel(yl)
            ax.set_title(f"VHB {name}")
        row[0].set_xlim(left=0.0)
        row[1].set_xlim(left=0.0)
        row[1].set_ylim(bottom=0.0)
    labels = {"EMI": "EMI (pull-in)", "EB": "EB (breakdown)", "RU": "RU (rupture)", "LT": "LT (wrinkling)",
              "LE": "LE (loss of ellipticity)"}
    handles = [axes[0, 0].plot([], [], "-", color=colour, label=labels[name])[0] for name, colour in COLOURS.items()]
    handles += [axes[0, 0].plot([], [], "-", color="0.55", lw=1.0, label="seed branches")[0],
                axes[0, 0].plot([], [], ":", color="k", lw=1.0, label="unstable part")[0]]
    fig.legend(handles=handles, loc="upper center", ncol=7, fontsize=8, frameon=False)
    fig.tight_layout(rect=(0, 0, 1, 1 - 0.3 / fig.get_figheight()))
    fig.savefig(path, dpi=120)
    plt.close(fig)


if __name__ == "__main__":
    main()
