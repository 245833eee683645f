"""Implicit dynamics M q'' + xi M q' + grad Pi(q, t) = 0 on the scene's own assembly.

A time step is a Newton solve of the incremental potential

    Pi(y, t*) + (1/2)(y - q_n - h v_n)^T M (y - q_n - h v_n) / h^2 + (1/2)(y - q_n)^T C (y - q_n) / h

(C = xi M the mass-proportional damping), i.e. backward Euler with step h: the scene's gradient
and banded (or bordered) stiffness plus the diagonal M / h^2 + C / h. Every energy term, contact
barriers included, enters unchanged, and Newton's ``max_step`` keeps each iterate short of any
contact gap, so no accepted state penetrates a body.

Two schemes share that solve:

* ``euler``: implicit (backward) Euler, the paper's scheme: y = q_{n+1}, h = dt, loads at
  t_{n+1}. First order; it damps numerically (amplitude loss ~ (omega dt)^2 / 2 per step).
* ``midpoint`` (default): the implicit midpoint rule. Solving the same problem with h = dt / 2
  and loads at t_n + dt / 2 gives the midpoint y = (q_n + q_{n+1}) / 2 exactly (substitute
  q_{n+1} = 2 y - q_n, v_{n+1} = 2 (y - q_n) / h - v_n into the midpoint rule); then extrapolate.
  Chosen over BDF2, Newmark and generalised-alpha because it is second order, symplectic (no
  numerical damping: the energy of an undamped oscillation stays bounded over long runs, which
  the drift test checks) and needs nothing but the backward-Euler solve, one step of history and
  no start-up procedure. Its lack of high-frequency dissipation is covered by the physical
  damping xi. The extrapolation 2 y - q_n can cross a contact gap even though y does not (a
  node arriving at a body): such a step is taken by implicit Euler instead (its state is
  Newton's own, so it never penetrates), counted in ``meta['euler_fallbacks']``.

* ``bdf2``: variable-step BDF2, the same solve again: with w = dt_n / dt_{n-1},
  a0 = (1 + 2w) / (1 + w), h = dt / a0, x_hat = ((1 + w) q_n - w^2/(1 + w) q_{n-1}) / a0 and
  v_hat likewise from the velocities, y = q_{n+1} solves the incremental potential from
  (x_hat, v_hat) with step h. Second order and L-stable: it damps the membrane's unresolved
  high-frequency ringing after a snap or an impact (which the midpoint rule keeps, forcing tiny
  steps), and its state is Newton's own, so contact never needs a fallback. The robotic
  scenes use it. Its first step is implicit Euler.

Adaptive steps: a step is cut (by 4) when Newton fails and (by the controller) when the local
error estimate exceeds ``tol`` times the membrane's current size; it grows by up to 2x when easy. The
estimate is (dt^2 / 2) |a_{n+1}| for Euler (its local error) and (dt^2 / 6) |a_{n+1/2} - a_{n-1/2}|
for the midpoint rule (a third difference, ~ dt^3 q''' / 6). Snaps get small steps, quasi-static
ramps large ones.

Loads are scheduled in time: any callable t -> {name: value}, or :func:`schedule` of
piecewise-linear (t, value) points per load.
"""

from __future__ import annotations

import functools
import json
import logging
import time
from dataclasses import asdict, dataclass, field
from typing import Callable

import numpy as np

from snapmem.dynamics.compiled_step import CompiledStep
from snapmem.errors import SnapmemError, SolverError, check_int, check_real
from snapmem.solvers.newton import NewtonOptions, newton, solve
from snapmem.model.scene import Evaluation, Scene
from snapmem.threads import single_threaded

log = logging.getLogger(__name__)

SCHEMES = ("midpoint", "bdf2", "euler")
EPS = float(np.finfo(float).eps)


# ----------------------------------------------------------------------------------------------
# loads in time
@dataclass(frozen=True)
class PiecewiseLinear:
    """A piecewise-linear function of time through (t, value) points, constant outside them.

    Attributes
    ----------
    times : tuple of float
        Increasing times [s].
    values : tuple of float
        Values at those times (load units).
    """

    times: tuple
    values: tuple

    def __post_init__(self):
        t = np.asarray(self.times, dtype=float)
        if t.size == 0 or t.size != len(self.values) or np.any(np.diff(t) < 0):
            raise SnapmemError(f"schedule times {list(self.times)}: need one value per time, times non-decreasing")

    def __call__(self, t: float) -> float:
        return float(np.interp(t, self.times, self.values))


