"""The dual-membrane pump ``pump2``: an active dielectric-elastomer plate and a passive membrane on
one fluid chamber (after Li et al. 2017's "robust" dual-membrane pump), under a flow schedule.

Membrane 1 is the ``pump`` scene's active plate: Gent, R = 0.1 m, H = 0.1 mm, mu = 45 kPa,
Jlim = 270, eps = 1e-10 F/m, at 300 V (MODEL.md, the fluid pump row). Membrane 2 is a passive
Mooney-Rivlin plate (c1/c2 = 7) clamped on the same chamber, which holds an incompressible fluid.
Its schedule is the pump's with the pressure ramp replaced by a flow (the chamber is filled from
a syringe): voltage 300 V from t = 0; fluid flows in at ``flow_rate`` from ``t_up`` to
``t_hold``; the voltage is switched off at ``t_hold`` (in ``t_switch``); the fluid flows back out
at the same rate from ``t_down`` until the chamber holds its start volume again.

Why this passive membrane (defaults: Mooney-Rivlin, ``passive_mu`` = 45 kPa, ``passive_H`` =
0.1 mm, ``passive_R`` = 0.2 m):
- A Mooney-Rivlin plate's p(V) rises monotonically (MODEL.md: no pressure maximum; traced here up
  to 0.35 m^3 for c1/c2 = 7), so the passive membrane never snaps itself: every snap of the pair is
  the active plate's.
- Under a prescribed fluid volume a single plate cannot snap (volume control stabilises its
  falling branch); with two membranes on one fluid, the pair is stable while
  p_1'(V_1) + p_2'(V_2) > 0 (as the two balloons). So the pair snaps only if the passive plate is
  softer than the active plate's falling branch is steep: |p_1'| ~ 45 Pa / 0.06 m^3 ~ 700 Pa/m^3
  at 300 V (from the limit point, 79.9 Pa at 0.0026 m^3, to the minimum, ~35 Pa at 0.065 m^3).
- The same film (mu, H) as the active plate, without electrodes, at twice the radius: at a fixed
  shape V/R^3 a plate's pressure scales as mu H / R and its stiffness dp/dV as mu H / R^4, so the
  passive plate holds 8x the volume at half the pressure and is 16x softer: ~35 Pa/m^3 at the
  active plate's limit pressure, where it holds ~0.38 m^3. The pair then snaps just past the
  active plate's limit point (as under pressure control: 79.97 Pa against 79.9), and the active
  plate's jump (0.0026 -> 0.27 m^3 at 300 V) comes out of the passive one with a pressure drop of
  ~12 Pa. A stiffer passive membrane (larger ``passive_mu``, ``passive_H``, smaller
  ``passive_R``) narrows the snap towards none; a softer one needs more fluid to reach the limit
  pressure.
- ``flow_rate`` 0.05 m^3/s fills the chamber to 0.5 m^3 by ``t_hold``: past the pair's snap at
  300 V (12.6 s), with time to settle before the voltage goes off.

Events (:func:`pump2_events`): ``snap`` (the active plate's fastest volume growth before
``t_down``), ``snap_back`` (its fastest fall after ``t_down``), ``pumped_volume`` [m^3] (the
volume the active plate gives up to the passive one when the voltage is switched off: V_1 just
before ``t_hold`` minus V_1 just before ``t_down``), ``snap_pressure`` [Pa] (the chamber's
highest pressure before the snap; NaN without one).
"""

from __future__ import annotations

import numpy as np

from snapmem.catalog.membranes import build_plate, common_parameters, material_parameters, with_defaults
from snapmem.catalog.registry import Parameter, SceneSpec, register
from snapmem.catalog.robot_scenes import EPS
from snapmem.errors import SnapmemError
from snapmem.model.chambers import Chamber
from snapmem.model.materials import Law
from snapmem.model.multi import MultiScene

#: The passive membrane's law: Mooney-Rivlin with the validation's c1/c2 = 7.
PASSIVE_C1, PASSIVE_C2 = 0.4375, 0.0625


