"""Hysteresis loops in one call: up, snap, down, snap back.

Continuation traces a branch to its limit point; the load is pushed just past it and the damped
dynamics (snapmem.dynamics.settle.settle) carries the membrane to rest on the far branch; continuation
goes on from that rest state up to a peak load and back down, to the limit point met on the way
down; the load is pushed just below it and the dynamics snaps the membrane back; continuation
takes it down to where it started. Everything is the same scene and the same energy terms.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass, replace

import numpy as np
import snapmem._lazy as _lazy

pd = _lazy.module("pandas")  # imported at first use (start-up)

from snapmem.continuation.tracer import ContinuationOptions, make_problem, trace
from snapmem.errors import SnapmemError, check_real
from snapmem.model.scene import Scene
from snapmem.threads import single_threaded

log = logging.getLogger(__name__)

#: A snap moves some node by more than this fraction of the membrane's size (else it is no snap).
MIN_JUMP = 1e-3


@dataclass
class Hysteresis:
    """A hysteresis loop.

    Attributes
    ----------
    table : pandas.DataFrame
        The traced branches one after the other, with a column ``segment``: 'loading',
        'after snap', 'unloading', 'after snap back'.
    snaps : pandas.DataFrame
        One row per snap: ``event`` ('snap' or 'snap back'), the ``control`` value at the limit
        point, the load it settled at, and the measures before and after (``u_max``, ``volume``,
        the scene's probes), the dynamic ``duration`` [s], whether it came ``at_rest``, the
        ``jump`` (largest node displacement from the limit point to the rest state, in the
        scene's length unit) and whether it ``jumped`` (by over :data:`MIN_JUMP` of the
        membrane's size: a limit point the state does not jump at is no snap).
    status : str
        'loop closed', or what stopped the loop (no limit point on a branch, a snap that did not
        come to rest, a limit point with no jump).
    closed : bool
        Whether the loop closed: both snaps happened and the unloading came back to the start.
    """

    table: pd.DataFrame
    snaps: pd.DataFrame
    status: str
    closed: bool = False


@single_threaded
def hysteresis(scene: Scene, control: str = "pressure", peak: float | None = None, push: float = 1e-3,
               rho: float | None = None, damping: float | None = None,
               options: ContinuationOptions = ContinuationOptions()) -> Hysteresis:
    """Up, snap, down, snap back: the hysteresis loop of ``scene`` in ``control``.

    Parameters
    ----------
    scene : Scene
        Its loads give the start (e.g. pressure 0).
    control : {'pressure', 'voltage', 'E_hat'}
    peak : float, optional
        The control value the loading goes up to after the snap (default 1.05 x the limit); it
        must exceed the control the snap settled at (the limit pushed by ``push``), else a
        SnapmemError (bad input) is raised once that is known, after the loading's trace.
    push : float
        How far past a limit point the load is pushed before the dynamics runs, relative to it.
    rho, damping : float, optional
        Density and mass-proportional damping for the snaps (default: the scene's ``rho``
        parameter or 1, and one over the membrane's period L sqrt(rho / mu)). They decide how
        the membrane moves, not where it comes to rest.
    """
    from snapmem.dynamics.settle import settle
    if control not in ("pressure", "voltage", "E_hat"):
        raise SnapmemError(f"control = {control!r}: a hysteresis loop needs a load control: pressure, voltage or E_hat")
    push = check_real("push", push, minimum=0.0, min_inclusive=False, maximum=0.5)
    pb = make_problem(scene, control)
    rho = check_real("rho", rho if rho is not None else float(scene.parameters.get("rho") or 1.0),
                     minimum=0.0, min_inclusive=False)
    period = scene.meridian.size * math.sqrt(rho / scene.mu)
    damping = check_real("damping", damping if damping is not None else 1.0 / period, minimum=0.0, min_inclusive=False)
    up = replace(options, stop_at_first_limit=True, direction=1)
    segments, snaps = [], []

    def snap(event, branch, sign):
        lp = next(p for p in branch.states if p.kind == "LP")
        q, loads = pb.state(lp.x, lp.lam)
        target = pb.loads(lp.lam * (1.0 + sign * push))
        before = scene.measures(q, loads)
        rest = settle(scene, q, target, rho=rho, damping=damping, t_max=1e3 * period)
        if rest.trajectory.meta.get("interrupted"):
            raise KeyboardInterrupt            # the dynamics held Ctrl-C / SIGTERM until a step ended
        after = scene.measures(rest.q, rest.loads)
        jump = float(np.max(np.abs(rest.q[:scene.n_node_dofs] - q[:scene.n_node_dofs])))
        row = {"event": event, "control_at_limit": lp.lam, "control_settled": lp.lam * (1.0 + sign * push),
               "duration": float(rest.trajectory["t"][-1]), "at_rest": rest.at_rest, "jump": jump,
               "jumped": jump > MIN_JUMP * scene.meridian.size}
        row.update({f"{k}_before": v for k, v in before.items() if isinstance(v, float)})
        row.update({f"{k}_after": v for k, v in after.items() if isinstance(v, float)})
        snaps.append(row)
        return rest

    start = pb.lam_of(scene.resolve_loads(None))
    loading = trace(scene, control, options=up)
    segments.append(loading.table.assign(segment="loading"))
    if loading.limit_points().empty:
        return Hysteresis(_join(segments), pd.DataFrame(snaps), f"no limit point on loading: {loading.status}")
    lam_up = float(loading.limit_points()["control"].iloc[0])
    rest = snap("snap", loading, +1)
    if not rest.at_rest:
        return Hysteresis(_join(segments), pd.DataFrame(snaps), "the snap did not come to rest")
    if not snaps[-1]["jumped"]:
        return Hysteresis(_join(segments), pd.DataFrame(snaps), _no_jump(snaps[-1], control))
    settled = snaps[-1]["control_settled"]
    if peak is None:
        peak = 1.05 * lam_up
    else:                                # the loading goes on from where the snap settled: up, not down
        peak = check_real("peak", peak, minimum=settled, min_inclusive=False)
    after = trace(scene, control, until={control: peak}, start=(rest.q, rest.loads), options=replace(options, direction=1))
    segments.append(after.table.assign(segment="after snap"))
    top = after.states[-1]
    q_top, loads_top = pb.state(top.x, top.lam)
    down = trace(scene, control, until={control: start}, start=(q_top, loads_top),
                 options=replace(options, direction=-1, stop_at_first_limit=True))
    segments.append(down.table.assign(segment="unloading"))
    if down.limit_points().empty:
        return Hysteresis(_join(segments), pd.DataFrame(snaps), f"no limit point on unloading: {down.status}")
    back = snap("snap back", down, -1)
    if not back.at_rest:
        return Hysteresis(_join(segments), pd.DataFrame(snaps), "the snap back did not come to rest")
    if not snaps[-1]["jumped"]:
        return Hysteresis(_join(segments), pd.DataFrame(snaps), _no_jump(snaps[-1], control))
    home = trace(scene, control, until={control: start}, start=(back.q, back.loads),
                 options=replace(options, direction=-1))
    segments.append(home.table.assign(segment="after snap back"))
    return Hysteresis(_join(segments), pd.DataFrame(snaps), "loop closed", closed=True)


def _no_jump(row: dict, control: str) -> str:
    return (f"the state did not jump at the limit point ({row['event']} at {control} = {row['control_at_limit']:.8g}: "
            f"largest displacement {row['jump']:.3g}, under {MIN_JUMP:g} of the membrane's size): no snap, no loop")


def _join(segments) -> pd.DataFrame:
    return pd.concat(segments, ignore_index=True)