def schedule(**loads) -> Callable[[float], dict]:
    """A load schedule t -> {name: value} from per-load constants, callables or (t, value) lists.

    Examples
    --------
    >>> loads = schedule(pressure=[(0, 0), (5, 0), (20, 150)], voltage=300.0)
    >>> loads(10.0)
    {'pressure': 50.0, 'voltage': 300.0}
    """
    parts = {}
    for name, spec in loads.items():
        if callable(spec):
            parts[name] = spec
        elif np.ndim(spec) == 0:
            parts[name] = (lambda c: lambda t: c)(float(spec))
        else:
            pts = np.asarray(spec, dtype=float)
            parts[name] = PiecewiseLinear(tuple(pts[:, 0]), tuple(pts[:, 1]))

    def at(t: float) -> dict:
        return {name: f(t) for name, f in parts.items()}

    at.breakpoints = sorted({float(x) for f in parts.values() for x in getattr(f, "times", ())})
    return at


def _as_schedule(loads) -> Callable[[float], dict]:
    if loads is None:
        return schedule()
    if callable(loads):
        return loads
    return schedule(**dict(loads))


# ----------------------------------------------------------------------------------------------
# masses
def lumped_masses(scene: Scene, rho: float) -> np.ndarray:
    """Lumped mass of every degree of freedom, shape (n_dof,) [kg].

    m_i = rho H A_i with A_i the node's reference ring area 2 pi r_bar_i l_bar_i (a pole node:
    its cap), for both r_i and z_i; each rigid body's own mass for its height.
    """
    rho = check_real("rho", rho, minimum=0.0, min_inclusive=False)
    m = np.repeat(rho * scene.thickness * scene.node_area, 2)
    return np.concatenate([m, [b.mass for b in scene.bodies]])


# ----------------------------------------------------------------------------------------------
# options and results
@dataclass(frozen=True)
class DynamicsOptions:
    """How to integrate in time.

    Attributes
    ----------
    scheme : str
        'midpoint' (second order, symplectic, default), 'bdf2' (second order, L-stable: for
        contact and violent snaps) or 'euler' (first order, the paper's).
    dt : float
        First (or, with ``adaptive=False``, every) time step [s], default 1e-3.
    adaptive : bool
        Adapt the step to the local error estimate (default True).
    tol : float
        Local error tolerance per step as a fraction of the membrane's size (the larger of the
        reference size L and the current largest coordinate), default 1e-4.
    dt_min, dt_max : float
        Step bounds [s] (defaults 1e-9 and 1.0).
    newton : NewtonOptions
        Tolerances of each step's Newton solve (residual relative to mu H L). At most 10 step
        halvings per iteration (statics allow 30): a time step whose Newton needs more is cut
        instead, which is cheaper. Measured on the pump (30 s): the failing solves at a slack
        cap's rounding floor spent 1107 of 1178 halvings; with 10, the CPU time fell 0.51 ->
        0.29 s with the same steps and snap times (gripper_rod 0.37 -> 0.19 s).
    save_interval : float
        Record a frame at most this often [s] (default 0: every accepted step); the last
        step is always recorded, and ``min_gap`` holds the smallest gap since the previous frame.
    max_steps : int
        Accepted plus rejected steps at most (default 1_000_000).
    line_search : str
        'energy' (default): Newton's step is accepted when it lowers the step's incremental
        potential (Armijo), which is what a time step minimises; 'residual': snapmem.solvers.newton's
        Armijo on |R|^2. Measured on the pump (30 s): 4497 step cuts and 7000 assemblies with
        'residual', 1063 cuts and half the CPU time with 'energy', same snap times.
    """

    scheme: str = "midpoint"
    dt: float = 1e-3
    adaptive: bool = True
    tol: float = 1e-4
    dt_min: float = 1e-9
    dt_max: float = 1.0
    newton: NewtonOptions = NewtonOptions(tol=1e-9, max_iterations=25, max_cuts=10)
    save_interval: float = 0.0
    max_steps: int = 1_000_000
    line_search: str = "energy"

    def __post_init__(self):
        if self.line_search not in ("energy", "residual"):
            raise SnapmemError(f"line_search = {self.line_search!r}: must be 'energy' or 'residual'")
        if self.scheme not in SCHEMES:
            raise SnapmemError(f"scheme = {self.scheme!r}: must be one of {', '.join(SCHEMES)}")
        check_real("dt", self.dt, minimum=0.0, min_inclusive=False)
        check_real("tol", self.tol, minimum=0.0, min_inclusive=False)
        check_real("dt_min", self.dt_min, minimum=0.0, min_inclusive=False)
        check_real("dt_max", self.dt_max, minimum=self.dt_min)
        check_real("save_interval", self.save_interval, minimum=0.0)
        check_int("max_steps", self.max_steps, minimum=1)

    @property
    def order(self) -> int:
        return 1 if self.scheme == "euler" else 2


