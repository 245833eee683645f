"""Stability atlas of the DE balloon (MR 1/7, R = 10, H = 0.1) in the (E_hat, pressure) plane.

Every curve is a continuation in E_hat (snapmem.continuation.atlas): the pressure maximum and
minimum (LP curves) from the branch at E_hat = 0, the P1 (pole held) and P2 bifurcation curves
from the branch at E_hat = 0.4, each followed both ways until it leaves 0 <= E_hat <= 0.6, passes
stretch 5 or loses ellipticity; loss-of-ellipticity points end branches traced at a few E_hat.
A second panel follows the limit point in c2 (mu = 2 (c1 + c2) = 1 fixed) through its cusp, a
third the torus's limit point over its aspect ratio Rs/Rb (the same continuation).
Exact values (MODEL.md section 7) sit beside every row: ``pressure_exact``.
Writes results/balloon_atlas.csv and results/balloon_atlas.png.
"""

import numpy as np
import pandas as pd

from snapmem import build_scene
from snapmem.continuation.atlas import Seed, stability_atlas
from snapmem.reference import exact
from snapmem.study import parse_args, save


def exact_pressure(row):
    """The exact sphere's pressure on the row's curve at its E_hat (or c2), nearest its stretch."""
    E, c1, c2 = (row["v"], 0.4375, 0.0625) if row["plane"] == "E_hat" else (0.0, 0.4375, row["v"])
    if row["plane"] == "c2":
        c1, c2 = 0.5 * c1 / (c1 + c2), 0.5 * c2 / (c1 + c2)
    if row["curve"].startswith("BP P"):
        lams = exact.sphere_bifurcation_stretches(int(row["curve"][-1]), c1, c2, E)
    elif row["curve"] == "LE":
        lams = [exact.sphere_ellipticity_loss(c1, c2, E)]
    else:
        lams = [lam for lam, _ in exact.balloon_extrema(c1=c1, c2=c2, E_hat=E, lam_max=10.0)]
    lams = [lam for lam in lams if lam is not None]
    if not lams:
        return np.nan
    lam = min(lams, key=lambda s: abs(s - row["stretch"]))
    return float(exact.balloon_pressure(lam, c1=c1, c2=c2, E_hat=E))


