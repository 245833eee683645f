"""Animate a saved trajectory: the meridian (mirrored, with the revolved membrane's outline and
any rigid bodies) beside the time series of its loads, volume and contact forces.

matplotlib is imported here only; a .gif is written with the Pillow writer that ships with
matplotlib, an .mp4 with ffmpeg (if it is installed).
"""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np

from snapmem.dynamics.driver import Trajectory
from snapmem.errors import SnapmemError, check_int

log = logging.getLogger(__name__)


def frame_indices(t: np.ndarray, frames: int) -> np.ndarray:
    """Indices of the recorded frames nearest to ``frames`` equally spaced times, shape (<= frames,)."""
    targets = np.linspace(t[0], t[-1], max(2, frames))
    idx = np.clip(np.searchsorted(t, targets), 0, t.size - 1)
    return np.unique(idx)


def check_trajectory(traj: Trajectory) -> None:
    """SnapmemError unless ``traj`` can be drawn: ``t`` (M,) finite and non-decreasing with M >= 1,
    ``r`` and ``z`` (M, N) finite with N >= 2, and every time series drawn (loads, forces,
    volume, ball height) finite of shape (M,). A file written by another program, or with empty,
    NaN or mismatched arrays, is refused naming the array."""
    data = traj.data
    t = np.asarray(data["t"])
    if t.dtype.kind not in "fiu" or t.ndim != 1 or t.size == 0:
        raise SnapmemError(f"trajectory: 't' must be a non-empty 1D array of times (shape {t.shape}, dtype {t.dtype})")
    arrays = {"t": (t.size,), "r": (t.size, None), "z": (t.size, None)}
    arrays.update({k: (t.size,) for k in data if k.startswith("load_") or k.endswith("_force")
                   or k in ("volume", "ball_z")})
    for key, shape in arrays.items():
        if key not in data:
            continue
        a = np.asarray(data[key])
        if a.dtype.kind not in "fiu" or a.ndim != len(shape) or a.shape[0] != shape[0] or (
                len(shape) == 2 and a.shape[1] < 2):
            want = f"({t.size},)" if len(shape) == 1 else f"({t.size}, N >= 2)"
            raise SnapmemError(f"trajectory: {key!r} has shape {a.shape} and dtype {a.dtype}; must be numbers "
                               f"of shape {want} (one per time)")
        if not np.all(np.isfinite(a)):
            raise SnapmemError(f"trajectory: {key!r} has non-finite values (NaN or inf)")
    if np.any(np.diff(t) < 0):
        raise SnapmemError("trajectory: times 't' must not decrease")


def animate(traj: Trajectory, out, frames: int = 120, fps: int = 20, dpi: int = 80) -> Path:
    """Write an animation of ``traj`` to ``out`` (.gif or .mp4); returns the path.

    Left: the meridian r >= 0 and its mirror image (the membrane's section through the axis),
    rigid bodies (rod, shell, plane, ball) drawn where the trajectory's scene put them. Right:
    loads, volume and contact forces against time, with a cursor.

    The file is written to a temporary name beside ``out`` and renamed when complete, so an
    error or an interrupt leaves no partial animation.
    """
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib import animation

    out = Path(out)
    if out.suffix not in (".gif", ".mp4"):
        raise SnapmemError(f"--out {out}: must end in .gif or .mp4")
    frames = check_int("frames", frames, minimum=1, maximum=100_000)
    fps = check_int("fps", fps, minimum=1, maximum=1000)
    check_trajectory(traj)
    t, r, z = traj["t"], traj["r"], traj["z"]
    closed = bool(traj.meta.get("closed", False))
    params = traj.meta.get("parameters", {}) or {}
    idx = frame_indices(t, frames)

    fig, (ax, ax2) = plt.subplots(1, 2, figsize=(10, 4.5), gridspec_kw={"width_ratios": [1.1, 1]})
    extent = max(np.abs(r).max(), np.abs(z).max()) * 1.1
    if "Rw" in params and params["Rw"] is not None:
        extent = max(extent, 1.05 * params["Rw"])
    ax.set_xlim(-extent, extent)
    zlo, zhi = z.min(), z.max()
    for key in ("ball_z",):
        if key in traj.data:
            zhi = max(zhi, traj[key].max() + params.get("rb", 0.0))
    pad = 0.1 * max(zhi - zlo, extent)
    ax.set_ylim(zlo - pad, zhi + pad)
    ax.set_aspect("equal")
    ax.set_xlabel("r")
    ax.set_ylabel("z")
    title = ax.set_title("")
    (right,) = ax.plot([], [], "C0-", lw=2)
    (left,) = ax.plot([], [], "C0-", lw=2, alpha=0.5)
    _draw_bodies(ax, params, extent, zlo - pad, zhi + pad)
    ball_patch = None
    if "ball_z" in traj.data:
        ball_patch = plt.Circle((0, traj["ball_z"][0]), params.get("rb", 0.05), color="C3", alpha=0.6)
        ax.add_patch(ball_patch)

    series = [k for k in traj.data if k.startswith("load_") or k.endswith("_force")] + ["volume"]
    for k in series:
        y = traj[k]
        scale = np.max(np.abs(y)) or 1.0
        ax2.plot(t, y / scale, label=f"{k.removeprefix('load_')} / {scale:.3g}")
    if "ball_z" in traj.data:
        y = traj["ball_z"]
        ax2.plot(t, (y - y.min()) / (np.ptp(y) or 1.0), label="ball height (scaled)")
    cursor = ax2.axvline(t[0], color="k", lw=1)
    ax2.set_xlabel("t [s]")
    ax2.legend(fontsize=7, loc="upper left")
    fig.tight_layout()

    def draw(i):
        ri, zi = r[i], z[i]
        if closed:
            ri, zi = np.append(ri, ri[0]), np.append(zi, zi[0])
        right.set_data(ri, zi)
        left.set_data(-ri, zi)
        if ball_patch is not None:
            ball_patch.center = (0, traj["ball_z"][i])
        cursor.set_xdata([t[i], t[i]])
        title.set_text(f"{traj.meta.get('scene', '')}  t = {t[i]:.3f} s")
        return right, left, cursor, title

    anim = animation.FuncAnimation(fig, draw, frames=idx, blit=False)
    if out.suffix == ".gif":
        writer = animation.PillowWriter(fps=fps)
    else:
        if not animation.FFMpegWriter.isAvailable():
            plt.close(fig)
            raise SnapmemError(f"--out {out}: writing .mp4 needs ffmpeg, which is not installed; use .gif")
        writer = animation.FFMpegWriter(fps=fps)
    partial = out.with_name(f".{out.stem}.partial{out.suffix}")
    try:
        anim.save(partial, writer=writer, dpi=dpi)
        partial.replace(out)
    finally:
        plt.close(fig)
        partial.unlink(missing_ok=True)
    log.info("wrote %s (%d frames)", out, idx.size)
    return out


def _draw_bodies(ax, params, extent, zlo, zhi):
    """Rod, shell and plate outlines from the scene parameters (ball: animated separately)."""
    name = params.get("name") or ""
    rw = params.get("Rw")
    if rw is not None and "Rb" in params:
        if rw < params["Rb"]:        # a rod in the hole
            ax.axvspan(-rw, rw, color="0.7", alpha=0.6)
        else:                        # a shell around
            ax.axvline(rw, color="0.3", lw=3)
            ax.axvline(-rw, color="0.3", lw=3)
    if name.startswith("ball") and "R" in params:
        ax.axhspan(zlo, -params["R"], color="0.7", alpha=0.6)