@dataclass
class Trajectory:
    """Recorded frames of a simulation, and how the run went.

    Attributes
    ----------
    data : dict of str -> ndarray
        Per frame (T rows): ``t`` [s], ``r``, ``z`` (T, N) [m], ``v`` (T, n_dof) [m/s],
        ``load_<name>``, ``volume`` [m^3], ``kinetic``, ``potential``, ``total`` [J], ``dt`` [s],
        ``newton`` (iterations of the step), ``min_gap`` [m] (smallest contact gap over all
        accepted steps since the previous frame; inf without contact), and for each contact
        ``<body>_force`` [N] and ``<body>_gap`` [m], for each rigid body ``<name>_z`` [m] and
        ``<name>_v`` [m/s].
    meta : dict
        Scene name and parameters, scheme, rho, damping, step and iteration counts, wall time.
    """

    data: dict
    meta: dict = field(default_factory=dict)

    def __getitem__(self, key) -> np.ndarray:
        return self.data[key]

    @property
    def final_q(self) -> np.ndarray:
        return self.data["q"][-1]

    def save(self, path):
        """Write a compressed .npz that loads without pickle (meta as a JSON string); atomically, so
        an interrupted save leaves no half file. Returns the path written ('.npz' appended if missing)."""
        from snapmem.io.results import write_npz
        arrays = {k: np.asarray(v) for k, v in self.data.items()}
        arrays["meta"] = np.array(json.dumps(self.meta, default=_json_default))
        return write_npz(path, **arrays)

    @classmethod
    def load(cls, path) -> "Trajectory":
        from snapmem.errors import read_npz                     # corrupt or truncated: one clear error
        data = read_npz(path, "trajectory file", required=("t", "r", "z"))
        meta = json.loads(str(data.pop("meta"))) if "meta" in data else {}
        return cls(data, meta)

    def snap_time(self, key: str = "volume") -> float:
        """Time of the fastest change of ``key`` (a snap-through or snap-back) [s]."""
        t, y = self.data["t"], self.data[key]
        rate = np.abs(np.diff(y) / np.maximum(np.diff(t), 1e-300))
        i = int(np.argmax(rate))
        return float(0.5 * (t[i] + t[i + 1]))


def _json_default(x):
    if isinstance(x, (np.floating, np.integer)):
        return x.item()
    if isinstance(x, np.ndarray):
        return x.tolist()
    return str(x)


