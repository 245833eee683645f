"""Implicit dynamics M q'' + xi M q' + grad Pi(q, t) = 0 on the scene's own assembly: :func:`simulate`.

Every time step is one Newton solve of a backward-Euler incremental potential
(:mod:`snapmem.dynamics.stepper`); the scheme (:mod:`snapmem.dynamics.schemes`: ``midpoint``,
the default, second order and symplectic; ``bdf2``, second order and L-stable; ``euler``, first
order) chooses what it is anchored at and turns its solution into the new state.

Adaptive steps: a step is cut (by 4) when Newton fails and (by the controller) when the scheme's
local error estimate exceeds ``tol`` times the membrane's current size; it grows by up to 2x when
easy (:mod:`snapmem.dynamics.step_control`). Snaps get small steps, quasi-static ramps large
ones. Steps land on the kinks of a piecewise-linear load schedule (:mod:`snapmem.dynamics.loads`).

The loop runs here a step at a time, or, where the scene's step is compiled and the loads are a
schedule, many steps a call in :mod:`snapmem.dynamics.compiled_run`: the same loop, compiled, with
the same numbers to the bit.
"""

from __future__ import annotations

import logging
import time
from dataclasses import asdict, dataclass
from typing import Callable

import numpy as np

from snapmem.dynamics.compiled_run import DT_MIN, MAX_STEPS, PYTHON_ATTEMPT, CompiledRun
from snapmem.dynamics.loads import as_schedule, schedule
from snapmem.dynamics.options import DynamicsOptions
from snapmem.dynamics.schemes import SCHEME_BY_NAME
from snapmem.dynamics.step_control import FAILED_CUT, error_ratio, next_step, shrunk_step, step_to_take
from snapmem.dynamics.stepper import _InternalState, _Recorder, _Stepper
from snapmem.dynamics.supplies import chamber_parts, lumped_masses_of
from snapmem.dynamics.trajectory import RunOutcome, Trajectory
from snapmem.errors import SolverError, check_real
from snapmem.io.interrupts import HeldInterrupts
from snapmem.model.multi import MultiScene
from snapmem.model.scene import Scene
from snapmem.threads import single_threaded

# what callers import from here, the schedule and the options' and results' classes included
__all__ = ["DynamicsOptions", "Trajectory", "lumped_masses", "schedule", "simulate"]

log = logging.getLogger(__name__)


def lumped_masses(scene: Scene, rho: float) -> np.ndarray:
    """Lumped mass of every degree of freedom, shape (n_dof,) [kg].

    m_i = rho H A_i with A_i the node's reference ring area 2 pi r_bar_i l_bar_i (a pole node:
    its cap), for both r_i and z_i; each rigid body's own mass for its height.
    """
    rho = check_real("rho", rho, minimum=0.0, min_inclusive=False)
    if isinstance(scene, MultiScene):
        return lumped_masses_of(scene, rho, lumped_masses)
    m = np.repeat(rho * scene.thickness * scene.node_area, 2)
    return np.concatenate([m, [b.mass for b in scene.bodies]])


@dataclass
class _RunState:
    """Where a run is: its time t [s], next step dt [s], state q [m], v [m/s] and last acceleration
    a_prev [m/s^2] (n_dof,), the last step's (q, v, dt) ``history`` (None before the first), and its
    counts. The Python loop and the compiled one (snapmem.dynamics.compiled_run) both advance it."""

    t: float
    dt: float
    q: np.ndarray
    v: np.ndarray
    a_prev: np.ndarray
    history: tuple | None
    steps: int = 0
    rejected: int = 0
    iterations: int = 0
    fallbacks: int = 0
    cuts: int = 0


def _max_steps_reached(options: DynamicsOptions, t: float) -> tuple:
    """(status, outcome) of a run that reached ``options.max_steps`` at t [s]."""
    return f"max_steps = {options.max_steps} reached at t = {t:.6g} s", RunOutcome.max_steps


def _dt_min_reached(options: DynamicsOptions, t: float, reason: str) -> tuple:
    """(status, outcome) of a run whose step fell below ``options.dt_min`` at t [s], Newton failing for ``reason``."""
    return (f"time step fell below dt_min = {options.dt_min:g} s at t = {t:.6g} s (Newton: {reason})",
            RunOutcome.dt_min)


