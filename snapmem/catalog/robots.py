"""The paper's soft robots (section 4) and its dynamic torus: their time schedules.

Every scene here is registered like the validation scenes (snapmem.catalog.robot_scenes;
``snapmem scenes`` lists them) and also has an *experiment*: the loads in time, the end time, density, damping and start state, so
that ``snapmem simulate NAME`` or :func:`run` replays it. SI units; eps = 1e-10 F/m.

* ``pump`` (Fig. 6): Gent plate R = 0.1 m at 300 V; pressure 0 until 5 s, +10 Pa/s to 15 s,
  held; voltage removed at 15 s; pressure -10 Pa/s from 20 s to 0 at 30 s.
* ``gripper_rod`` / ``gripper_shell`` (Fig. 7): torus Rb = 0.1 m, Rs = 0.02 m around a rod of
  radius Rw (default 0.04 m) or inside a shell of inner radius Rw (default 0.25 m); pressure ramps
  at ``rate`` to ``p_max`` and is held.
* ``ball_drop`` (Fig. 8, case 1): balloon R = 0.1 m on a rigid plate, inflated to 500 Pa, a ball
  (rb = 0.05 m, 0.5 kg, g = -10 m/s^2) dropped onto it from ``drop`` above the top.
* ``ball_throw`` (Fig. 8, case 2): the ball resting on the balloon at 500 Pa; pressure rises at
  100 Pa/s: the balloon snaps through and throws the ball.
* ``torus_snap``: the default scene of the paper's C++ code (normalised units): torus Rs = 2
  about Rb = 10, H = 0.1, Mooney-Rivlin mu = 4225, rho = 100, xi = 1 /s, 200 nodes; pressure
  ramps at 100 /s to 200 and is held to t = 100 s; it snaps through.

Mass-proportional damping acts on the membrane; in ``ball_drop`` it acts on the ball too
(``damp_ball = 1``, as a mass-proportional damping of the whole system does, so that xi sets how
fast the ball settles), in ``ball_throw`` not (``damp_ball = 0``: the thrown ball flies freely).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from snapmem.catalog.registry import get_spec
from snapmem.catalog.robot_scenes import EPS, MU_MR, ROBOTIC_SCENES  # noqa: F401  (public names of this module)
from snapmem.dynamics.driver import DynamicsOptions, Trajectory, schedule, simulate
from snapmem.errors import SnapmemError
from snapmem.model.contact import Ball, Plane
from snapmem.model.scene import Scene
from snapmem.solvers.newton import NewtonOptions, solve
from snapmem.statics import equilibrium


@dataclass
class Experiment:
    """A scene with everything a simulation of it needs.

    Attributes
    ----------
    scene : Scene
    loads : callable t -> {name: value}
    t_end : float
        Default end time [s].
    rho : float
        Membrane density [kg/m^3].
    damping : float
        Mass-proportional damping xi [1/s].
    q0, v0 : ndarray or None
        Start state and velocity (None: reference, rest).
    damp_bodies : bool
        Whether xi acts on the rigid bodies too.
    options : DynamicsOptions
        Default time-stepping options of this experiment.
    """

    scene: Scene
    loads: Callable[[float], dict]
    t_end: float
    rho: float
    damping: float
    q0: np.ndarray | None = None
    v0: np.ndarray | None = None
    damp_bodies: bool = False
    options: DynamicsOptions = field(default_factory=DynamicsOptions)


#: name -> function(scene) -> Experiment, for every scene that can be simulated with its own schedule
EXPERIMENTS: dict[str, Callable[[Scene], Experiment]] = {}


def experiment(name: str, **params) -> Experiment:
    """The experiment of scene ``name`` with parameters overriding its defaults.

    Scenes without an experiment of their own (plate, balloon, torus) are simulated at their
    loads held constant from rest, with rho and xi of 1 (normalised units).
    """
    spec = get_spec(name)
    scene = spec.build(**params)
    if name in EXPERIMENTS:
        return EXPERIMENTS[name](scene)
    q0 = None if scene.start_guess is None else scene.start_guess(scene.loads)
    return Experiment(scene, schedule(**scene.loads), 10.0, 1.0, 1.0, q0=q0)


def run(name: str, t_end: float | None = None, options: DynamicsOptions | None = None,
        progress=None, **params) -> Trajectory:
    """Simulate the registered scene ``name`` with its own schedule (see module docstring)."""
    ex = experiment(name, **params)
    traj = simulate(ex.scene, ex.loads, ex.t_end if t_end is None else t_end, rho=ex.rho, damping=ex.damping,
                    q0=ex.q0, v0=ex.v0, options=options or ex.options, damp_bodies=ex.damp_bodies,
                    progress=progress)
    return traj


def _options(params, **extra) -> DynamicsOptions:
    """BDF2 at the scene's tolerance, about 2000 frames recorded (the smallest gap of every step is kept)."""
    return DynamicsOptions(**{"scheme": "bdf2", "tol": params["tol"], "save_interval": params["t_end"] / 2000,
                              **extra})