# ----------------------------------------------------------------------------------------------
# the integrator
class _Stepper:
    """One implicit step (backward Euler solve of the incremental potential) on a scene."""

    def __init__(self, scene: Scene, mass: np.ndarray, damping: np.ndarray, options: DynamicsOptions):
        self.scene, self.mass, self.damping, self.options = scene, mass, damping, options
        self.free = scene.free
        self.tol = options.newton.tol * scene.force_scale
        self._mass_free, self._damping_free = mass[self.free], damping[self.free]
        self._size = scene.meridian.size
        # the whole Newton solve in one compiled call where the scene's terms allow it
        self.compiled = CompiledStep.of(scene) if options.line_search == "energy" else None

    def solve(self, q, v, h, loads, current=None):
        """y minimising the incremental potential of step h from (q, v); (y, report).

        Newton starts from the predictor q + h v if it is admissible, else from ``current`` (the
        present state, always admissible; default q)."""
        if self.compiled is not None:
            done = self.compiled.solve(q, v, h, loads, q if current is None else current, self._mass_free,
                                       self._damping_free, self.tol, self._size, self.options.newton)
            if done is not None:
                return done
        scene, free = self.scene, self.free
        inertia_free = self._mass_free / h ** 2 + self._damping_free / h
        momentum = self._mass_free * v[free] / h

        def assemble(y):
            ev = scene.evaluate(y, loads, order=2)
            d = (y - q)[free]
            residual = ev.residual + inertia_free * d - momentum
            energy = ev.energy + 0.5 * float(d @ (inertia_free * d)) - float(momentum @ d)   # + const
            K = ev.stiffness
            K.add_diagonal(inertia_free)
            return Evaluation(energy, ev.gradient, residual, K, ev.residual_floor)

        guess = q + h * v
        # the inertia term's rounding floor, eps |q| M / h^2, grows as h falls: keep the tolerance above it
        tol = max(self.tol, 1e3 * EPS * float(inertia_free.max()) * self._size)
        if scene.inadmissible(guess) is not None:
            guess = q if current is None else current
        solver = functools.partial(newton, merit=self.options.line_search)
        y, _ev, report = solver(assemble, guess, free, tol, self.options.newton, scene.inadmissible, scene.max_step)
        return y, report


