"""The one figure style of snapmem: symbols with units, how branches, critical points and snaps
are drawn, legends outside the data, readable log axes.

Every figure of the studies and of ``snapmem trace/fold/hysteresis --plot`` goes through here:

- axis labels come from :data:`LABELS`, one mapping from table columns to symbols with units
  (normalised for the paper's scenes, where mu = 1; :data:`SI_LABELS` for the robots, ``si=True``);
- stable parts of a branch are solid, unstable parts dashed (:data:`STABLE`, :data:`UNSTABLE`);
- critical points are marked by kind (:data:`CRITICAL`: LP, BP, CP, EB, EMI, LT, LE, RU), each
  kind with one marker, and explained in a key beside the plot;
- a snap is an arrow at constant load from the limit point to the stable part it lands on;
- legends stand outside the axes, to the right; log axes get plain labels at 1, 2, 5 x 10^k
  when they span few decades and no minor labels, so tick labels never overlap.

matplotlib is imported inside the functions, only when a figure is drawn.
"""

from __future__ import annotations

import numpy as np

#: Column name -> (symbol, unit), for the paper's normalised scenes (mu = 1: p is p_hat).
LABELS = {
    "pressure": (r"$\hat p$", ""),
    "p_hat": (r"$\hat p$", ""),
    "p_limit": (r"$\hat p_{\mathrm{LP}}$", ""),
    "E_hat": (r"$\hat E$", ""),
    "E_hat_value": (r"$\hat E$", ""),
    "E_hat_limit": (r"$\hat E_{\mathrm{LP}}$", ""),
    "pressure_limit": (r"$\hat p_{\mathrm{LP}}$", ""),
    "voltage_limit": (r"$\phi_{\mathrm{LP}}$", "V"),
    "voltage": (r"$\phi$", "V"),
    "phi": (r"$\phi$", "V"),
    "stretch": (r"$\lambda$", ""),
    "stretch_max": (r"$\lambda_{\max}$", ""),
    "u_max_over_Rb": (r"$u_m/R_b$", ""),
    "deflection_normalised": (r"$u_m/R$", ""),
    "u_max_normalised": (r"$u_m/R_b$", ""),
    "u_max": (r"$u_m$", ""),
    "deflection": (r"$u_m$", ""),
    "volume": (r"$V$", ""),
    "gas_amount": (r"$nRT$", ""),
    "t": (r"$t$", "s"),
    "dt": (r"$\Delta t$", "s"),
    "wall_time_s": ("wall time", "s"),
    "nodes": (r"nodes $N$", ""),
    "aspect_ratio": (r"$R_s/R_b$", ""),
    "error": ("relative error", ""),
    "error_vs_richardson": (r"$|\hat p_{\mathrm{LP}}(N) - \hat p_{\mathrm{LP}}(\infty)|\,/\,\hat p_{\mathrm{LP}}(\infty)$", ""),
    "force": (r"contact force $F$", "N"),
    "height": (r"ball height $b_h$", "m"),
    "ball_apex": (r"apex height $b_{h,\max}$", "m"),
    "mb": (r"$m_b$", "kg"),
    "xi": (r"$\xi$", "1/s"),
    "dhat": (r"$\hat d$", "m"),
    "kappa": (r"$\kappa$", "Pa"),
    "Rw": (r"$R_w$", "m"),
    "min_tension": (r"$\min(T_1, T_2)$", ""),
}

#: The same where a scene is dimensional (``si=True``: the robots, in Pa, V, m, s).
SI_LABELS = {
    "pressure": (r"$p$", "Pa"),
    "p_limit": (r"$p_{\mathrm{LP}}$", "Pa"),
    "pressure_limit": (r"$p_{\mathrm{LP}}$", "Pa"),
    "u_max": (r"$u_m$", "m"),
    "deflection": (r"$u_m$", "m"),
    "volume": (r"$V$", "m$^3$"),
    "gas_amount": (r"$nRT$", "J"),
    "min_tension": (r"$\min(T_1, T_2)$", "N/m"),
}

#: Line styles of a branch's stable and unstable parts.
STABLE, UNSTABLE = "-", "--"

#: Critical point kind -> (marker, what it is). The order is the order of the key.
CRITICAL = {
    "LP": ("o", "limit point"),
    "EMI": ("o", "electromechanical instability"),
    "BP": ("s", "bifurcation point"),
    "CP": ("D", "cusp"),
    "EB": ("^", "electrical breakdown"),
    "LT": ("v", "loss of tension"),
    "LE": ("<", "loss of ellipticity"),
    "RU": ("X", "rupture"),
}

#: Size of a one-panel figure [in] (the axes; the legend is added beside it).
SIZE = (5.0, 3.6)
DPI = 150
RC = {"font.size": 9, "axes.titlesize": 9, "axes.labelsize": 9, "legend.fontsize": 8, "xtick.labelsize": 8,
      "ytick.labelsize": 8, "axes.grid": True, "grid.alpha": 0.3, "grid.linewidth": 0.5,
      "lines.linewidth": 1.4, "legend.frameon": False, "savefig.bbox": "tight", "savefig.pad_inches": 0.05}