def passive_parameters(params: dict) -> dict:
    """The passive plate's membrane parameters: the active's, with its own law, size and no voltage.

    Its law is Mooney-Rivlin (c1/c2 = 7) of modulus ``passive_mu``, unless the scene's law is given
    as an instance (``build_scene("pump2", law=...)``): then both plates take that law, as every
    membrane of a scene built with a law instance does."""
    if isinstance(params["material"], Law):
        return {**params, "H": params["passive_H"], "R": params["passive_R"], "voltage": None, "E_hat": 0.0,
                "pressure": 0.0, "viscous_mu": None, "relaxation_time": None, "prestretch": 1.0,
                "prestretch_1": None, "prestretch_2": None}
    return {**params, "material": "mooney_rivlin", "c1": PASSIVE_C1, "c2": PASSIVE_C2, "mu": params["passive_mu"],
            "H": params["passive_H"], "R": params["passive_R"], "voltage": None, "E_hat": 0.0, "pressure": 0.0,
            "viscous_mu": None, "relaxation_time": None, "prestretch": 1.0, "prestretch_1": None,
            "prestretch_2": None}


def _pump2(params: dict, with_loads: tuple) -> MultiScene:
    times = [(name, params[name]) for name in ("t_up", "t_hold", "t_down")]
    for (early, t0), (late, t1) in zip(times, times[1:]):
        if t1 < t0:
            raise SnapmemError(f"{late} = {t1:g} s: the pump's schedule needs t_up <= t_hold <= t_down "
                               f"({early} = {t0:g} s)")
    active = build_plate({**params, "pressure": 0.0}, tuple(with_loads) + ("voltage",))
    active.name = "active"
    passive = build_plate(passive_parameters(params), ())
    passive.name = "passive"
    chamber = Chamber("volume", (0, 1))
    return MultiScene([active, passive], [chamber], name="pump2", parameters=dict(active.parameters))


def start_state(scene: MultiScene) -> np.ndarray:
    """Both plates as shallow domes of rise 0.05 R (the flat plate is singular; at 300 V and no
    pressure the active one is in compression), as the ``pump`` scene starts."""
    q = scene.reference_state()
    for m, qi in zip(scene.membranes, scene.split(q)):
        R = float(m.meridian.r.max())
        qi[1::2] = 0.05 * R * (1.0 - (m.meridian.r / R) ** 2)
    return q


def fluid_schedule(params: dict, volume0: float) -> list:
    """The chamber's fluid volume [(t [s], V [m^3])]: V0 until t_up, + flow_rate to t_hold, held,
    - flow_rate from t_down back to V0."""
    rate, t_up, t_hold, t_down = params["flow_rate"], params["t_up"], params["t_hold"], params["t_down"]
    top = volume0 + rate * (t_hold - t_up)
    return [(0.0, volume0), (t_up, volume0), (t_hold, top), (t_down, top), (t_down + (t_hold - t_up), volume0)]


def pump2_loads(scene: MultiScene) -> tuple:
    """(the loads' schedule spec {name: [(t, value)]}, the start state) of the ``pump2`` experiment
    (module docstring); :mod:`snapmem.catalog.robots` makes the experiment of them (Euler, as the
    ``pump``'s: its numerical damping carries the snap back through the slack cap)."""
    p = scene.parameters
    q0 = start_state(scene)
    phi = p["voltage"] if p["voltage"] is not None else 300.0
    return ({"fluid_volume": fluid_schedule(p, scene.volume(q0)),
             "voltage_1": [(0.0, phi), (p["t_hold"], phi), (p["t_hold"] + p["t_switch"], 0.0)]}, q0)