@single_threaded
def simulate(scene: Scene, loads=None, t_end: float = 1.0, rho: float = 1.0, damping: float = 0.0,
             q0: np.ndarray | None = None, v0: np.ndarray | None = None, t0: float = 0.0,
             options: DynamicsOptions = DynamicsOptions(), damp_bodies: bool = False,
             progress: Callable[[float, float], None] | None = None,
             stop: Callable[[float, np.ndarray, np.ndarray], bool] | None = None) -> Trajectory:
    """Integrate the scene's motion from t0 to t_end.

    Parameters
    ----------
    scene : Scene
    loads : callable t -> mapping, mapping of schedules (see :func:`schedule`), or None
        Loads in time; loads the schedule does not name keep the scene's defaults.
    t_end : float
        End time [s].
    rho : float
        Mass density of the membrane [kg/m^3] (lumped masses, :func:`lumped_masses`).
    damping : float
        Mass-proportional damping coefficient xi [1/s] of the membrane.
    q0, v0 : ndarray (n_dof,), optional
        Initial state (default the reference) and velocity (default rest).
    options : DynamicsOptions
    damp_bodies : bool
        Apply xi to the rigid bodies too (default False: a ball flies freely).
    progress : callable (t, t_end), optional
        Called after every accepted step.
    stop : callable (t, q, v) -> bool, optional
        Ends the run early (after recording the step) when it returns True.

    Returns
    -------
    Trajectory
        ``meta['status']`` is 'completed', or why the run ended early (the step fell below
        ``dt_min``, e.g. where a slack membrane crumples, or ``max_steps``); the frames up to
        there are kept.
    """
    wall = time.perf_counter()
    t_end = check_real("t_end", t_end)
    at = _as_schedule(loads)
    xi = check_real("damping", damping, minimum=0.0)
    mass = lumped_masses(scene, rho)
    c = xi * mass
    if not damp_bodies:
        c[scene.n_node_dofs:] = 0.0
    q = scene.reference_state() if q0 is None else np.array(q0, dtype=float)
    v = np.zeros_like(q) if v0 is None else np.array(v0, dtype=float)
    v[list(scene.fixed)] = 0.0
    why = scene.inadmissible(q)
    if why is not None:
        raise SolverError(f"initial state is outside the model's domain: {why}")
    stepper = _Stepper(scene, mass, c, options)
    free = scene.free

    last_loads = [None, None]

    def loads_at(t):                     # a step asks for the loads at its end twice (solve, record)
        if last_loads[0] != t:
            last_loads[:] = t, scene.resolve_loads(at(t))
        return last_loads[1]

    def acceleration(q, v, t):
        a = np.zeros_like(q)
        g = scene.evaluate(q, loads_at(t), order=1).gradient
        a[free] = -(g[free] + c[free] * v[free]) / mass[free]
        return a

    recorder = _Recorder(scene, mass, options.save_interval, stepper.compiled)
    a_prev = acceleration(q, v, t0)
    t, dt = t0, min(options.dt, max(t_end - t0, options.dt_min))
    recorder.record(t, q, v, loads_at(t), dt=0.0, iterations=0, force=True)
    steps = rejected = iterations = fallbacks = cuts = 0
    history = None                                     # (q_{n-1}, v_{n-1}, dt_{n-1}) for BDF2
    status = "completed"
    p = options.order
    length = scene.meridian.size
    breaks = [b for b in getattr(at, "breakpoints", []) if t0 < b < t_end]
    try:
        while t < t_end - 1e-12 * max(1.0, abs(t_end)):
            if steps + rejected >= options.max_steps:
                status = f"max_steps = {options.max_steps} reached at t = {t:.6g} s"
                break
            dt = min(dt, t_end - t)
            upcoming = [b for b in breaks if t + 1e-12 < b < t + dt]
            if upcoming:                                  # land on schedule kinks
                dt = upcoming[0] - t
            if t_end - (t + dt) < 1e-3 * dt:
                dt = t_end - t
            bdf2 = options.scheme == "bdf2" and history is not None
            if bdf2:
                # variable-step BDF2: v_{n+1} = (y - x_hat) / h, a_{n+1} = (v_{n+1} - v_hat) / h
                w = dt / history[2]
                a0, a1, a2 = (1 + 2 * w) / (1 + w), -(1 + w), w * w / (1 + w)
                h = dt / a0
                x_hat = -(a1 * q + a2 * history[0]) / a0
                v_hat = -(a1 * v + a2 * history[1]) / a0
                y, report = stepper.solve(x_hat, v_hat, h, loads_at(t + dt), current=q)
            else:
                h = dt / 2 if options.scheme == "midpoint" else dt
                y, report = stepper.solve(q, v, h, loads_at(t + h))
            iterations += report.iterations
            cuts += report.step_cuts
            if not report.converged:
                rejected += 1
                dt *= 0.25
                log.debug("t = %.6g: Newton failed (%s); dt -> %.3g", t, report.reason, dt)
                if dt < options.dt_min:
                    status = f"time step fell below dt_min = {options.dt_min:g} s at t = {t:.6g} s (Newton: {report.reason})"
                    break
                continue
            order = p
            if bdf2:
                q_new, v_new = y, (y - x_hat) / h
            elif options.scheme == "bdf2":            # its first step: implicit Euler
                q_new, v_new, order = y, (y - q) / h, 1
            elif p == 2:
                q_new = 2.0 * y - q
                v_new = 2.0 * (y - q) / h - v
                if scene.inadmissible(q_new) is not None:
                    # the extrapolation crossed a contact gap (or a lock): take this step by implicit
                    # Euler instead, whose state is Newton's own and so always admissible
                    y, report_euler = stepper.solve(q, v, dt, loads_at(t + dt))
                    iterations += report_euler.iterations
                    if not report_euler.converged:
                        rejected += 1
                        dt *= 0.25
                        if dt < options.dt_min:
                            status = (f"time step fell below dt_min = {options.dt_min:g} s at t = {t:.6g} s "
                                      f"(Newton: {report_euler.reason})")
                            break
                        continue
                    q_new, v_new, order = y, (y - q) / dt, 1
                    report.iterations += report_euler.iterations
                    fallbacks += 1
            else:
                q_new, v_new = y, (y - q) / h
            a_new = (v_new - v_hat) / h if bdf2 and options.adaptive else (v_new - v) / dt
            err = 0.0
            if options.adaptive:
                c_err = 2.0 / 9.0 if bdf2 else 1.0 / 6.0
                change = np.abs(a_new - a_prev) if order == 2 else np.abs(a_new)
                est = (c_err if order == 2 else 0.5) * dt * dt * float(change[free].max())
                size = max(length, float(np.abs(q_new[: scene.n_node_dofs]).max()))     # grows with the membrane
                err = est / (options.tol * size)
                if err > 1.0 and dt > options.dt_min:
                    rejected += 1
                    dt = max(options.dt_min, dt * max(0.2, 0.9 * err ** (-1.0 / (order + 1))))
                    continue
            # one assignment, so that an interrupt cannot leave t and the state apart
            t, history, q, v, a_prev = t + dt, (q, v, dt), q_new, v_new, a_new
            steps += 1
            recorder.record(t, q, v, loads_at(t), dt=dt, iterations=report.iterations,
                            force=t >= t_end - 1e-12 * max(1.0, abs(t_end)))
            if progress is not None:
                progress(t, t_end)
            if stop is not None and stop(t, q, v):
                recorder.record(t, q, v, loads_at(t), dt=dt, iterations=report.iterations, force=True)
                break
            if options.adaptive:
                grow = 2.0 if err == 0.0 else min(2.0, 0.9 * err ** (-1.0 / (order + 1)))
                if report.iterations > 6:
                    grow = min(grow, 1.0)
                dt = min(options.dt_max, max(options.dt_min, dt * grow))
            else:
                dt = options.dt          # a fixed step returns to its size after a cut or a landing on a kink
    except KeyboardInterrupt:                          # keep what was computed: the frames up to here
        status = f"interrupted at t = {t:.6g} s"
    if status != "completed":
        log.warning("simulation stopped early: %s", status)
        recorder.record(t, q, v, loads_at(t), dt=0.0, iterations=0, force=True)
    elif stop is not None and t < t_end - 1e-12 * max(1.0, abs(t_end)):
        status = "stopped by the stop condition"
    meta = {"scene": scene.name, "status": status, "parameters": scene.parameters, "scheme": options.scheme, "rho": rho,
            "damping": xi, "steps": steps, "rejected": rejected, "euler_fallbacks": fallbacks, "newton_iterations": iterations, "line_search_cuts": cuts,
            "wall_time": time.perf_counter() - wall, "t0": t0, "t_end": float(t),
            "nodes": scene.meridian.nodes, "closed": scene.meridian.closed,
            "bodies": [b.name for b in scene.bodies], "options": asdict(options)}
    return recorder.trajectory(meta)