def _identical(a: tuple, b: tuple) -> bool:
    """Whether the tuples hold the same objects, one by one."""
    return len(a) == len(b) and all(x is y for x, y in zip(a, b))


@single_threaded
def simulate(scene: Scene, loads=None, t_end: float = 1.0, rho: float = 1.0, damping: float = 0.0,
             q0: np.ndarray | None = None, v0: np.ndarray | None = None, t0: float = 0.0,
             options: DynamicsOptions = DynamicsOptions(), damp_bodies: bool = False,
             progress: Callable[[float, float], None] | None = None,
             stop: Callable[[float, np.ndarray, np.ndarray], bool] | None = None,
             resume: dict | None = None) -> Trajectory:
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
        Called as the run advances, with the time reached [s]: after every call of the compiled
        run (many steps, some 20 ms of work: :mod:`snapmem.dynamics.compiled_run`), or after every
        accepted step where the loop takes a step at a time.
    stop : callable (t, q, v) -> bool, optional
        Ends the run early (after recording the step) when it returns True.
    resume : dict, optional
        ``meta['resume']`` of an earlier run of the same scene: continue it from where it ended (its
        time, state, next step, the scheme's history and the viscous networks' internal stretches;
        ``q0``, ``v0`` and ``t0`` are then ignored), so that a run split in two is the one run.

    Returns
    -------
    Trajectory
        ``meta['outcome']`` says how the run ended, one word of
        :class:`~snapmem.dynamics.trajectory.RunOutcome` ('completed', 'stopped', 'interrupted',
        'max_steps', 'dt_min'); ``meta['status']`` is 'completed', or why the run ended early (the step fell below
        ``dt_min``, e.g. where a slack membrane crumples, or ``max_steps``); the frames up to
        there are kept; ``meta['resume']`` continues the run (``resume``). ``meta['interrupted']`` is True when SIGINT (Ctrl-C) or SIGTERM came:
        the signal is taken between two steps (never inside a compiled kernel, where it would
        come back as SystemError), the run stops there with every frame so far, and the caller
        decides what to do (the command line saves them and exits 130). A second signal stops it
        at once, the frames so far still kept.
    """
    wall = time.perf_counter()
    t_end = check_real("t_end", t_end)
    at = as_schedule(loads)
    xi = check_real("damping", damping, minimum=0.0)
    mass = lumped_masses(scene, rho)
    c = xi * mass
    if not damp_bodies:
        c[scene.n_node_dofs:] = 0.0
    if resume is not None:                          # continue an earlier run: its end is the start
        q0, v0, t0 = resume["q"], resume["v"], float(resume["t"])
    q = scene.reference_state() if q0 is None else np.array(q0, dtype=float)
    v = np.zeros_like(q) if v0 is None else np.array(v0, dtype=float)
    v[list(scene.fixed)] = 0.0
    why = scene.inadmissible(q)
    if why is not None:
        raise SolverError(f"initial state is outside the model's domain: {why}")
    chambers, recorder_class = None, _Recorder
    if isinstance(scene, MultiScene):     # several membranes: their chambers' pressures are unknowns too
        stepper, chambers, recorder_class = chamber_parts(scene, mass, c, options, q, scene.resolve_loads(at(t0)))
        internal = chambers
    else:
        stepper = _Stepper(scene, mass, c, options)
        internal = _InternalState(scene, q, stepper.compiled)      # viscous networks' internal stretches (none: does nothing)
    if resume is not None:
        internal.restore(resume.get("internal", {}))
    free = scene.free
    massive = free[mass[free] > 0]          # a constraint's multiplier (support = free) has no mass, nor acceleration

    last_loads = [None, None, None, ()]      # t, the resolved loads, the schedule's dict at t and its items

    def loads_at(t):                     # a step asks for the loads at its end twice (solve, record)
        if last_loads[0] != t:
            given = at(t)
            items = (*given, *given.values()) if type(given) is dict else None
            # the same dict holding the very same keys and values (a constant schedule's) resolves alike
            if items is None or given is not last_loads[2] or not _identical(items, last_loads[3]):
                last_loads[1] = scene.resolve_loads(given)
            last_loads[0], last_loads[2], last_loads[3] = t, given, items
        return last_loads[1] if chambers is None else chambers.with_pressures(last_loads[1])

    def acceleration(q, v, t):
        a = np.zeros_like(q)
        g = scene.evaluate(q, loads_at(t), order=1).gradient
        a[massive] = -(g[massive] + c[massive] * v[massive]) / mass[massive]
        return a

    recorder = recorder_class(scene, mass, options.save_interval, stepper.compiled, internal)
    a_prev = acceleration(q, v, t0) if resume is None else np.array(resume["a_prev"], dtype=float)
    t, dt = t0, min(options.dt, max(t_end - t0, options.dt_min)) if resume is None else float(resume["dt"])
    recorder.record(t, q, v, loads_at(t), dt=0.0, iterations=0, force=True, internal=internal.frame())
    history = None                                     # (q_{n-1}, v_{n-1}, dt_{n-1}) of the last step
    if resume is not None and resume.get("history") is not None:
        hq, hv, hdt = resume["history"]
        history = (np.array(hq, dtype=float), np.array(hv, dtype=float), float(hdt))
    run = _RunState(t, dt, q, v, a_prev, history)
    status, outcome = "completed", RunOutcome.completed
    scheme = SCHEME_BY_NAME[options.scheme]
    length = scene.meridian.size
    breaks = [b for b in getattr(at, "breakpoints", []) if t0 < b < t_end]
    t_last = t_end - 1e-12 * max(1.0, abs(t_end))     # a run ends at t >= t_last (rounding of the steps' sum)
    n_node_dofs = scene.n_node_dofs
    # many steps a call where the step is compiled and the loads a schedule (None: a step at a time)
    loop = None if chambers is not None else CompiledRun.of(stepper, internal, at, scene, options, t0, t_end, t_last,
                                                             stop)
    python_turn = False                                # the next attempt is the Python loop's (handed back)
    held = HeldInterrupts().__enter__()                # SIGINT/SIGTERM noted, taken between two steps
    try:
        while run.t < t_last:
            if held.received is not None:
                status, outcome = f"interrupted at t = {run.t:.6g} s", RunOutcome.interrupted
                break
            if loop is not None and not python_turn:
                ended = loop.advance(run, recorder)
                if progress is not None:
                    progress(run.t, t_end)
                if ended == MAX_STEPS:
                    status, outcome = _max_steps_reached(options, run.t)
                    break
                if ended == DT_MIN:
                    status, outcome = _dt_min_reached(options, run.t, loop.newton_reason())
                    break
                python_turn = ended == PYTHON_ATTEMPT
                continue
            python_turn = False
            t, dt, q, v, a_prev, history = run.t, run.dt, run.q, run.v, run.a_prev, run.history
            if run.steps + run.rejected >= options.max_steps:
                status, outcome = _max_steps_reached(options, t)
                break
            dt = step_to_take(t, dt, t_end, breaks)
            anchor = scheme.anchor(q, v, t, dt, history)
            internal.open(scheme, t, dt, history)
            form = anchor.scheme.compiled_outcome(anchor)
            y, report = stepper.solve(anchor.q, anchor.v, anchor.h, loads_at(anchor.load_time), current=anchor.start,
                                      outcome=None if form is None else (*form, a_prev))
            internal.close(y if report.converged else None, dt)
            run.iterations += report.iterations
            run.cuts += report.step_cuts
            if not report.converged:
                run.rejected += 1
                run.dt = dt = dt * FAILED_CUT
                log.debug("t = %.6g: Newton failed (%s); dt -> %.3g", t, report.reason, dt)
                if dt < options.dt_min:
                    status, outcome = _dt_min_reached(options, t, report.reason)
                    break
                continue
            q_new, v_new, a_new, est, largest = stepper.outcome(anchor, y, a_prev, free, n_node_dofs)
            fallback = anchor.scheme.fallback
            if fallback is not None and scene.inadmissible(q_new) is not None:
                # the extrapolation crossed a contact gap (or a lock): take this step by the fallback
                # scheme instead, whose state is Newton's own and so always admissible
                anchor = fallback.anchor(q, v, t, dt, history)
                internal.open(fallback, t, dt, history)
                y, report_fallback = stepper.solve(anchor.q, anchor.v, anchor.h, loads_at(anchor.load_time),
                                                   current=anchor.start)
                internal.close(y if report_fallback.converged else None, dt)
                run.iterations += report_fallback.iterations
                if not report_fallback.converged:
                    run.rejected += 1
                    run.dt = dt = dt * FAILED_CUT
                    if dt < options.dt_min:
                        status, outcome = _dt_min_reached(options, t, report_fallback.reason)
                        break
                    continue
                q_new, v_new, a_new, est, largest = stepper.outcome(anchor, y, a_prev, free, n_node_dofs)
                report.iterations += report_fallback.iterations
                run.fallbacks += 1
            order = anchor.scheme.order
            err = 0.0
            if options.adaptive:
                err = error_ratio(est, options.tol, length, largest)    # relative to the membrane's size
                if err > 1.0 and dt > options.dt_min:
                    run.rejected += 1
                    run.dt = shrunk_step(dt, err, order, options.dt_min)
                    continue
            t = t + dt                 # one assignment, so that an interrupt cannot leave t and the state apart
            run.t, run.history, run.q, run.v, run.a_prev = t, (q, v, dt), q_new, v_new, a_new
            internal.commit()
            run.steps += 1
            recorder.record(t, q_new, v_new, loads_at(t), dt=dt, iterations=report.iterations,
                            force=t >= t_last, internal=internal.frame())
            if progress is not None:
                progress(t, t_end)
            if stop is not None and stop(t, q_new, v_new):
                recorder.record(t, q_new, v_new, loads_at(t), dt=dt, iterations=report.iterations, force=True,
                                internal=internal.frame())
                run.dt = dt
                break
            if options.adaptive:
                run.dt = next_step(dt, err, order, report.iterations, options.dt_min, options.dt_max)
            else:
                run.dt = options.dt      # a fixed step returns to its size after a cut or a landing on a kink
    except (KeyboardInterrupt, SystemError) as exc:    # keep what was computed: the frames up to here
        if isinstance(exc, SystemError) and held.received is None:
            held.__exit__(None, None, None)
            raise                                      # not an interrupt (a second one can land in a kernel)
        status, outcome = f"interrupted at t = {run.t:.6g} s", RunOutcome.interrupted
    except BaseException:
        held.__exit__(None, None, None)
        internal.finish()
        raise
    t, dt, q, v, a_prev, history = run.t, run.dt, run.q, run.v, run.a_prev, run.history
    steps, rejected, iterations, fallbacks, cuts = run.steps, run.rejected, run.iterations, run.fallbacks, run.cuts
    try:                                               # held until the frames are whole
        if status != "completed":
            log.warning("simulation stopped early: %s", status)
            recorder.record(t, q, v, loads_at(t), dt=0.0, iterations=0, force=True, internal=internal.frame())
        elif stop is not None and t < t_last:
            status, outcome = "stopped by the stop condition", RunOutcome.stopped
        meta = {"scene": scene.name, "status": status, "outcome": outcome.value, "parameters": scene.parameters, "scheme": options.scheme, "rho": rho,
                "damping": xi, "steps": steps, "rejected": rejected, "euler_fallbacks": fallbacks, "newton_iterations": iterations, "line_search_cuts": cuts,
                "wall_time": time.perf_counter() - wall, "t0": t0, "t_end": float(t),
                "nodes": scene.meridian.nodes, "closed": scene.meridian.closed,
                "bodies": [b.name for b in scene.bodies], "options": asdict(options),
                "interrupted": False}
        meta["resume"] = {"t": float(t), "q": q, "v": v, "dt": float(dt), "a_prev": a_prev,
                          "history": None if history is None else list(history), "internal": internal.state()}
        trajectory = recorder.trajectory(meta)
        internal.finish()
        trajectory.meta["interrupted"] = held.received is not None or outcome is RunOutcome.interrupted
        return trajectory
    finally:
        held.__exit__(None, None, None)