# ------------------------------------------------------------------------------------------
# pump
def _pump_experiment(scene: Scene) -> Experiment:
    p = scene.parameters
    rate, t_up, t_hold, t_down = p["rate"], p["t_up"], p["t_hold"], p["t_down"]
    p_top = rate * (t_hold - t_up)
    t_zero = t_down + p_top / rate
    phi = p["voltage"] if p["voltage"] is not None else 300.0
    loads = schedule(pressure=[(0.0, 0.0), (t_up, 0.0), (t_hold, p_top), (t_down, p_top), (t_zero, 0.0)],
                     voltage=[(0.0, phi), (t_hold, phi), (t_hold + p["t_switch"], 0.0)])
    # start from a shallow dome of rise 0.05 R: the flat plate is singular, and at 300 V without
    # pressure the membrane is in compression and would buckle out of plane from round-off
    q0 = scene.reference_state()
    R = p["R"]
    q0[1::2] = 0.05 * R * (1.0 - (scene.meridian.r / R) ** 2)
    # implicit Euler: its numerical damping carries the snap back through the slack, crumpling
    # cap near the axis (min tension < 0) where BDF2 at tight tolerance stalls
    return Experiment(scene, loads, p["t_end"], p["rho"], p["xi"], q0=q0,
                      options=_options(p, dt=1e-3, dt_max=0.5, scheme="euler"))


EXPERIMENTS["pump"] = _pump_experiment


# ------------------------------------------------------------------------------------------
# grippers
def _gripper_experiment(scene: Scene) -> Experiment:
    p = scene.parameters
    t_top = p["p_max"] / p["rate"]
    loads = schedule(pressure=[(0.0, 0.0), (t_top, p["p_max"])])
    return Experiment(scene, loads, p["t_end"], p["rho"], p["xi"], options=_options(p, dt=1e-3, dt_max=0.5))


EXPERIMENTS["gripper_rod"] = _gripper_experiment
EXPERIMENTS["gripper_shell"] = _gripper_experiment


# ------------------------------------------------------------------------------------------
# ball actuator
def _inflated(scene: Scene, pressure: float, voltage: float) -> np.ndarray:
    """The balloon's equilibrium on its plate at (pressure, voltage), without the ball, shape (2N,)."""
    keep = [t for t in scene.terms if not isinstance(t, (Ball, Plane))]
    loads = {"pressure": pressure}
    if "voltage" in scene.loads:
        loads["voltage"] = voltage
    eq = equilibrium(Scene(scene.meridian, scene.thickness, keep, fixed=scene.fixed, loads=scene.loads), loads)
    if eq.converged:
        plate = [t for t in scene.terms if isinstance(t, Plane)]
        on_plate = Scene(scene.meridian, scene.thickness, keep + plate, fixed=scene.fixed, loads=scene.loads)
        eq = solve(on_plate, loads, q0=eq.q, options=NewtonOptions(max_iterations=100))
    if not eq.converged:
        raise SnapmemError(f"no inflated equilibrium at pressure = {pressure:g} Pa: {eq.report.reason}")
    return eq.q


def _ball_drop_experiment(scene: Scene) -> Experiment:
    p = scene.parameters
    q_m = _inflated(scene, p["pressure"], scene.loads.get("voltage", 0.0))
    top = q_m[-1]
    q0 = np.concatenate([q_m, [top + p["rb"] + p["drop"]]])
    return Experiment(scene, schedule(**scene.loads), p["t_end"], p["rho"], p["xi"], q0=q0, damp_bodies=p["damp_ball"] > 0,
                      options=_options(p, dt=1e-4, dt_max=0.05))


def resting(scene: Scene, pressure: float, voltage: float = 0.0) -> np.ndarray:
    """Static equilibrium of the ball resting on the inflated balloon (ball scenes), shape (2N + 1,)."""
    q_m = _inflated(scene, pressure, voltage)
    ball = next(t for t in scene.terms if isinstance(t, Ball))
    q = np.concatenate([q_m, [q_m[-1] + ball.radius + 0.5 * ball.dhat]])
    loads = {"pressure": pressure}
    if "voltage" in scene.loads:
        loads["voltage"] = voltage
    eq = solve(scene, loads, q0=q, options=NewtonOptions(max_iterations=200))
    if not eq.converged:
        raise SnapmemError(f"the ball found no rest on the balloon at {pressure:g} Pa: {eq.report.reason}")
    return eq.q