class _Recorder:
    """Collects frames: the state every frame, the smallest contact gap every step; the frames'
    energies, volumes and contact reports when the trajectory is built.

    With the scene's compiled step (``compiled``) those come from one compiled call over all
    frames (``CompiledStep.measures_many``) instead of three assemblies per frame: the profile
    of ``ball_drop`` showed per-frame measures taking as long as the time steps' Newton solves.
    """

    def __init__(self, scene: Scene, mass, interval: float, compiled: CompiledStep | None = None):
        from snapmem.model.contact import contact_terms
        self.scene, self.mass, self.interval, self.compiled = scene, mass, interval, compiled
        self.contacts = contact_terms(scene)
        self.rows: list[dict] = []
        self.last_t = -np.inf
        self.min_gap = np.inf

    def _gap(self, q):
        if not self.contacts:
            return np.inf
        if self.compiled is not None:
            return self.compiled.min_gap(q)
        x = self.scene.node_coordinates(q)
        gaps = [t.gaps(x, y).min() for t, y in zip(self.scene.node_terms, self.scene.body_coordinates(q))
                if t in self.contacts]
        return min(gaps)

    def record(self, t, q, v, loads, dt, iterations, force=False):
        if not force and t - self.last_t < self.interval:
            self.min_gap = min(self.min_gap, self._gap(q))
            return
        if self.rows and self.rows[-1]["t"] == t:
            self.rows.pop()
        kinetic = 0.5 * float(self.mass @ (v * v))
        self.rows.append({"t": t, "q": q.copy(), "v": v.copy(), "kinetic": kinetic, "dt": dt, "newton": iterations,
                          "min_gap": self.min_gap, "loads": loads})    # the frame's own gap joins it when measured
        self.last_t = t
        self.min_gap = np.inf

    def _measures(self, Q, loads):
        """Potential energy, volume, smallest gap (T,) and contact report columns of the frames Q."""
        if self.compiled is not None:
            return self.compiled.measures_many(Q, loads)
        from snapmem.model.contact import contact_report
        scene = self.scene
        reports = [contact_report(scene, q) for q in Q]
        columns = {k: np.array([r[k] for r in reports]) for k in (reports[0] if reports else {})}
        return (np.array([scene.energy(q, each) for q, each in zip(Q, loads)]),
                np.array([scene.volume(q) for q in Q]), np.array([self._gap(q) for q in Q]), columns)

    def trajectory(self, meta) -> Trajectory:
        """The frames as arrays; node coordinates and body heights and speeds split off q and v."""
        loads = [row["loads"] for row in self.rows]
        data = {k: np.array([row[k] for row in self.rows]) for k in self.rows[0] if k != "loads"}
        potential, volume, gap, contacts = self._measures(data["q"], loads)
        data.update(volume=volume, potential=potential, total=data["kinetic"] + potential,
                    min_gap=np.minimum(data["min_gap"], gap))
        for name in loads[0]:
            data["load_" + name] = np.array([each[name] for each in loads])
        data.update(contacts)
        n = self.scene.n_node_dofs
        data["r"], data["z"] = data["q"][:, 0:n:2].copy(), data["q"][:, 1:n:2].copy()
        for i, body in enumerate(self.scene.bodies):
            data[f"{body.name}_z"] = data["q"][:, n + i].copy()
            data[f"{body.name}_v"] = data["v"][:, n + i].copy()
        return Trajectory(data, meta)


