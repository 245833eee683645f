"""The critical points of the DE balloon (MR c1 = 0.4375, c2 = 0.0625, R = 10, H = 0.1) against the
membrane sphere's bifurcation criterion, and their convergence with the mesh.

For E_hat = 0.4 (up to stretch 3.7) and 0.5 (up to 2.4, short of the loss of ellipticity near
2.65), supports 'pole' and 'free', N = 51, 101, 201, 401: every LP and BP of the uniform branch
with its kind, Legendre mode n (from the null vector), stretch and pressure, the criterion's root
for that n beside it (for an LP the pressure extremum; of the roots the one where dp/dl < 0),
the error, and the observed order log2(e_{N/2} / e_N). Writes balloon_bifurcations.csv and
balloon_bifurcations.png (error against N).
"""

import numpy as np
import pandas as pd

from snapmem import build_scene
from snapmem.continuation import trace
from snapmem.reference.exact import balloon_extrema, balloon_pressure, sphere_bifurcation_stretches
from snapmem.study import parse_args, save

CASES = {0.4: 3.7, 0.5: 2.4}                  # E_hat: the stretch the trace stops at


def criterion_stretch(mode: int, E_hat: float) -> float:
    """The criterion's root for mode n where dp/dl < 0 (between the pressure maximum and the
    minimum, if any); for an LP (mode -1) the pressure maximum."""
    extrema = [lam for lam, _ in balloon_extrema(E_hat=E_hat)]
    if mode < 0:
        return extrema[0]
    upper = extrema[1] if len(extrema) > 1 else np.inf
    roots = [r for r in sphere_bifurcation_stretches(mode, E_hat=E_hat) if extrema[0] < r < upper]
    return roots[0] if roots else np.nan


def points(E_hat: float, support: str, nodes: int) -> pd.DataFrame:
    branch = trace(build_scene("balloon", ("pressure",), E_hat=E_hat, nodes=nodes, support=support),
                   "pressure", until={"stretch": CASES[E_hat]})
    t = branch.points.copy()
    t.insert(0, "E_hat_value", E_hat)
    t.insert(1, "support", support)
    t.insert(2, "nodes", nodes)
    t["criterion_stretch"] = [criterion_stretch(int(n), E_hat) for n in t["mode"]]
    t["criterion_pressure"] = balloon_pressure(t["criterion_stretch"], E_hat=E_hat)
    t["error"] = t["stretch"] - t["criterion_stretch"]
    return t


def draw(t: pd.DataFrame, path) -> None:
    """|stretch - criterion| against N, one line per critical point, legend beside the axes."""
    from snapmem.viz import style
    fig, ax = style.axes()
    for (kind, mode), sub in t.groupby(["kind", "mode"]):
        ax.plot(sub["nodes"], sub["error"].abs(), "o-", ms=3, label=kind if mode < 0 else f"{kind} n = {mode}")
    style.log_axis(ax)
    from matplotlib import ticker
    ax.xaxis.set_major_locator(ticker.FixedLocator(sorted(t["nodes"].unique())))   # a tick at every mesh
    ax.set_xlabel(style.label("nodes"))
    ax.set_ylabel(r"$|\lambda - \lambda_{\mathrm{criterion}}|$")
    ax.set_title(f"balloon, {style.value_label('E_hat', t['E_hat_value'].iloc[0])}, support {t['support'].iloc[0]}")
    style.legend(ax, title="critical point")
    style.save(fig, path)


def main(argv=None):
    args = parse_args(__doc__, argv)
    sizes = [51, 101, 201] if args.quick else [51, 101, 201, 401]
    supports = ["free"] if args.quick else ["pole", "free"]
    cases = [0.4] if args.quick else list(CASES)
    t = pd.concat([points(E, s, n) for E in cases for s in supports for n in sizes], ignore_index=True)
    if "imperfection" not in t:
        t["imperfection"] = np.nan
    keys = ["E_hat_value", "support", "kind", "mode"]
    t["observed_order"] = t.groupby(keys)["error"].transform(lambda e: np.log2(e.abs().shift(1) / e.abs()))
    columns = keys + ["nodes", "stretch", "pressure", "criterion_stretch", "criterion_pressure", "error",
                      "observed_order", "located", "coupling", "symmetry_broken", "imperfection", "crossed"]
    t = t[columns]
    save(args, "balloon_bifurcations", t, cases=CASES, sizes=sizes)
    draw(t[(t["support"] == "free") & (t["E_hat_value"] == cases[-1])], args.out / "balloon_bifurcations.png")
    print(t[columns].to_string(index=False))
    return t


if __name__ == "__main__":
    main()
