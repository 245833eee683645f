"""The balloon on a gas reservoir: its snap shrinks and vanishes as the reservoir shrinks (a cusp).

The MODEL.md validation balloon (R = 10, H = 0.1, mu = 1) is inflated from a reservoir of volume
V_d holding a fixed amount of gas A (``balloon --set chamber=gas --set gas_volume=V_d``, traced in
``--control gas_amount``; p_atm = 0.25). The gas law (p + p_atm)(V + V_d) = A (isothermal; P V^gamma
adiabatic) stiffens the chamber: with a large reservoir the gas amount has a maximum and a
minimum (a snap up and a snap back, tending to the pressure-controlled ones), with a small one
none (as under volume control). The two limit points merge at a cusp V_d*.

The limit points are continued in V_d along the pressure branch of the same mesh
(snapmem.continuation.chambers.reservoir_folds: a point of the branch is a limit point of A for
exactly one V_d = -gamma P dV/dp - V), the cusp located by Brent's method on the branch, and the
pair for a given V_d by root finding on it (reservoir_limit_points); a few reservoirs are checked
against traces of the gas-chamber scene itself (``check`` rows: its limit points' pressures).
The exact 1-DOF curve (snapmem.reference.gas_balloon) is drawn under the computed one.

Writes gas_balloon.csv (the cusp's V_d at N = 51, 101, 201, isothermal and adiabatic, against the
exact value: relative error and observed order, expected 2), gas_balloon.curve.csv (the limit-point
pair against V_d at N = 101 with the exact one, and the gas-chamber traces' check) and
gas_balloon.png.
"""

import numpy as np
import pandas as pd

from snapmem import build_scene
from snapmem.continuation import trace
from snapmem.continuation.chambers import reservoir_folds, reservoir_limit_points
from snapmem.reference import gas_balloon as exact
from snapmem.reference.exact import balloon_extrema
from snapmem.reference.two_balloons import balloon_volume
from snapmem.study import parse_args, save
from snapmem.viz import style

P_ATM = 0.25                           # ambient absolute pressure (the scene's default, ~1 bar for mu = 0.42 MPa)
STRETCH_LIMIT = 3.2                    # the pressure branch is traced past its minimum (lam 2.59)
V_REF = float(balloon_volume(1.0))     # the balloon's reference volume [m^3]


def pressure_branch(nodes: int):
    """The plain balloon traced in pressure past its pressure minimum."""
    return trace(build_scene("balloon", nodes=nodes), "pressure", until={"stretch": STRETCH_LIMIT})


def cusp_errors(sizes) -> pd.DataFrame:
    """The cusp (V_d*, its pressure and stretch) at each N against the exact one, isothermal and adiabatic."""
    rows = []
    for n in sizes:
        branch = pressure_branch(n)
        for gamma in (1.0, 1.4):
            c, e = reservoir_folds(branch, P_ATM, gamma)["cusp"], exact.cusp(p_atm=P_ATM, gamma=gamma)
            rows.append({"gamma": gamma, "nodes": n, "reservoir": c["reservoir"], "reservoir_ratio": c["reservoir"] / V_REF,
                         "pressure": c["pressure"], "stretch": c["stretch"], "exact_reservoir": e["reservoir"],
                         "exact_pressure": e["pressure"], "exact_stretch": e["lam"]})
    t = pd.DataFrame(rows)
    for q in ("reservoir", "pressure", "stretch"):
        t[f"{q}_error"] = (t[q] / t[f"exact_{q}"] - 1).abs()
    t["reservoir_order"] = t.groupby("gamma")["reservoir_error"].transform(
        lambda e: np.log(e.shift(1) / e) / np.log(2.0))              # N - 1 doubles from row to row
    return t


def fold_pair_curve(nodes: int, ratios, checked) -> pd.DataFrame:
    """The limit-point pair against V_d = ratio V_d* (snapmem and exact); at the ``checked`` ratios
    also the gas-chamber scene's own limit points (traced in gas_amount)."""
    branch = pressure_branch(nodes)
    found = reservoir_folds(branch, P_ATM)["cusp"]
    rows = []
    for ratio in ratios:
        reservoir = ratio * found["reservoir"]
        pair = reservoir_limit_points(branch, reservoir, P_ATM, cusp=found)
        truth = exact.limit_points(ratio * exact.cusp(p_atm=P_ATM)["reservoir"], p_atm=P_ATM)
        traced = [np.nan, np.nan]
        if ratio in checked:
            scene = build_scene("balloon", nodes=nodes, chamber="gas", gas_volume=reservoir, p_atm=P_ATM)
            lps = trace(scene, "gas_amount", until={"stretch_max": STRETCH_LIMIT}).limit_points()
            traced = list(lps["pressure"].iloc[:2]) + [np.nan] * (2 - min(len(lps), 2))
        for k, (q, side) in enumerate(zip(pair, ("max", "min"))):
            rows.append({"ratio": ratio, "reservoir": reservoir, "reservoir_ratio": reservoir / V_REF, "side": side,
                         "stretch": q["stretch"], "pressure": q["pressure"], "amount": q["amount"],
                         "exact_stretch": truth[k][0], "exact_pressure": truth[k][1], "exact_amount": truth[k][2],
                         "traced_pressure": traced[k]})
    t = pd.DataFrame(rows)
    top = t[t["side"] == "max"].set_index("ratio")["amount"]
    bottom = t[t["side"] == "min"].set_index("ratio")["amount"]
    t["snap_size"] = t["ratio"].map((top - bottom) / top)              # (A_max - A_min) / A_max
    exact_top = t[t["side"] == "max"].set_index("ratio")["exact_amount"]
    exact_bottom = t[t["side"] == "min"].set_index("ratio")["exact_amount"]
    t["exact_snap_size"] = t["ratio"].map((exact_top - exact_bottom) / exact_top)
    return t