# ----------------------------------------------------------------------------------------------
# snap-through: from a state (a located limit point pushed past) to rest on the far branch
@dataclass
class Settled:
    """The rest state reached by :func:`settle`.

    Attributes
    ----------
    q : ndarray (n_dof,)
        Equilibrium polished by a static Newton solve at the final loads (if it converged).
    loads : dict
    trajectory : Trajectory
    at_rest : bool
        Whether the motion died out before ``t_max`` and the static polish converged.
    """

    q: np.ndarray
    loads: dict
    trajectory: Trajectory
    at_rest: bool


def settle(scene: Scene, q: np.ndarray, loads=None, rho: float = 1.0, damping: float = 1.0,
           t_max: float = 1e3, rest_tol: float = 1e-6,
           options: DynamicsOptions = DynamicsOptions(scheme="bdf2", tol=1e-3),
           v0: np.ndarray | None = None) -> Settled:
    """Run the damped dynamics from q (e.g. just past a limit point) until it comes to rest.

    Parameters
    ----------
    scene : Scene
    q : ndarray (n_dof,)
        Starting state (at rest unless ``v0``).
    loads : mapping or schedule
        Loads (constant, or in time); default the scene's.
    rho, damping : float
        Membrane density [kg/m^3] and mass-proportional damping xi [1/s] (> 0 to come to rest).
    t_max : float
        Give up after this long [s].
    rest_tol : float
        At rest when the speed is below rest_tol * L * xi and the acceleration below
        rest_tol * L * xi^2 (L the meridian size): what motion is left would move a node by
        less than about rest_tol * L.

    Returns
    -------
    Settled
        The rest state (polished to a static equilibrium with :func:`snapmem.solvers.newton.solve`), the
        loads there and the trajectory: hand it back to continuation to go on along the far
        branch, ``trace(scene, control, start=(rest.q, rest.loads))``. The default integrator is
        BDF2 at a loose tolerance: only where the motion ends matters, not its path.
    """
    at = _as_schedule(loads if loads is not None else {})
    check_real("damping", damping, minimum=0.0, min_inclusive=False)
    length = scene.meridian.size
    free = scene.free
    vmax, amax = rest_tol * length * damping, rest_tol * length * damping ** 2
    state = {"v_prev": None, "t_prev": None}

    def at_rest(t, q_now, v_now):
        prev, t_prev = state["v_prev"], state["t_prev"]
        state["v_prev"], state["t_prev"] = v_now.copy(), t
        if prev is None or np.max(np.abs(v_now[free])) > vmax:
            return False
        return np.max(np.abs((v_now - prev)[free])) / max(t - t_prev, 1e-300) <= amax

    traj = simulate(scene, at, t_max, rho=rho, damping=damping, q0=q, v0=v0, options=options, stop=at_rest)
    q_end = traj.final_q
    final_loads = scene.resolve_loads(at(float(traj["t"][-1])))
    eq = solve(scene, final_loads, q0=q_end)
    moved = np.max(np.abs(eq.q - q_end)) if eq.converged else np.inf
    ok = bool(eq.converged and moved <= 1e3 * rest_tol * length and traj["t"][-1] < t_max)
    log.info("settle: t = %.4g s, static polish %s, moved %.3g m", traj["t"][-1], eq.report.reason, moved)
    return Settled(eq.q if eq.converged else q_end, final_loads, traj, ok)
