"""Dynamics of several membranes and their chambers: fluid and gas chambers, and their supplies.

A :class:`~snapmem.model.multi.MultiScene` steps through the same backward-Euler incremental
potential as one membrane (:mod:`snapmem.dynamics.stepper`), with the pressure p_c of every
chamber that holds a fluid or a gas as one more unknown. A step solves

    R(y; p) + (M / h^2 + C / h)(y - x_hat) - M v_hat / h = 0       (every membrane, its chamber's p)
    -(V_c(y) - V_c*(p_c)) = 0                                     (every such chamber)

(the stationarity of the incremental potential plus p_c (V_c* - V_c), as in statics:
:mod:`snapmem.continuation.chambers`), a band matrix bordered by one row and column per chamber,
[[K + M/h^2 + C/h, -G], [-G^T, -D]], so every solve stays O(N) per membrane. What fills the
chamber sets V_c* and D = -dV_c*/dp_c >= 0:

- **a fluid of prescribed volume** (``chamber = volume``): V_c* = V_fluid(t*), the load
  ``fluid_volume`` [m^3] (default: held at its start). A **flow source** at a prescribed rate Q(t)
  [m^3/s] is this with V_fluid(t) = V_0 + int_0^t Q (:func:`flow_volume`); D = 0.
- **a fluid fed from a pressure source through a linear resistance**: loads ``source_pressure``
  p_s [Pa] and ``flow_resistance`` R_f [Pa s/m^3]. The flow is dV_fluid/dt = (p_s - p) / R_f, so
  the fluid volume is a dynamic unknown, integrated by the run's scheme like the positions: the
  scheme's anchor x_hat (and step h) of V_fluid gives V_c* = x_hat + h (p_s - p) / R_f, D = h / R_f.
  It is an incremental potential: eliminating p leaves the minimisation of
  Pi(y) - p_s V_c(y) + R_f (V_c(y) - x_hat)^2 / (2 h), whose dissipation R_f Q^2 h / 2 gives
  the symmetric tangent K + (R_f / h) G G^T.
- **an isothermal ideal gas** (``chamber = gas``): V_c* = n R T / (p_c + p_atm), with n R T the
  load ``gas_amount`` [J] (default: the chamber's, or what it holds at the start);
  D = n R T / (p_c + p_atm)^2: the gas' energy -n R T ln V + p_atm V at the solve's state.

Suffixes ``_2``, ... name the loads of the second chamber on. The chamber's pressure is a state
of the run (the last solve's), recorded with every frame as ``load_pressure`` (``load_pressure_2``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from snapmem.dynamics.compiled_chambers import (TARGET_GAS, TARGET_RESISTANCE, TARGET_VOLUME, ChamberCompiledStep,
                                                chamber_target)
from snapmem.dynamics.loads import PiecewiseLinear
from snapmem.dynamics.stepper import EPS, _Recorder, _Stepper
from snapmem.dynamics.trajectory import Trajectory
from snapmem.errors import SnapmemError, check_real
from snapmem.kernels.banded import BorderedMatrix
from snapmem.model.chambers import ChamberKind, gas_energy
from snapmem.model.local_checks import failure_margins_many
from snapmem.model.multi import MultiScene
from snapmem.model.scene import Evaluation
from snapmem.solvers.newton import newton


#: The chambers' targets, one formula for both steps: the numpy step calls the kernel's Python form.
_chamber_target = chamber_target.py_func


def _suffix(c: int) -> str:
    return "" if c == 0 else f"_{c + 1}"


@dataclass(frozen=True)
class FlowVolume:
    """V(t) = V_0 + int_{t0}^t Q(s) ds [m^3]: the fluid volume of a flow source at rate Q [m^3/s].

    Attributes
    ----------
    volume0 : float
        V_0 [m^3] at ``t0``.
    rate : float, callable t -> Q, or PiecewiseLinear
        The flow rate [m^3/s]; a piecewise-linear one is integrated exactly (trapezoids), a
        callable by quadrature.
    t0 : float
        Start time [s].
    """

    volume0: float
    rate: object
    t0: float = 0.0

    def __call__(self, t: float) -> float:
        if isinstance(self.rate, PiecewiseLinear):
            return self.volume0 + _integral(self.rate, self.t0, t)
        if callable(self.rate):
            from scipy.integrate import quad          # only here: start-up loads no scipy.integrate
            return self.volume0 + quad(self.rate, self.t0, t, limit=200)[0]
        return self.volume0 + float(self.rate) * (t - self.t0)

    @property
    def times(self) -> tuple:
        """The kinks of V(t) (the rate's jumps land steps there, as a schedule's do)."""
        return tuple(getattr(self.rate, "times", ()))


def flow_volume(volume0: float, rate, t0: float = 0.0) -> FlowVolume:
    """The ``fluid_volume`` schedule of a flow source: V_0 [m^3] at t0 [s] plus the integral of
    ``rate`` [m^3/s] (a constant, a callable t -> Q, or a list of (t, Q) points, linear between).

    Examples
    --------
    >>> V = flow_volume(1.0, [(0.0, 0.0), (2.0, 1.0)])
    >>> V(2.0)
    2.0
    """
    check_real("volume0", volume0)
    if not callable(rate) and np.ndim(rate) > 0:
        points = np.asarray(rate, dtype=float)
        if points.ndim != 2 or points.shape[1] != 2:
            raise SnapmemError(f"rate = {rate!r}: a constant, a callable t -> Q, or a list of (t, Q) points")
        rate = PiecewiseLinear(tuple(points[:, 0]), tuple(points[:, 1]))
    return FlowVolume(float(volume0), rate, float(t0))


def _integral(f: PiecewiseLinear, a: float, b: float) -> float:
    """int_a^b f [f s] of a piecewise-linear f (constant outside its points), exactly."""
    if b < a:
        return -_integral(f, b, a)
    times = np.asarray(f.times, float)
    inner = times[(times > a) & (times < b)]
    x = np.concatenate([[a], inner, [b]])
    y = np.interp(x, times, np.asarray(f.values, float))
    return float(np.sum(0.5 * (y[1:] + y[:-1]) * np.diff(x)))


class ChamberState:
    """The chambers' side of a run: their pressures (the last solve's), the fluid volumes of the
    resistance-fed chambers (a first-order state that follows the run's scheme), and what each
    chamber holds. Its methods ``open``, ``close``, ``commit``, ``finish``, ``frame`` are those of
    the viscous networks' internal state (:class:`snapmem.dynamics.stepper._InternalState`), so
    the driver runs both the same way."""

    terms = ()

    def __init__(self, scene: MultiScene, q0: np.ndarray, loads0: dict):
        self.scene = scene
        self.multiplied = [c for c, ch in enumerate(scene.chambers) if ch.has_multiplier]
        self.names = [scene.pressure_name(c) for c in self.multiplied]
        self.pressure = np.array([loads0[name] for name in self.names], dtype=float)
        self.held = {}                     # a fluid's volume or a gas' amount when no load sets it
        self.fluid = {}                    # resistance-fed chambers: their fluid volume [m^3]
        for j, c in enumerate(self.multiplied):
            ch, v = scene.chambers[c], scene.chamber_volume(q0, c)
            if ch.kind is ChamberKind.GAS:
                amount = loads0.get("gas_amount" + _suffix(c), ch.amount)
                self.held[c] = (self.pressure[j] + ch.p_atm) * v if amount is None else amount
                self.pressure[j] = self.held[c] / v - ch.p_atm        # the gas law at the start
            else:
                self.held[c] = v if ch.volume is None else ch.volume
                if self._fed(c, loads0):
                    self.fluid[c] = v
        self.previous = None
        self.solved = self.pressure.copy()     # the last solve's pressures (ChamberStepper sets them)
        self._anchors = {}
        self._pending = None

    # ----------------------------------------------------------------------------------------
    def _fed(self, c: int, loads: dict) -> bool:
        """Whether chamber c is fed through a resistance (its ``source_pressure`` is a load)."""
        fed = "source_pressure" + _suffix(c) in loads
        if fed and "fluid_volume" + _suffix(c) in loads:
            raise SnapmemError(f"chamber {c + 1}: fluid_volume and source_pressure both given; a chamber's "
                               "fluid volume is prescribed or fed through a resistance, not both")
        return fed

    def with_pressures(self, loads: dict) -> dict:
        """``loads`` with the chambers' present pressures."""
        out = dict(loads)
        out.update(zip(self.names, self.pressure.tolist()))
        return out

    def target_parameters(self, j: int, loads: dict) -> tuple:
        """(kind, params) of the j-th multiplied chamber's target V_c*(p) at a solve's loads
        (:func:`snapmem.dynamics.compiled_chambers.chamber_target`, which documents them)."""
        c = self.multiplied[j]
        ch, s = self.scene.chambers[c], _suffix(c)
        if ch.kind is ChamberKind.GAS:
            return TARGET_GAS, (float(loads.get("gas_amount" + s, self.held[c])), float(ch.p_atm))
        if c in self.fluid:
            resistance = loads.get("flow_resistance" + s)
            if resistance is None or not resistance > 0:
                raise SnapmemError(f"flow_resistance{s} = {resistance}: chamber {c + 1} is fed through a "
                                   "resistance (source_pressure is a load); give flow_resistance > 0 [Pa s/m^3]")
            anchor, step, _ = self._anchors[c]
            return TARGET_RESISTANCE, (float(anchor), float(step), float(loads["source_pressure" + s]),
                                       float(resistance))
        return TARGET_VOLUME, (float(loads.get("fluid_volume" + s, self.held[c])),)

    def target(self, j: int, loads: dict, h: float):
        """p -> (V_c* [m^3], D = -dV_c*/dp [m^3/Pa]) of the j-th multiplied chamber at a solve's loads."""
        kind, params = self.target_parameters(j, loads)
        return lambda p: _chamber_target(kind, params, p)

    def inadmissible(self, pressure: np.ndarray):
        for j, c in enumerate(self.multiplied):
            ch = self.scene.chambers[c]
            if ch.kind is ChamberKind.GAS and not pressure[j] + ch.p_atm > 0:
                return f"chamber {c + 1}: absolute gas pressure not positive"
        return None

    # ----------------------------------------------------------------------------------------
    def open(self, scheme, t: float, dt: float, history) -> None:
        """Before a solve: the scheme's anchor (x_hat, h) of every resistance-fed fluid volume."""
        self._anchors = {}
        for c, volume in self.fluid.items():
            past = None if history is None or self.previous is None else (
                np.array([self.previous[c]]), np.zeros(1), history[2])
            anchor = scheme.anchor(np.array([volume]), np.zeros(1), t, dt, past)
            self._anchors[c] = (float(anchor.q[0]), anchor.h, anchor)

    def close(self, y: np.ndarray | None, dt: float) -> None:
        """After a solve: the new fluid volumes and the solve's pressures (``solved``) pending
        (y None: the solve failed). The pressures are the solve's, at its load time (the midpoint
        rule's: the step's middle)."""
        if y is None:
            self._pending = None
            return
        fluid = {c: float(self._anchors[c][2].new_state(np.array([self.scene.chamber_volume(y, c)]))[0][0])
                 for c in self.fluid}
        self._pending = (fluid, self.solved.copy())

    def commit(self) -> None:
        if self._pending is None:
            return
        self.previous = dict(self.fluid)
        self.fluid, self.pressure = self._pending
        self._pending = None

    def finish(self) -> None:
        pass

    def state(self) -> dict:
        """What a continued run would need: not recorded for chambers (:meth:`restore` refuses)."""
        return {}

    def restore(self, saved: dict) -> None:
        """Continuing a run of several membranes is not supported: say so rather than restart wrong."""
        raise SnapmemError("restart: continuing a run of several membranes on chambers is not supported; "
                           "run it again from the start with the longer t_end")

    def frame(self) -> dict:
        """What a frame records: ``fluid_volume_state`` of the resistance-fed chambers [m^3]."""
        return {f"fluid_volume_state{_suffix(c)}": v for c, v in self.fluid.items()}


class ChamberStepper:
    """One implicit step on a :class:`MultiScene`: the backward-Euler solve of
    :class:`snapmem.dynamics.stepper._Stepper` bordered by the chambers' pressures (module
    docstring), by Newton on the residual (a saddle point when a fluid's volume is prescribed):
    the whole solve in one compiled call (:mod:`snapmem.dynamics.compiled_chambers`) where the
    scene's terms allow it (``compiled``, else None), numpy Newton otherwise and for a step the
    compiled one hands back."""

    def __init__(self, scene: MultiScene, mass: np.ndarray, damping: np.ndarray, options, chambers: ChamberState):
        self.scene, self.mass, self.damping, self.options, self.chambers = scene, mass, damping, options, chambers
        self.free = scene.free
        self.tol = options.newton.tol * scene.force_scale
        self._mass_free, self._damping_free = mass[self.free], damping[self.free]
        self._size = scene.meridian.size
        n, k = scene.n_node_dofs, len(chambers.multiplied)
        self._extended_free = np.concatenate([self.free, n + np.arange(k)])
        # the chamber rows in force units: a volume error of 1e-9 L^3 weighs as 1e-9 of the force scale
        self._row_scale = scene.force_scale / self._size ** 3
        self.compiled = ChamberCompiledStep.of(scene, chambers.multiplied)

    outcome = _Stepper.outcome          # the scheme's own (the compiled chambers' step computes none)

    def solve(self, q, v, h, loads, current=None, outcome=None):
        """y of the step of h from (q, v) at ``loads``, the chambers' pressures beside it; (y, report).
        (``outcome``: the single membrane's compiled step computes the scheme's outcome in its call;
        this one leaves it to :meth:`outcome`.)"""
        scene, free, chambers = self.scene, self.free, self.chambers
        n, k, s = scene.n_node_dofs, len(chambers.multiplied), self._row_scale
        inertia_free = self._mass_free / h ** 2 + self._damping_free / h
        momentum = self._mass_free * v[free] / h
        tol = max(self.tol, 1e3 * EPS * float(inertia_free.max()) * self._size)
        start = q + h * v
        fallback = q if current is None else current
        if self.compiled is not None:          # (it checks the guess itself)
            done = self.compiled.solve(q, start, fallback, chambers.pressure, inertia_free, momentum, loads,
                                       [chambers.target_parameters(j, loads) for j in range(k)], s, tol,
                                       self.options.newton)
            if done is not None:
                y, chambers.solved, report = done
                return y, report
        if scene.inadmissible(start) is not None:
            start = fallback
        targets = [chambers.target(j, loads, h) for j in range(k)]

        def assemble(x):
            y, p = x[:n], x[n:]
            each = dict(loads)
            each.update(zip(chambers.names, p.tolist()))
            ev = scene.evaluate(y, each, order=2)
            d = (y - q)[free]
            residual = ev.residual + inertia_free * d - momentum
            K = ev.stiffness
            K.add_diagonal(inertia_free)
            G, rows, D = np.empty((scene.n_free, k)), np.empty(k), np.zeros((k, k))
            for j, c in enumerate(chambers.multiplied):
                volume, G[:, j] = scene.chamber_volume_and_gradient(y, c)
                v_star, D[j, j] = targets[j](p[j])
                rows[j] = -s * (volume - v_star)
            J = BorderedMatrix(K, -G, -s * G, -s * D)
            return Evaluation(0.0, None, np.concatenate([residual, rows]), J, ev.residual_floor)

        x0 = np.concatenate([start, chambers.pressure])

        def inadmissible(x):
            return scene.inadmissible(x[:n]) or chambers.inadmissible(x[n:])

        def max_step(x, dx):
            return scene.max_step(x[:n], dx[:n])

        x, _ev, report = newton(assemble, x0, self._extended_free, tol, self.options.newton, inadmissible, max_step,
                                merit="residual")
        chambers.solved = x[n:].copy()
        return x[:n], report


class ChamberRecorder(_Recorder):
    """The frames of a multi-membrane run: each frame's potential (the membranes' energies without
    the chambers' pressure work, plus each chamber's own energy: a gas' -n R T ln V + p_atm V, a
    prescribed pressure's -p V, 0 for an incompressible fluid) as ``potential`` (the chambers'
    part also as ``chamber_energy``), the chambers' volumes (``volume``, ``volume_chamber_2``, ...),
    and every membrane's columns with its number as a suffix: ``volume_i`` [m^3], ``kinetic_i``
    [J], ``u_max_i`` [m], ``stretch_max_i``, ``breakdown_margin_i``, ``rupture_margin_i``, its
    probes (``stretch_i``, ``deflection_i``) and its nodes ``r_i``, ``z_i`` [m] (``r``, ``z``: the
    first membrane's; ``breakdown_margin``, ``rupture_margin``: the smallest over the membranes)."""

    def __init__(self, scene: MultiScene, mass, interval: float, chambers: ChamberState, compiled=None):
        self.scene, self.mass, self.interval, self.compiled, self.internal = scene, mass, interval, None, None
        self.chambers = chambers
        self.steps = None if compiled is None else compiled.steps     # the membranes' compiled steps
        self.contacts = ()
        self.rows = []
        self.last_t = -np.inf
        self.min_gap = np.inf

    def chamber_energy(self, volumes, loads) -> float:
        """The chambers' own energy [J] at their volumes [m^3] (one per chamber) and loads (the
        pressures being the frame's)."""
        scene, total = self.scene, 0.0
        for c, (ch, volume) in enumerate(zip(scene.chambers, volumes)):
            if ch.kind is ChamberKind.GAS:
                total += gas_energy(volume, loads.get("gas_amount" + _suffix(c), self.chambers.held[c]), ch.p_atm)
            elif ch.kind is ChamberKind.PRESSURE:
                total -= loads[scene.pressure_name(c)] * volume
        return total

    def frames_energy_and_volumes(self, Q: np.ndarray, loads: list) -> tuple:
        """The membranes' energy without the chambers' pressure work (T,) [J], every membrane's
        volume (M, T) and every chamber's (C, T) [m^3] at the frames Q (T, n_dof): by the
        membranes' compiled measures (one call per membrane) when the run's step is compiled."""
        scene = self.scene
        parts = [np.ascontiguousarray(Q[:, a:b]) for a, b in zip(scene.offsets[:-1], scene.offsets[1:])]
        if self.steps is None:
            unpressed = [{**each, **{scene.pressure_name(c): 0.0 for c in range(len(scene.chambers))}}
                         for each in loads]
            energy = np.array([scene.energy(q, each) for q, each in zip(Q, unpressed)])
            own = np.array([[m.volume(qi) for qi in Qi] for m, Qi in zip(scene.membranes, parts)])
            chambers = np.array([[scene.chamber_volume(q, c) for q in Q] for c in range(len(scene.chambers))])
            return energy, own, chambers.reshape(len(scene.chambers), len(Q))
        energy, own = np.zeros(len(Q)), []
        for i, (step, Qi) in enumerate(zip(self.steps, parts)):
            each = [{"pressure": 0.0, "voltage": frame.get(f"voltage_{i + 1}", 0.0)} for frame in loads]
            e, v = step.measures_many(Qi, each)[:2]
            energy += e
            own.append(v)
        chambers = [ch.dead_volume + sum(s * own[i] for i, s in zip(ch.membranes, ch.signs)) for ch in scene.chambers]
        return energy, np.array(own), np.array(chambers).reshape(len(scene.chambers), len(Q))

    def trajectory(self, meta) -> Trajectory:
        scene = self.scene
        loads = [row["loads"] for row in self.rows]
        data = {k: np.array([row[k] for row in self.rows]) for k in self.rows[0] if k != "loads"}
        membranes, own_volumes, chamber_volumes = self.frames_energy_and_volumes(data["q"], loads)
        chambers = np.array([self.chamber_energy(volumes, each) for volumes, each in zip(chamber_volumes.T, loads)])
        potential = membranes + chambers
        data.update(potential=potential, chamber_energy=chambers, total=data["kinetic"] + potential,
                    volume=chamber_volumes[0] if scene.chambers else own_volumes[0])
        for c in range(1, len(scene.chambers)):
            data[f"volume_chamber_{c + 1}"] = chamber_volumes[c]
        names = sorted({name for each in loads for name in each})
        for name in names:
            data["load_" + name] = np.array([each.get(name, np.nan) for each in loads])
        for c, ch in enumerate(scene.chambers):      # a gas' pressure: its law at the frame's own state
            if ch.kind is ChamberKind.GAS:
                amount = [each.get("gas_amount" + _suffix(c), self.chambers.held[c]) for each in loads]
                data["load_" + scene.pressure_name(c)] = np.array(amount) / chamber_volumes[c] - ch.p_atm
        for i, m in enumerate(scene.membranes):
            part = slice(scene.offsets[i], scene.offsets[i + 1])
            Q = data["q"][:, part]
            data[f"volume_{i + 1}"] = own_volumes[i]
            data[f"kinetic_{i + 1}"] = 0.5 * np.einsum("tj,j,tj->t", data["v"][:, part], self.mass[part],
                                                       data["v"][:, part])
            for name, probe in m.probes.items():
                data[f"{name}_{i + 1}"] = np.array([probe(qi) for qi in Q])
            data[f"r_{i + 1}"], data[f"z_{i + 1}"] = r, z = Q[:, 0::2].copy(), Q[:, 1::2].copy()
            data[f"u_max_{i + 1}"] = np.hypot(r - m.meridian.r, z - m.meridian.z).max(axis=1)
            a, b = m.meridian.edges[:, 0], m.meridian.edges[:, 1]
            lam1 = np.hypot(r[:, b] - r[:, a], z[:, b] - z[:, a]) * m.meridian.inverse_length
            with np.errstate(invalid="ignore"):
                lam2 = 0.5 * (r[:, a] + r[:, b]) * m.meridian.inverse_mid_radius
            data[f"stretch_max_{i + 1}"] = np.maximum(lam1.max(axis=1), np.nanmax(lam2, axis=1))
            voltages = [each.get(f"voltage_{i + 1}", 0.0) for each in loads]
            for key, values in failure_margins_many(m, np.ascontiguousarray(Q), voltages).items():
                data[f"{key}_{i + 1}"] = values
        for key in ("breakdown_margin", "rupture_margin"):          # the scene's: its weakest membrane's
            data[key] = np.min([data[f"{key}_{i + 1}"] for i in range(len(scene.membranes))], axis=0)
        data["r"], data["z"] = data["r_1"], data["z_1"]
        return Trajectory(data, meta)


def lumped_masses_of(scene: MultiScene, rho: float, masses) -> np.ndarray:
    """Every membrane's lumped masses (``masses``: the single-membrane rule, scene -> (n_dof,)), stacked [kg]."""
    return np.concatenate([masses(m, rho) for m in scene.membranes])


def chamber_parts(scene: MultiScene, mass, damping, options, q0: np.ndarray, loads0: dict):
    """(stepper, chamber state, recorder class) of a run on a multi-membrane scene."""
    if any(m.bodies for m in scene.membranes):
        raise SnapmemError(f"scene {scene.name!r}: rigid bodies in a multi-membrane run are not supported")
    state = ChamberState(scene, q0, loads0)
    stepper = ChamberStepper(scene, mass, damping, options, state)
    return stepper, state, (lambda scene, mass, interval, compiled, internal: ChamberRecorder(
        scene, mass, interval, state, stepper.compiled))