def draw(curve: pd.DataFrame, cusps: pd.DataFrame, path) -> None:
    """Left: the stretch at the two limit points against V_d / V_ref, merging at the cusp.
    Right: the snap's size in the gas amount against the distance from the cusp (exponent 3/2)."""
    fig, (left, right) = style.axes(ncols=2)
    (lam_max, _), (lam_min, _) = balloon_extrema()[:2]
    e = exact.cusp(p_atm=P_ATM)
    lam = np.linspace(lam_max + 1e-4, lam_min - 1e-4, 800)
    left.plot(exact.reservoir_at_fold(lam, p_atm=P_ATM) / V_REF, lam, color="0.75", lw=3.5, label="exact (1-DOF)")
    for side, marker, what in (("max", "o", "max of $nRT$ (snap)"), ("min", "s", "min of $nRT$ (snap back)")):
        sub = curve[curve["side"] == side]
        left.plot(sub["reservoir_ratio"], sub["stretch"], color="C0", marker=marker, ms=3, lw=1.0,
                  label=f"N = 101: {what}")
    c101 = cusps[(cusps["nodes"] == 101) & (cusps["gamma"] == 1.0)].iloc[0]
    marker, _ = style.CRITICAL["CP"]
    left.plot([c101["reservoir_ratio"]], [c101["stretch"]], ls="none", marker=marker, mfc="white", color="k",
              label=f"cusp: $V_d^*/V_0$ = {c101['reservoir_ratio']:.1f}")
    low, high = e["reservoir_ratio"] * 0.5, curve["reservoir_ratio"].max() * 1.5
    left.set_xlim(low, high)
    for value, text in ((lam_max, r"pressure control: $\hat p$ maximum"), (lam_min, r"$\hat p$ minimum")):
        left.axhline(value, color="0.4", lw=0.8, ls=":")
        left.text(high / 1.2, value, text, fontsize=7, va="bottom", ha="right", color="0.3")
    left.axvspan(low, e["reservoir_ratio"], color="0.92", lw=0)
    left.text(low * 1.1, 0.5 * (lam_max + lam_min), "no snap", fontsize=7, color="0.3", rotation=90, va="center")
    style.log_axis(left, "x")
    left.set_xlabel(r"reservoir volume $V_d / V_0$ ($V_0$: the balloon's reference volume)")
    left.set_ylabel(r"stretch at the limit points $\lambda_{\mathrm{LP}}$")
    left.set_title("balloon on a gas reservoir: limit points of the gas amount")

    sub = curve[curve["side"] == "max"]
    distance = sub["ratio"] - 1.0
    right.plot(distance, sub["exact_snap_size"], color="0.75", lw=3.5, label="exact")
    right.plot(distance, sub["snap_size"], color="C0", marker="o", ms=3, lw=1.0, label="N = 101")
    near = distance < 0.3
    ref = 3.0 * sub["snap_size"].iloc[0] * (distance[near] / distance.iloc[0]) ** 1.5
    right.plot(distance[near], ref, color="k", lw=0.8, ls="--", label=r"$\propto (V_d/V_d^* - 1)^{3/2}$")
    style.log_axis(right)
    right.set_xlabel(r"distance from the cusp $V_d / V_d^* - 1$")
    right.set_ylabel(r"snap in the gas amount $(A_{\max} - A_{\min}) / A_{\max}$")
    right.set_title("the snap vanishes at the cusp")
    left.legend(loc="center right", fontsize=7)
    right.legend(loc="lower right", fontsize=8)
    style.save(fig, path)


def main(argv=None):
    args = parse_args(__doc__, argv)
    sizes = [51, 101] if args.quick else [51, 101, 201]
    cusps = cusp_errors(sizes)
    save(args, "gas_balloon", cusps, sizes=sizes, R=10.0, H=0.1, c1=0.4375, c2=0.0625, p_atm=P_ATM)
    ratios = 1.0 + (np.geomspace(1e-3, 1e2, 8) if args.quick else np.geomspace(1e-4, 1e3, 36))
    checked = (ratios[2], ratios[-1]) if args.quick else (ratios[10], ratios[20], ratios[30])
    curve = fold_pair_curve(101, ratios, checked)
    save(args, "gas_balloon.curve", curve, nodes=101, p_atm=P_ATM, checked=[float(r) for r in checked])
    draw(curve, cusps, args.out / "gas_balloon.png")
    with pd.option_context("display.width", 200):
        print(cusps[["gamma", "nodes", "reservoir_ratio", "reservoir_error", "reservoir_order",
                     "pressure_error", "stretch_error"]].to_string(index=False))
        print(curve.dropna(subset=["traced_pressure"])[["ratio", "side", "pressure", "traced_pressure",
                                                        "exact_pressure"]].to_string(index=False))
    return cusps


if __name__ == "__main__":
    main()