def pump2_events(traj, snap_of) -> dict:
    """``snap``, ``snap_back`` [s], ``pumped_volume`` [m^3] and ``snap_pressure`` [Pa] of a pump2 run
    (module docstring); NaN where the event did not happen. ``snap_of`` is the robots' snap
    detector (:func:`snapmem.catalog.robots._snap`: a jump out of a quiet state with a burst of
    kinetic energy), here on the active plate's volume and kinetic energy, and the jump must move
    the active plate by over JUMP_VOLUME R^3 (:func:`_jump`)."""
    p = traj.meta["parameters"]
    t, volume, kinetic = traj["t"], traj["volume_1"], traj["kinetic_1"]
    mid = 0.5 * (t[:-1] + t[1:])
    before_hold, before_down = np.interp([p["t_hold"], p["t_down"]], t, volume)
    snap = _jump(t, volume, snap_of(t, volume, kinetic, mid < p["t_down"], +1), p["R"])
    loading = t < snap if np.isfinite(snap) else t < p["t_hold"]
    return {"snap": snap, "snap_back": _jump(t, volume, snap_of(t, volume, kinetic, mid >= p["t_down"], -1), p["R"]),
            "pumped_volume": float(before_hold - before_down),
            "snap_pressure": float(np.max(traj["load_pressure"][loading])) if np.isfinite(snap) else float("nan")}


#: A snap of pump2 changes the active plate's volume by over JUMP_VOLUME R^3 within +-JUMP_WINDOW.
JUMP_VOLUME, JUMP_WINDOW = 5.0, 0.5          # [-], [s]


def _jump(t, volume, when: float, radius: float) -> float:
    """``when`` if the active plate's volume changes by over JUMP_VOLUME R^3 from JUMP_WINDOW before
    to JUMP_WINDOW after it (a snap through the falling branch, 0.0026 -> 0.27 m^3 at 300 V), else
    NaN: the sudden start of the flow also rattles the plates, with a burst of kinetic energy, but
    moves the active plate by about R^3 (0.0012 m^3 at 0 V)."""
    if not np.isfinite(when):
        return when
    before, after = np.interp([when - JUMP_WINDOW, when + JUMP_WINDOW], t, volume)
    return when if abs(after - before) > JUMP_VOLUME * radius ** 3 else float("nan")


register(SceneSpec(
    "pump2", "dual-membrane pump: active Gent DE plate (300 V) and passive Mooney-Rivlin plate on one "
    "fluid chamber, flow cycle 0-30 s",
    common_parameters(41, H=1e-4)
    + (Parameter("R", 0.1, "m", "active plate's radius", minimum=0.0, open_min=True),)
    + with_defaults(material_parameters(material="gent", eps=EPS), voltage=300.0, mu=45e3)
    + (Parameter("passive_mu", 45e3, "Pa", "passive plate's shear modulus (Mooney-Rivlin, c1/c2 = 7)",
                 minimum=0.0, open_min=True),
       Parameter("passive_H", 1e-4, "m", "passive plate's thickness", minimum=0.0, open_min=True),
       Parameter("passive_R", 0.2, "m", "passive plate's radius", minimum=0.0, open_min=True),
       Parameter("flow_rate", 0.05, "m^3/s", "fluid flow in (and out) of the chamber", minimum=0.0, open_min=True),
       Parameter("t_up", 5.0, "s", "fluid starts flowing in", minimum=0.0),
       Parameter("t_hold", 15.0, "s", "flow stops, voltage switched off", minimum=0.0),
       Parameter("t_switch", 0.05, "s", "time the voltage takes to fall to 0", minimum=0.0, open_min=True),
       Parameter("t_down", 20.0, "s", "fluid starts flowing out", minimum=0.0),
       Parameter("rho", 1000.0, "kg/m^3", "membrane density", minimum=0.0, open_min=True),
       Parameter("xi", 1.0, "1/s", "mass-proportional damping", minimum=0.0),
       Parameter("t_end", 30.0, "s", "end of the simulation", minimum=0.0, open_min=True),
       Parameter("tol", 2e-2, "", "local time-error tolerance per step, fraction of the size (1e-8 to 1)",
                 minimum=1e-8, maximum=1.0)),
    _pump2))
