"""Figures drawn from result tables (matplotlib imported only here, only when drawing)."""

from __future__ import annotations

import snapmem._lazy as _lazy

pd = _lazy.module("pandas")  # imported at first use (start-up)


def _pyplot():
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    return plt


def plot_branch(table: pd.DataFrame, x: str, y: str, path=None, ax=None, label: str | None = None,
                exact=None, title: str | None = None):
    """Draw a branch: stable parts solid, unstable dashed, limit and bifurcation points marked.

    Parameters
    ----------
    table : DataFrame
        A branch table (columns ``x``, ``y``, ``stable``, ``point``).
    x, y : str
        Columns on the axes.
    path : str or Path, optional
        Where to save a PNG (the figure is closed after saving).
    exact : (xs, ys), optional
        A reference curve drawn as a thin black line.
    """
    plt = _pyplot()
    own = ax is None
    if own:
        fig, ax = plt.subplots(figsize=(6, 4.2))
    stable = table["stable"].fillna(True).astype(bool).to_numpy() if "stable" in table else None
    xs, ys = table[x].to_numpy(), table[y].to_numpy()
    color = None
    if stable is None:
        (line,) = ax.plot(xs, ys, "-", label=label)
    else:
        # split into runs of equal stability, overlapping by one point so the curve is continuous
        start = 0
        for i in range(1, len(xs) + 1):
            if i == len(xs) or stable[i] != stable[start]:
                seg = slice(start, min(i + 1, len(xs)))
                (line,) = ax.plot(xs[seg], ys[seg], "-" if stable[start] else "--", color=color,
                                  label=label if start == 0 else None)
                color = line.get_color()
                start = i
    if exact is not None:
        ax.plot(exact[0], exact[1], "k-", lw=0.6, label="exact" if label is None else None)
    if "point" in table:
        for kind, marker in (("LP", "o"), ("BP", "s")):
            crit = table[table["point"] == kind]
            if len(crit):
                ax.plot(crit[x], crit[y], marker, mfc="none", color=color or "k", ms=7)
    ax.set_xlabel(x)
    ax.set_ylabel(y)
    if title:
        ax.set_title(title)
    if label is not None:
        ax.legend(fontsize=8)
    if own and path is not None:
        fig.tight_layout()
        fig.savefig(path, dpi=120)
        plt.close(fig)
    return ax


def plot_xy(table: pd.DataFrame, x: str, y: str, path, group: str | None = None, title: str | None = None,
            logx=False, logy=False, marker="o-"):
    """A plain line plot of y against x, one line per value of ``group``; saved to ``path``."""
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(6, 4.2))
    groups = [(None, table)] if group is None else list(table.groupby(group, sort=True))
    for key, sub in groups:
        ax.plot(sub[x], sub[y], marker, ms=3, label=None if key is None else f"{group} = {key:g}"
                if isinstance(key, float) else f"{group} = {key}")
    ax.set_xlabel(x)
    ax.set_ylabel(y)
    if logx:
        ax.set_xscale("log")
    if logy:
        ax.set_yscale("log")
    if group is not None:
        ax.legend(fontsize=8)
    if title:
        ax.set_title(title)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def plot_family(table: pd.DataFrame, x: str, y: str, group: str, path, exact=None, title: str | None = None,
                xlabel: str | None = None, ylabel: str | None = None):
    """One branch per value of ``group`` (stable solid, unstable dashed, critical points marked).

    ``exact`` maps a group value to (xs, ys) of a reference curve drawn thin and black.
    """
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(6, 4.2))
    for key, sub in table.groupby(group, sort=True):
        plot_branch(sub, x, y, ax=ax, label=f"{group} = {key:g}",
                    exact=None if exact is None else exact(key))
    ax.set_xlabel(xlabel or x)
    ax.set_ylabel(ylabel or y)
    if title:
        ax.set_title(title, fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def plot_hysteresis(table: pd.DataFrame, snaps: pd.DataFrame, x: str, y: str, path, title: str | None = None):
    """A hysteresis loop: each traced segment named, each snap a dotted jump at its load."""
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(6, 4.2))
    for segment, sub in table.groupby("segment", sort=False):
        plot_branch(sub, x, y, ax=ax, label=segment)
    for _, s in snaps.iterrows():
        ax.annotate("", xy=(s[f"{x}_after"], s["control_settled"]), xytext=(s[f"{x}_before"], s["control_settled"]),
                    arrowprops={"arrowstyle": "->", "linestyle": ":", "color": "k"})
        ax.text(0.5 * (s[f"{x}_before"] + s[f"{x}_after"]), s["control_settled"], s["event"], fontsize=8,
                ha="center", va="bottom")
    ax.set_xlabel(x)
    ax.set_ylabel(y)
    if title:
        ax.set_title(title, fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