def pyplot():
    """matplotlib.pyplot on the Agg backend with the snapmem style applied."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    plt.rcParams.update(RC)
    return plt


def _entry(column: str, si: bool):
    if si and column in SI_LABELS:
        return SI_LABELS[column]
    return LABELS.get(column, (column.replace("_", " "), ""))


def label(column: str, si: bool = False) -> str:
    """The axis label of a table column: its symbol and unit, e.g. ``$p$ [Pa]`` (``si``: the
    dimensional form; the normalised one has no unit)."""
    symbol, unit = _entry(column, si)
    return f"{symbol} [{unit}]" if unit else symbol


def value_label(column: str, value, si: bool = False) -> str:
    """Legend entry of one member of a family: ``$\\hat E$ = 0.1538``, ``$\\phi$ = 300 V``."""
    symbol, unit = _entry(column, si)
    shown = f"{value:g}" if isinstance(value, (float, int, np.floating, np.integer)) else str(value)
    return f"{symbol} = {shown}" + (f" {unit}" if unit else "")


def axes(size=SIZE, nrows: int = 1, ncols: int = 1, **kwargs):
    """A styled figure and its axes."""
    plt = pyplot()
    return plt.subplots(nrows, ncols, figsize=(size[0] * ncols, size[1] * nrows), **kwargs)


def set_labels(ax, x: str, y: str, si: bool = False) -> None:
    ax.set_xlabel(label(x, si))
    ax.set_ylabel(label(y, si))


def log_axis(ax, which: str = "both") -> None:
    """Log scale on ``which`` ('x', 'y' or 'both') with labels that cannot overlap: at 10^k, and
    also 2 and 5 x 10^k when the data span less than two decades; no minor tick labels. One
    format per axis: plain numbers when every tick is in [1e-3, 1e4], powers of ten otherwise."""
    from matplotlib import ticker
    for name in ("x", "y") if which == "both" else (which,):
        axis = ax.xaxis if name == "x" else ax.yaxis
        (ax.set_xscale if name == "x" else ax.set_yscale)("log")
        lo, hi = (ax.get_xlim() if name == "x" else ax.get_ylim())
        decades = np.log10(hi / lo) if lo > 0 and hi > lo else 3.0
        subs = (1.0, 2.0, 5.0) if decades < 2.0 else (1.0,)
        plain = lo >= 1e-3 and hi <= 1e4
        axis.set_major_locator(ticker.LogLocator(base=10.0, subs=subs))
        axis.set_major_formatter(ticker.FuncFormatter(lambda v, _pos, plain=plain: log_tick(v, plain)))
        axis.set_minor_locator(ticker.LogLocator(base=10.0, subs=np.arange(2, 10) * 1.0))
        axis.set_minor_formatter(ticker.NullFormatter())


def log_tick(value: float, plain: bool) -> str:
    """A log axis tick label: ``0.02`` (plain) or ``$2\\times10^{-5}$``."""
    if value <= 0:
        return ""
    if plain:
        return f"{value:g}"
    exponent = int(np.floor(np.log10(value) + 1e-9))
    mantissa = value / 10.0 ** exponent
    head = "" if abs(mantissa - 1) < 1e-6 else f"{mantissa:.0f}" + r"\times"
    return f"${head}10^{{{exponent}}}$"


# -------------------------------------------------------------------------------------------------
# branches
def stability(table) -> np.ndarray | None:
    """The ``stable`` column as booleans (missing values count as stable), or None without it."""
    if "stable" not in table:
        return None
    values = table["stable"]
    if values.dtype == object:
        values = values.map(lambda v: str(v).strip().lower() in ("true", "1", "nan", "none", ""))
    return values.fillna(True).astype(bool).to_numpy()


def point_kinds(table) -> np.ndarray:
    """The ``point`` column as strings ('' for ordinary points)."""
    if "point" not in table:
        return np.full(len(table), "", dtype=object)
    return np.array(["" if _missing(v) else str(v) for v in table["point"].to_numpy(dtype=object)], dtype=object)


def _missing(value) -> bool:
    return value is None or (isinstance(value, float) and np.isnan(value))


def draw_branch(ax, table, x: str, y: str, color=None, label: str | None = None, **kwargs):
    """One branch: runs of equal stability, solid where stable and dashed where not, joined at
    their common points. Returns (colour used, set of the key entries drawn: 'stable', 'unstable')."""
    xs, ys = table[x].to_numpy(dtype=float), table[y].to_numpy(dtype=float)
    stable = stability(table)
    if stable is None:
        (line,) = ax.plot(xs, ys, STABLE, color=color, label=label, **kwargs)
        return line.get_color(), set()
    start = 0
    for i in range(1, len(xs) + 1):
        if i == len(xs) or stable[i] != stable[start]:
            part = slice(start, min(i + 1, len(xs)))
            (line,) = ax.plot(xs[part], ys[part], STABLE if stable[start] else UNSTABLE, color=color,
                              label=label if start == 0 else None, **kwargs)
            color = line.get_color()
            start = i
    return color, {"stable" if s else "unstable" for s in stable}


def mark_critical(ax, table, x: str, y: str, color="k") -> set:
    """Mark the branch's critical points by kind (:data:`CRITICAL`); returns the kinds drawn."""
    kinds = point_kinds(table)
    drawn = set()
    for kind, (marker, _) in CRITICAL.items():
        rows = kinds == kind
        if rows.any():
            ax.plot(table[x].to_numpy()[rows], table[y].to_numpy()[rows], marker, ms=6, color=color, mfc="white",
                    mew=1.3, ls="none", zorder=5)
            drawn.add(kind)
    return drawn