def _ball_throw_experiment(scene: Scene) -> Experiment:
    p = scene.parameters
    p0 = p["pressure"]
    q0 = resting(scene, p0, scene.loads.get("voltage", 0.0))
    loads = schedule(pressure=[(0.0, p0), (p["t_end"], p0 + p["rate"] * p["t_end"])])
    return Experiment(scene, loads, p["t_end"], p["rho"], p["xi"], q0=q0, damp_bodies=p["damp_ball"] > 0,
                      options=_options(p, dt=1e-3, dt_max=0.05))


EXPERIMENTS["ball_drop"] = _ball_drop_experiment
EXPERIMENTS["ball_throw"] = _ball_throw_experiment


# ------------------------------------------------------------------------------------------
# torus_snap: the default scene of the paper's C++ code
def _torus_snap_experiment(scene: Scene) -> Experiment:
    p = scene.parameters
    loads = schedule(pressure=[(0.0, 0.0), (p["p_max"] / p["rate"], p["p_max"])])
    return Experiment(scene, loads, p["t_end"], p["rho"], p["xi"], options=_options(p, dt=1e-3, dt_max=1.0))


EXPERIMENTS["torus_snap"] = _torus_snap_experiment


def events(traj: Trajectory) -> dict:
    """The events of a robotic run that its accuracy is judged by, by scene.

    * pump: ``snap`` (time of the fastest volume growth before t_down [s]) and ``snap_back``
      (fastest fall after it).
    * grippers and torus_snap: ``snap`` (time of the fastest volume change); torus_snap adds
      ``outer_radius`` (final) [m].

    A snap is reported only when it happened (else NaN): the fastest volume change must come
    with a burst of kinetic energy, over :data:`SNAP_KINETIC_RATIO` times the quietest frame
    before it, and that quiet frame must come after the start. The response to the loads applied
    at t = 0 (the pump's voltage: a start-up transient, moving from the first frame on) is not a
    snap; nor is a membrane that only follows its slowly changing load.
    * ball_drop: ``impact`` (the ball's gap first falls below the barrier width), ``bounce``
      (its first lowest point) and ``rebound`` (the highest point after that) [s], and
      ``rebound_height``, the ball centre's height above the plate there [m].
    * ball_throw: ``snap``, when the volume first reaches the geometric mean of its start and its
      largest value (inside the jump of a snap of any size; the fastest volume change is a peak
      of the membrane's ringing after the snap, which the time step does not decide), ``launch``
      (the ball's gap last rises above the barrier width) [s], and ``ball_apex``, the highest
      point of the ball's free flight above the plate [m] (z + v^2 / 2|g| once it flies: the ball
      is undamped, so that is exact even where the run ends before the apex; NaN if it never
      flies).

    Times and heights between frames are interpolated (linearly for crossings, by a parabola
    through three frames for extrema), so they resolve well below the frame interval.
    """
    t, volume = traj["t"], traj["volume"]
    name = traj.meta.get("scene", "")
    if name in ("ball_drop", "ball_throw"):
        return _ball_events(traj, name)
    if name == "pump2":
        return pump2_events(traj, _snap)
    kinetic = traj["kinetic"]
    out = {}
    if name == "pump":
        t_down = traj.meta["parameters"]["t_down"]
        mid = 0.5 * (t[:-1] + t[1:])
        out["snap"] = _snap(t, volume, kinetic, mid < t_down, +1)
        out["snap_back"] = _snap(t, volume, kinetic, mid >= t_down, -1)
    else:
        out["snap"] = _snap(t, volume, kinetic, np.ones(t.size - 1, dtype=bool), 0)
    if name == "torus_snap":
        out["outer_radius"] = float(traj["r"][-1].max())
    return out


#: A snap's kinetic energy is over this many times the median of the frames before it.
SNAP_KINETIC_RATIO = 100.0
#: After a snap the volume's rate of change falls below this fraction of its peak (it was a jump).
SNAP_SETTLE_FRACTION = 0.1


def _snap(t, volume, kinetic, intervals, direction: int) -> float:
    """Midpoint time [s] of the fastest volume change among ``intervals`` (bool, one per pair of
    frames; growth if ``direction`` > 0, fall if < 0, either if 0), if it is a snap; else NaN.

    A snap is a jump out of a quiet state: (i) frames before it show the state moving slowly
    (the run's first instant excluded: a run starts from rest, and motion from there on is the
    response to the loads applied at the start, not a snap); (ii) the kinetic energy at the
    change (its two frames and the next) exceeds :data:`SNAP_KINETIC_RATIO` times its median over
    those frames; (iii) the volume's rate falls below :data:`SNAP_SETTLE_FRACTION` of its peak
    later in the window (a jump that ended, not a run still speeding up at its end).
    """
    nan = float("nan")
    rate = np.diff(volume) / np.maximum(np.diff(t), 1e-300)
    score = rate * direction if direction else np.abs(rate)
    where = np.flatnonzero(intervals)
    if where.size == 0:
        return nan
    i = int(where[np.argmax(score[where])])
    if not score[i] > 0:
        return nan
    before = np.arange(where[0], i + 1)
    before = before[t[before] > t[0]]
    later = where[where > i]
    if before.size == 0 or later.size == 0:
        return nan
    burst = float(kinetic[i:i + 3].max())
    jumped = np.abs(rate[later]).min() <= SNAP_SETTLE_FRACTION * abs(rate[i])
    if burst > SNAP_KINETIC_RATIO * float(np.median(kinetic[before])) and jumped:
        return float(0.5 * (t[i] + t[i + 1]))
    return nan


