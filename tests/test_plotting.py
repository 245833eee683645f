"""The figure style: snaps land where the exact balloon regains its load, labels carry symbols and
units, log tick labels never overlap, legends stand outside the data."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from scipy.optimize import brentq

from snapmem import exact
from snapmem.viz import style
from snapmem.viz.plotting import plot_branch, plot_family, plot_xy


def exact_branch(lam_max=4.0, points=3001, E_hat=0.0) -> pd.DataFrame:
    """The balloon's exact p(lam) as a branch table: stable where dp/dlam > 0, the extrema as LPs."""
    lam = np.linspace(1.0, lam_max, points)
    extrema = exact.balloon_extrema(E_hat=E_hat)
    lam = np.unique(np.concatenate([lam, [l for l, _ in extrema if l < lam_max]]))
    p = exact.balloon_pressure(lam, E_hat=E_hat)
    point = np.where(np.isin(lam, [l for l, _ in extrema]), "LP", "")
    stable = exact.balloon_pressure_slope(lam, E_hat=E_hat) > 0
    stable[point == "LP"] = False                        # the fold itself: the unstable side's value
    return pd.DataFrame({"stretch": lam, "pressure": p, "stable": stable, "point": point})


def test_snaps_land_where_the_exact_balloon_regains_its_load():
    table = exact_branch()
    (l_max, p_max), (l_min, p_min) = exact.balloon_extrema()[:2]
    jumps = style.snaps(table, "stretch", "pressure")
    assert len(jumps) == 2
    (up_from, up_to), (down_from, down_to) = jumps
    # snap-through at the maximum, forward, onto the stiffening branch at the same pressure
    far = brentq(lambda l: exact.balloon_pressure(l) - p_max, l_min, 4.0)
    assert up_from == pytest.approx((l_max, p_max), rel=1e-12)
    assert up_to[0] == pytest.approx(far, abs=1e-5) and up_to[1] == p_max
    # snap-back at the minimum, backward, onto the first rising part
    near = brentq(lambda l: exact.balloon_pressure(l) - p_min, 1.0, l_max)
    assert down_to[0] == pytest.approx(near, abs=1e-5) and down_to[1] == p_min


def test_no_snap_where_the_load_is_never_regained():
    table = exact_branch(lam_max=3.0)                    # stops before p regains its maximum
    jumps = style.snaps(table, "stretch", "pressure")
    assert len(jumps) == 1 and jumps[0][1][0] < table["stretch"][table["point"] == "LP"].iloc[0]
    assert style.snaps(table.assign(point=""), "stretch", "pressure") == []


def test_labels_are_symbols_with_units():
    assert style.label("pressure") == r"$\hat p$"
    assert style.label("pressure", si=True) == "$p$ [Pa]"
    assert style.label("voltage") == r"$\phi$ [V]"
    assert style.label("volume", si=True) == "$V$ [m$^3$]"
    assert style.label("u_max_over_Rb") == "$u_m/R_b$"
    assert style.label("some_column") == "some column"
    assert style.value_label("E_hat_value", 0.1538) == r"$\hat E$ = 0.1538"
    assert style.value_label("phi", 300.0) == r"$\phi$ = 300 V"
    from matplotlib.mathtext import MathTextParser
    parser = MathTextParser("path")
    for column in {**style.LABELS, **style.SI_LABELS}:
        for si in (False, True):
            parser.parse(style.label(column, si))       # every label is valid mathtext


def test_log_tick_labels():
    assert style.log_tick(0.02, plain=True) == "0.02"
    assert style.log_tick(1e-5, plain=False) == "$10^{-5}$"
    assert style.log_tick(2e-4, plain=False) == r"$2\times10^{-4}$"


def _overlaps(boxes) -> bool:
    boxes = sorted(boxes, key=lambda b: b.x0)
    return any(a.overlaps(b) for i, a in enumerate(boxes) for b in boxes[i + 1:])


@pytest.mark.parametrize("lo, hi", [(0.019, 0.055), (2e-3, 4e-2), (1e-6, 0.2), (3e-4, 2e-3)])
def test_log_axis_labels_never_overlap(lo, hi):
    fig, ax = style.axes()
    ax.plot([lo, hi], [lo, hi])
    style.log_axis(ax)
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    for axis in (ax.xaxis, ax.yaxis):
        labels = [t for t in axis.get_ticklabels(which="both") if t.get_visible() and t.get_text()]
        assert len(labels) >= 2, (lo, hi)                       # something to read
        assert not _overlaps([t.get_window_extent(renderer).expanded(1.05, 1.0) for t in labels])
    style.pyplot().close(fig)


def test_branch_drawn_stable_solid_unstable_dashed_with_snaps(tmp_path):
    table = exact_branch()
    ax, key = plot_branch(table, "stretch", "pressure", ax=style.axes()[1])
    assert key == {"stable", "unstable", "LP", "snap"}
    styles = {line.get_linestyle() for line in ax.get_lines()}
    assert {"-", "--"} <= styles
    markers = [line for line in ax.get_lines() if line.get_marker() == "o"]
    assert sum(len(line.get_xdata()) for line in markers) == 2
    assert len([c for c in ax.get_children() if type(c).__name__ == "Annotation"]) == 2
    style.pyplot().close(ax.figure)


def test_legends_stand_outside_the_data(tmp_path):
    table = pd.concat([exact_branch(E_hat=E, points=400).assign(E_hat_value=E) for E in (0.0, 0.2)])
    captured = {}
    original = style.save

    def keep(fig, path):
        fig.canvas.draw()
        captured["fig"] = fig
        original(fig, path)

    style.save = keep
    try:
        plot_family(table, "stretch", "pressure", "E_hat_value", tmp_path / "family.png")
        plot_xy(table, "stretch", "pressure", tmp_path / "xy.png", group="E_hat_value", logy=False)
    finally:
        style.save = original
    fig = captured["fig"]
    ax = fig.axes[0]
    legends = [a for a in ax.get_children() if type(a).__name__ == "Legend"]
    assert legends
    for legend in legends:
        assert legend.get_window_extent().x0 > ax.get_window_extent().x1
    for name in ("family.png", "xy.png"):
        assert (tmp_path / name).stat().st_size > 10_000


def test_trace_plot_from_the_cli(tmp_path):
    from snapmem.cli import main
    png = tmp_path / "b.png"
    assert main(["trace", "balloon", "--set", "nodes=31", "--until", "stretch_max=4", "--plot", str(png),
                 "--x", "stretch"]) == 0
    assert png.stat().st_size > 10_000