def snaps(table, x: str, control: str) -> list:
    """Snaps of a branch traced in ``control``: from each limit point, at constant control, to the
    first stable point of the branch beyond the unstable part that follows it.

    A fold reached along a stable part (loading) jumps forward along the branch, one reached
    coming back (unloading) backward. Returns a list of ((x0, c), (x1, c)); a limit point whose
    load the branch never reaches again on a stable part has no snap drawn.
    """
    stable = stability(table)
    if stable is None:
        return []
    kinds = point_kinds(table)
    xs, cs = table[x].to_numpy(dtype=float), table[control].to_numpy(dtype=float)
    out = []
    for k in np.flatnonzero((kinds == "LP") | (kinds == "EMI")):
        if k == 0 or k + 1 == len(xs):
            continue
        before, after = bool(stable[k - 1]), bool(stable[k + 1])
        if before and not after:
            order = np.arange(k + 1, len(xs))          # loading: jump forward
        elif after and not before:
            order = np.arange(k - 1, -1, -1)           # unloading: jump back
        else:
            continue
        target = _stable_crossing(xs, cs, stable, order, cs[k])
        if target is not None:
            out.append(((xs[k], cs[k]), (target, cs[k])))
    return out


def _stable_crossing(xs, cs, stable, order, level):
    """x where the branch, walked in ``order`` past its unstable part, first crosses ``level`` on a
    stable segment (linear interpolation), or None."""
    left_unstable = False
    for a, b in zip(order[:-1], order[1:]):
        if not stable[a] or not stable[b]:
            left_unstable = True
            continue
        if not left_unstable:
            continue
        ca, cb = cs[a] - level, cs[b] - level
        if ca == 0.0:
            return xs[a]
        if ca * cb < 0.0:
            return xs[a] + (xs[b] - xs[a]) * ca / (ca - cb)
    return None


def draw_snap(ax, start, end, color="k") -> None:
    """A snap: an arrow at constant load from ``start`` to ``end`` (x, y)."""
    ax.annotate("", xy=end, xytext=start, zorder=6,
                arrowprops={"arrowstyle": "-|>", "color": color, "lw": 1.0, "ls": ":", "shrinkA": 4, "shrinkB": 2,
                            "mutation_scale": 10})


# -------------------------------------------------------------------------------------------------
# legends outside the data
def legend(ax, title: str | None = None, key=()) -> None:
    """The series legend beside the axes (right, top) and under it a key to what ``key`` names of
    'stable', 'unstable', the critical point kinds and 'snap' (what was drawn)."""
    from matplotlib.lines import Line2D
    handles, labels = ax.get_legend_handles_labels()
    anchor_y = 1.0
    if handles:
        first = ax.legend(handles, labels, title=title, loc="upper left", bbox_to_anchor=(1.02, 1.0),
                          borderaxespad=0.0, alignment="left")
        ax.add_artist(first)
        anchor_y = None
    entries = []
    if "unstable" in key:                     # the styles explained only where both appear
        entries += [Line2D([], [], color="0.3", ls=STABLE, label="stable"),
                    Line2D([], [], color="0.3", ls=UNSTABLE, label="unstable")]
    for kind in CRITICAL:
        if kind in key:
            marker, what = CRITICAL[kind]
            entries.append(Line2D([], [], color="0.3", marker=marker, mfc="white", ls="none", label=f"{kind}: {what}"))
    if "snap" in key:
        entries.append(Line2D([], [], color="0.3", ls=":", marker=">", markevery=[1], label="snap (constant load)"))
    if entries:
        ax.legend(handles=entries, loc="lower left" if anchor_y is None else "upper left",
                  bbox_to_anchor=(1.02, 0.0 if anchor_y is None else 1.0), borderaxespad=0.0)


def save(fig, path) -> None:
    """Save at the style's resolution with every legend beside the axes included, and close the figure."""
    import matplotlib.pyplot as plt
    from matplotlib.legend import Legend
    legends = [a for ax in fig.axes for a in (*ax.artists, ax.get_legend()) if isinstance(a, Legend)]
    fig.savefig(path, dpi=DPI, bbox_inches="tight", bbox_extra_artists=legends)
    plt.close(fig)