def main(argv=None):
    args = parse_args(__doc__, argv)
    nodes, step = (31, 0.1) if args.quick else (81, 0.05)
    seeds = [Seed("LP max", 0.0, ("stretch", 1.53)), Seed("LP min", 0.0, ("stretch", 2.59)),
             Seed("BP P1", 0.4, ("stretch", 1.77), "BP"), Seed("BP P2", 0.4, ("stretch", 2.95), "BP")]
    e_plane, work = stability_atlas(lambda E: build_scene("balloon", nodes=nodes, E_hat=E), seeds, (0.0, 0.6),
                                    le_values=[0.45, 0.5, 0.55, 0.6] if not args.quick else [0.5], ds_max=step)
    c_plane, work_c = stability_atlas(lambda c2: build_scene("balloon", nodes=nodes, mu=1.0, c2=c2),
                                      [Seed("LP", 0.0625, ("stretch", 1.53))], (0.0625, 0.12), ds_max=step)
    torus, work_t = stability_atlas(lambda a: build_scene("torus", nodes=2 * nodes // 3, aspect_ratio=a),
                                    [Seed("LP", 0.2, ("u_max", 0.0))], (0.05, 0.9), until={"u_max": 6.0},
                                    stretch_max=6.0, ds_max=2 * step)
    table = pd.concat([e_plane.assign(plane="E_hat"), c_plane.assign(plane="c2"),
                       torus.assign(plane="aspect_ratio")], ignore_index=True)
    table["pressure_exact"] = [exact_pressure(row) if row["plane"] != "aspect_ratio" else np.nan
                               for _, row in table.iterrows()]
    save(args, "balloon_atlas", table, nodes=nodes,
         newton_iterations=sum(w["newton_iterations"] for w in (work, work_c, work_t)))
    draw(table, args.out / "balloon_atlas.png")
    return table


def draw(table, path):
    """Two panels from the CSV: the (E_hat, p) atlas and the fold curve through its cusp in c2/c1."""
    from snapmem.viz.style import pyplot
    plt = pyplot()
    fig, (ax, bx, tx) = plt.subplots(1, 3, figsize=(15, 5.2), gridspec_kw={"width_ratios": [1.6, 1, 1]})
    below = dict(loc="upper center", bbox_to_anchor=(0.5, -0.16), ncol=2)       # legends outside the data
    e = table[table["plane"] == "E_hat"]
    styles = {"LP max": "C0", "LP min": "C4", "BP P1": "C1", "BP P2": "C2"}
    names = {"BP P1": "BP P1 (pole held: exact BP)", "BP P2": "BP P2 (unfolded: perfect problem's BP)"}
    for name, colour in styles.items():
        for _, part in e[(e["curve"] == name) & (e["kind"].fillna("") == "")].groupby("direction"):
            part = part.sort_values("v")
            ax.plot(part["v"], 1e3 * part["pressure"], "-", color=colour, lw=1.8,
                    label=names.get(name, name) if part["direction"].iloc[0] == 1 else None)
            ax.plot(part["v"], 1e3 * part["pressure_exact"], ":", color="k", lw=1)
    le = e[e["curve"] == "LE"]
    ax.plot(le["v"], 1e3 * le["pressure"], "kx", ms=8, label="LE located on traced branches")
    grid = np.linspace(0.36, 0.6, 40)
    lam = [exact.sphere_ellipticity_loss(E_hat=E) for E in grid]
    ax.plot(grid, [1e3 * exact.balloon_pressure(x, E_hat=E) if x else np.nan for x, E in zip(lam, grid)], "k--", lw=1,
            label="LE of the uniform sphere (W11 = 0)")
    special = e[e["kind"].isin(["TP", "CP"])]
    if len(special):
        ax.plot(special["v"], 1e3 * special["pressure"], "rs", ms=6, label="turning point in E_hat (TP)")
    ax.plot([], [], ":", color="k", lw=1, label="exact sphere")
    ax.set_xlim(0.0, None)
    ax.set_xlabel(r"normalised voltage $\hat E$")
    ax.set_ylabel(r"pressure $\hat p \times 10^3$")
    ax.set_title("DE balloon: limit and bifurcation curves")
    ax.legend(**below)
    c = table[(table["plane"] == "c2")]
    curve = c[c["kind"].fillna("") == ""]
    for _, part in curve.groupby("direction"):
        part = part.sort_values("s")
        bx.plot(part["v"] / 0.4375, 1e3 * part["pressure"], "-", color="C0", lw=1.8)
    cusp = c[c["kind"] == "CP"]
    bx.plot(cusp["v"] / 0.4375, 1e3 * cusp["pressure"], "r*", ms=12, label=f"cusp (CP) c2/c1 = {cusp['v'].iloc[0] / 0.4375:.4f}"
            if len(cusp) else "cusp")
    ratio = exact.balloon_cusp_mooney_rivlin()[0]
    bx.axvline(ratio, color="k", ls=":", lw=1, label=f"exact {ratio:.4f}")
    bx.set_xlabel(r"$c_2/c_1$ ($\mu = 2(c_1 + c_2)$ fixed)")
    bx.set_ylabel(r"limit pressure $\hat p \times 10^3$")
    bx.set_title(r"LP curve through its cusp ($\hat E = 0$)")
    bx.legend(**below)
    torus = table[(table["plane"] == "aspect_ratio") & (table["kind"].fillna("") == "")]
    for _, part in torus.groupby("direction"):
        part = part.sort_values("v")
        tx.plot(part["v"], 1e3 * part["pressure"], "-", color="C0", lw=1.8)
    tx.set_yscale("log")
    tx.set_xlabel(r"torus aspect ratio $R_s/R_b$")
    tx.set_ylabel(r"limit pressure $\hat p \times 10^3$")
    tx.set_title(r"torus counterpart: LP curve ($\hat E = 0$)")
    fig.tight_layout()
    fig.savefig(path, dpi=130, bbox_inches="tight")
    plt.close(fig)


if __name__ == "__main__":
    main()