def _ball_events(traj: Trajectory, name: str) -> dict:
    p = traj.meta["parameters"]
    t, z, gap = traj["t"], traj["ball_z"] + p["R"], traj["ball_gap"]         # heights above the plate
    nan = float("nan")
    if name == "ball_drop":
        impact = _crossing(t, gap, p["dhat"], falling=True)
        out = {"impact": impact, "bounce": nan, "rebound": nan, "rebound_height": nan}
        low = _extremum(t, z, t >= impact, lowest=True)
        if low is not None:
            out["bounce"] = low[0]
            high = _extremum(t, z, t > low[0], lowest=False)
            if high is not None:
                out["rebound"], out["rebound_height"] = high
        return out
    volume = traj["volume"]
    snapped = math.isfinite(_snap(t, volume, traj["kinetic"], np.ones(t.size - 1, dtype=bool), +1))
    snap = _crossing(t, volume, float(np.sqrt(volume[0] * volume.max())), falling=False) if snapped else nan
    touching = gap < p["dhat"]
    out = {"snap": snap, "launch": nan, "ball_apex": nan}          # no flight, no apex
    if touching.any() and not touching[-1]:
        last = int(np.flatnonzero(touching)[-1])
        out["launch"] = _crossing(t[last:], gap[last:], p["dhat"], falling=False)
        v = traj["ball_v"][-1]
        out["ball_apex"] = max(float(z[last:].max()), float(z[-1] + max(v, 0.0) ** 2 / (2.0 * abs(p["g"]))))
    return out


def _crossing(t, y, level, falling: bool) -> float:
    """First time y crosses ``level`` (downwards if ``falling``), linear between frames; nan if never."""
    above = y > level
    idx = np.flatnonzero(above[:-1] & ~above[1:]) if falling else np.flatnonzero(~above[:-1] & above[1:])
    if idx.size == 0:
        return float("nan")
    i = int(idx[0])
    return float(t[i] + (level - y[i]) * (t[i + 1] - t[i]) / (y[i + 1] - y[i]))


def _extremum(t, y, where, lowest: bool):
    """(time, value) of the first local minimum (or maximum) of y among frames ``where``, refined by
    the parabola through it and its neighbours; None if there is none."""
    s = -1.0 if lowest else 1.0
    idx = np.flatnonzero(where[1:-1] & (s * y[1:-1] >= s * y[:-2]) & (s * y[1:-1] > s * y[2:])) + 1
    if idx.size == 0:
        return None
    i = int(idx[0])
    (t0, t1, t2), (y0, y1, y2) = t[i - 1:i + 2], y[i - 1:i + 2]
    d01, d12 = (y1 - y0) / (t1 - t0), (y2 - y1) / (t2 - t1)
    c = (d12 - d01) / (t2 - t0)                                     # y = y1 + b (t - t1) + c (t - t1)^2
    b = d01 + c * (t1 - t0)
    if c == 0:
        return float(t1), float(y1)
    tm = t1 - b / (2 * c)
    return float(tm), float(y1 - b * b / (4 * c))


# ------------------------------------------------------------------------------------------
# pump2 (snapmem.catalog.pump2: the scene, its experiment and events)
from snapmem.catalog.pump2 import pump2_events, pump2_loads  # noqa: E402


def _pump2_experiment(scene) -> Experiment:
    """As the pump's options, with at most 4 line-search cuts per Newton iteration (not 10): the
    numpy chamber step's failing solves (the snaps, the slack cap) are cut sooner, a third of the
    line-search work; the events move by under 0.2% (within the 4x-tighter check of studies/pump2.py)."""
    p = scene.parameters
    loads, q0 = pump2_loads(scene)
    return Experiment(scene, schedule(**loads), p["t_end"], p["rho"], p["xi"], q0=q0,
                      options=_options(p, dt=1e-3, dt_max=0.5, scheme="euler",
                                       newton=NewtonOptions(tol=1e-9, max_iterations=25, max_cuts=4)))


EXPERIMENTS["pump2"] = _pump2_experiment
