"""Figures drawn from result tables, in the one style of :mod:`snapmem.viz.style`.

Branches: stable parts solid, unstable dashed, critical points marked by kind, snaps as arrows
at constant load; axis labels are the columns' symbols with units; legends beside the axes.
matplotlib is imported only when drawing.
"""

from __future__ import annotations

import snapmem._lazy as _lazy

pd = _lazy.module("pandas")  # imported at first use (start-up)

from snapmem.viz import style

#: Columns that are loads: a branch drawn against one of them gets its snaps drawn.
LOADS = ("pressure", "E_hat", "voltage", "p_hat")


def _pyplot():
    """matplotlib.pyplot with the snapmem style (kept for the studies that draw their own panels)."""
    return style.pyplot()


def _finish(fig, ax, path, title, key=(), legend_title=None):
    if title:
        ax.set_title(title)
    style.legend(ax, title=legend_title, key=key)
    if path is not None:
        style.save(fig, path)


def plot_branch(table: pd.DataFrame, x: str, y: str, path=None, ax=None, label: str | None = None,
                exact=None, title: str | None = None, control: str | None = None, si: bool = False,
                color=None):
    """Draw a branch: stable solid, unstable dashed, critical points marked, snaps as arrows.

    Parameters
    ----------
    table : DataFrame
        A branch table (columns ``x``, ``y``, and ``stable``, ``point`` where present).
    x, y : str
        Columns on the axes (labelled by :data:`snapmem.viz.style.LABELS`).
    path : str or Path, optional
        Where to save a PNG (a figure of its own, closed after saving).
    ax : matplotlib Axes, optional
        Draw into these axes instead (no legend, no saving: the caller finishes the figure).
    label : str, optional
        Legend entry of the branch.
    exact : (xs, ys), optional
        A reference curve, drawn as a wide light line under the branch.
    control : str, optional
        The load the branch was traced in; snaps are drawn when it is the y axis (default: y if
        y is a load column).
    si : bool
        Dimensional axis labels (Pa, V, m) instead of the normalised ones.

    Returns
    -------
    (ax, key) : the axes and the set of key entries drawn ('stable', 'unstable', critical point
    kinds, 'snap'), for :func:`snapmem.viz.style.legend`.
    """
    own = ax is None
    if own:
        fig, ax = style.axes()
    if exact is not None:
        ax.plot(exact[0], exact[1], "-", color="0.75", lw=3.5, zorder=1, solid_capstyle="round",
                label="exact" if own else None)
    color, key = style.draw_branch(ax, table, x, y, color=color, label=label, zorder=3)
    key |= style.mark_critical(ax, table, x, y, color=color)
    control = control or (y if y in LOADS else None)
    jumps = style.snaps(table, x, control) if control == y else []
    for start, end in jumps:
        style.draw_snap(ax, start, end, color=color)
        key.add("snap")
    style.set_labels(ax, x, y, si)
    if own:
        _finish(fig, ax, path, title, key)
    return ax, key


def plot_family(table: pd.DataFrame, x: str, y: str, group: str, path, exact=None, title: str | None = None,
                xlabel: str | None = None, ylabel: str | None = None, si: bool = False, control: str | None = None):
    """One branch per value of ``group`` (stable solid, unstable dashed, critical points, snaps).

    ``exact`` maps a group value to (xs, ys) of a reference curve, drawn wide and light under it.
    """
    fig, ax = style.axes()
    drawn = set()
    for key, sub in table.groupby(group, sort=True):
        drawn |= plot_branch(sub, x, y, ax=ax, label=style.value_label(group, key, si),
                             exact=None if exact is None else exact(key), control=control, si=si)[1]
    if exact is not None:
        ax.plot([], [], "-", color="0.75", lw=3.5, label="exact")
    ax.set_xlabel(xlabel or style.label(x, si))
    ax.set_ylabel(ylabel or style.label(y, si))
    _finish(fig, ax, path, title, drawn)


def plot_xy(table: pd.DataFrame, x: str, y: str, path=None, group: str | None = None, title: str | None = None,
            logx=False, logy=False, marker="o-", ax=None, si: bool = False, legend_title: str | None = None):
    """Lines of y against x, one per value of ``group``; saved to ``path`` (or drawn into ``ax``).

    Numbers of ``group`` are shown as ``symbol = value unit``; text values as they are (under
    ``legend_title``).
    """
    own = ax is None
    if own:
        fig, ax = style.axes()
    groups = [(None, table)] if group is None else list(table.groupby(group, sort=True))
    for key, sub in groups:
        name = None if key is None else (key if isinstance(key, str) else style.value_label(group, key, si))
        ax.plot(sub[x], sub[y], marker, ms=3.5, label=name)
    style.set_labels(ax, x, y, si)
    if logx:
        style.log_axis(ax, "x")
    if logy:
        style.log_axis(ax, "y")
    if own:
        _finish(fig, ax, path, title, legend_title=legend_title)
    elif title:
        ax.set_title(title)
    return ax


def plot_hysteresis(table: pd.DataFrame, snaps: pd.DataFrame, x: str, y: str, path, title: str | None = None,
                    si: bool = False):
    """A hysteresis loop: each traced segment a branch, each snap an arrow at its settled load."""
    fig, ax = style.axes()
    drawn = {"snap"} if len(snaps) else set()
    for segment, sub in table.groupby("segment", sort=False):
        drawn |= plot_branch(sub, x, y, ax=ax, label=str(segment), control="none", si=si)[1]
    for _, s in snaps.iterrows():
        style.draw_snap(ax, (s[f"{x}_before"], s["control_settled"]), (s[f"{x}_after"], s["control_settled"]))
        ax.text(0.5 * (s[f"{x}_before"] + s[f"{x}_after"]), s["control_settled"], s["event"], fontsize=7,
                ha="center", va="bottom")
    _finish(fig, ax, path, title, drawn)
