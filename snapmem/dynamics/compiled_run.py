"""Many time steps in one compiled call: the loop of :func:`snapmem.dynamics.driver.simulate` for a
scene whose time step is compiled (:mod:`snapmem.dynamics.compiled_step`) and whose loads are a
schedule (:func:`snapmem.dynamics.loads.schedule`).

Why it exists: a robot's time step is one compiled Newton solve of some 60-100 us, and the
driver's Python around it (the scheme's anchor, the loads, the networks' bookkeeping, the error
control, the frame) took another 40 us a step attempt (docs/performance.md, "The compiled
run"). Here that loop runs compiled, and returns to Python only every so many steps.

It is the driver's loop, step for step: the schemes' numbers
(:func:`snapmem.dynamics.step_arithmetic.scheme_step`), the step control
(:mod:`snapmem.dynamics.step_control`), the schedule's :func:`~snapmem.dynamics.loads.interpolate`
and the electric coefficient are the functions the Python loop calls, inlined; the solve is the
compiled time step (``time_step``), which opens and closes the viscous networks' step itself; the
midpoint rule's fallback to implicit Euler is taken here too. So a run gives the Python loop's
numbers to the bit (tests/test_compiled_run.py compares every array of many runs).

A call (:func:`run_steps`) ends after ``budget`` step attempts or when its frame arrays are full
(the driver then reports progress and takes interrupts), at the run's end, at ``max_steps`` or
``dt_min``, and before an attempt it cannot take: one whose compiled Newton hands the step back
(a tangent the band LDL^T cannot factor), which the driver's Python loop then takes with the
general Newton.

What it covers: what the compiled step covers, with loads that are a schedule of piecewise-linear
and constant parts; no ``stop`` callback (it is called after every step). :meth:`CompiledRun.of`
returns None otherwise (and inside :func:`stepwise`), and the Python loop runs.
"""

from __future__ import annotations

import contextlib
import time
from collections import namedtuple

import numpy as np

from snapmem._lazy import Kernel, njit
from snapmem.dynamics.compiled_assembly import NetworkStep, Viscous, admissible, contact_gaps
from snapmem.dynamics.compiled_newton import CONVERGED, HANDED_BACK, OUTCOMES, time_step
from snapmem.dynamics.compiled_step import SQUARE, CompiledStep, electric_coefficient_compiled
from snapmem.dynamics.loads import Constant, PiecewiseLinear, interpolate_compiled
from snapmem.dynamics.schemes import SCHEME_BY_NAME
from snapmem.dynamics.step_arithmetic import BDF2, EULER, MIDPOINT_RULE, bdf2_anchor, scheme_step_compiled
from snapmem.dynamics.step_control import (FAILED_CUT, error_estimate_compiled, error_ratio_compiled,
                                           next_step_compiled, shrunk_step_compiled, step_to_take_compiled)

#: The schemes the compiled run knows (step_arithmetic.scheme_step's kinds; another runs on the Python loop).
KINDS = (EULER, MIDPOINT_RULE, BDF2)
#: How a :func:`run_steps` call ends.
(PAUSED, FINISHED, MAX_STEPS, DT_MIN, PYTHON_ATTEMPT) = range(5)

#: The slots of ``Run.clock``: the time [s], the next step [s], the last accepted step [s], the time
#: of the last frame [s], the smallest contact gap since that frame [m], the networks' dissipation [J].
T, DT, PAST_DT, LAST_FRAME, MIN_GAP, DISSIPATED = range(6)
#: The slots of ``Run.counts``: accepted and rejected steps, Newton iterations, Euler fallbacks, line
#: search cuts; whether the scheme has a last step (history) and the networks a last state; the
#: Newton code (snapmem.dynamics.compiled_newton) of the solve that ended a run at dt_min.
STEPS, REJECTED, ITERATIONS, FALLBACKS, CUTS, HISTORY, NETWORK_HISTORY, NEWTON_CODE = range(8)

#: Where the run is (the arrays it advances in place): ``clock``, ``counts`` (slots above), the state
#: ``q``, ``v`` and the last acceleration ``a`` (n_dof,), the last state ``q_past``, ``v_past``.
Run = namedtuple("Run", ["clock", "counts", "q", "v", "a", "q_past", "v_past"])
#: The run's fixed numbers: the scheme (a step_arithmetic kind), and per kind its ``start`` (the kind
#: without history), ``fallback`` (-1: none), ``order`` and ``error_constant``; DynamicsOptions'
#: ``adaptive``, ``tol``, ``dt_min``, ``dt_max``, ``dt_fixed`` (options.dt), ``save_interval`` and
#: ``max_steps``; ``t_end`` and ``t_last`` (the run ends at t >= t_last) [s]; ``length`` (the
#: membrane's reference size [m]); the time step's Newton: ``newton_tol`` [N], ``size`` [m],
#: ``increment_tol`` [m], ``max_iterations``, ``max_cuts``.
Control = namedtuple("Control", ["scheme", "start", "fallback", "order", "error_constant", "adaptive", "tol",
                                 "dt_min", "dt_max", "dt_fixed", "save_interval", "max_steps", "t_end", "t_last",
                                 "length", "newton_tol", "size", "increment_tol", "max_iterations", "max_cuts"])
#: The loads: the schedule's kinks ``breaks`` [s]; one piecewise-linear table per load, rows of
#: ``times`` [s] and ``values`` (L, m), the first ``sizes`` (L,) entries of each; the rows of the
#: pressure and the voltage (-1: the kernels take none), the electric terms' coefficients and the
#: exponent SQUARE (snapmem.dynamics.compiled_step.electric_coefficient).
Schedule = namedtuple("Schedule", ["breaks", "times", "values", "sizes", "pressure", "voltage", "electric", "square"])
#: The frames a call records (capacity F): ``t`` [s], ``q``, ``v`` (F, n_dof), ``dt`` [s], ``newton``
#: (iterations), ``min_gap`` [m], ``loads`` (F, L) every table's value, the networks' ``zeta`` (F, K,
#: 2, E) and ``dissipated`` [J] (written only with networks).
Frames = namedtuple("Frames", ["t", "q", "v", "dt", "newton", "min_gap", "loads", "zeta", "dissipated"])


@njit(cache=True, nogil=True)
def run_steps(run, control, schedule, frames, budget, mass, damping, P, general_law, linear, balls, viscous,
              network_step):
    """At most ``budget`` step attempts of the driver's loop (snapmem.dynamics.driver.simulate, which
    documents every rule) from ``run``, recording frames into ``frames``: (code, frames written),
    the code one of PAUSED, FINISHED, MAX_STEPS, DT_MIN, PYTHON_ATTEMPT (before the attempt, the
    run as it was). ``mass``, ``damping``: on the free degrees of freedom; ``P`` ... ``viscous``:
    the compiled step's (snapmem.dynamics.compiled_assembly); ``network_step``: the networks' step
    (a NetworkStep on the run's arrays: its ``zeta`` the state, ``zeta_previous`` the last one), or
    None without networks."""
    clock, counts = run.clock, run.counts
    q, v, a, q_past, v_past = run.q, run.v, run.a, run.q_past, run.v_past
    t, dt, past_dt = clock[T], clock[DT], clock[PAST_DT]
    last_frame, min_gap, dissipated = clock[LAST_FRAME], clock[MIN_GAP], clock[DISSIPATED]
    history, network_history = counts[HISTORY] != 0, counts[NETWORK_HISTORY] != 0
    written, code = 0, PAUSED
    for _ in range(budget):
        if not t < control.t_last:
            code = FINISHED
            break
        if counts[STEPS] + counts[REJECTED] >= control.max_steps:
            code = MAX_STEPS
            break
        dt_asked = dt
        dt = step_to_take_compiled(t, dt, control.t_end, schedule.breaks)
        scheme = control.scheme
        kind = scheme if history else control.start[scheme]
        network_kind = scheme if history and network_history else control.start[scheme]
        iterations = cuts = newton_code = 0
        solved = handed_back = fell_back = False
        change = largest = 0.0
        y, v_new, a_new = q, v, a
        for attempt in range(2):          # the scheme's solve, and its fallback's if that state is outside
            h, load_time, outcome_kind, outcome_step, a0, a1, a2 = scheme_step_compiled(kind, t, dt, past_dt)[:7]
            if kind == BDF2:
                x_hat, v_hat = bdf2_anchor(q, v, q_past, v_past, a0, a1, a2)
            else:
                x_hat, v_hat = q, v
            if network_step is not None:   # the networks' step: the scheme's maps (the fallback's own)
                numbers = scheme_step_compiled(network_kind if attempt == 0 else kind, t, dt, past_dt)
                c = network_step.coefficients
                c[0] = float(numbers[0])
                c[1] = numbers[7]
                c[2] = numbers[8]
                c[3] = numbers[9]
                c[4] = numbers[10]
                c[5] = numbers[11]
                c[6] = dt
            pressure, a_el = _kernel_loads(schedule, load_time)
            y, newton_code, its, solve_cuts, _, q_solved, v_new, a_new, change, largest = time_step(
                x_hat, v_hat, h, mass, damping, q, P, general_law, linear, balls, viscous, network_step, pressure,
                a_el, control.newton_tol, control.size, control.increment_tol, control.max_iterations,
                control.max_cuts, outcome_kind, outcome_step, a)
            if newton_code == HANDED_BACK:
                handed_back = True
                break
            iterations += its
            if attempt == 0:
                cuts += solve_cuts
            if newton_code != CONVERGED:
                break
            y = q_solved
            if control.fallback[kind] >= 0 and not admissible(y, P, general_law, linear, balls):
                kind = control.fallback[kind]      # the extrapolation crossed a gap: take the step by it
                fell_back = True
                continue
            solved = True
            break
        if handed_back:
            dt = dt_asked
            code = PYTHON_ATTEMPT
            break
        counts[ITERATIONS] += iterations
        counts[CUTS] += cuts
        if not solved:
            counts[REJECTED] += 1
            dt *= FAILED_CUT
            if dt < control.dt_min:
                counts[NEWTON_CODE] = newton_code
                code = DT_MIN
                break
            continue
        if fell_back:
            counts[FALLBACKS] += 1
        order = control.order[kind]
        err = 0.0
        if control.adaptive:
            err = error_ratio_compiled(error_estimate_compiled(control.error_constant[kind], dt, change), control.tol,
                                       control.length, largest)
            if err > 1.0 and dt > control.dt_min:
                counts[REJECTED] += 1
                dt = shrunk_step_compiled(dt, err, order, control.dt_min)
                continue
        t = t + dt
        past_dt = dt
        history = True
        for i in range(q.size):
            q_past[i], v_past[i] = q[i], v[i]
            q[i], v[i], a[i] = y[i], v_new[i], a_new[i]
        if network_step is not None:               # commit the networks' step
            _copy(network_step.zeta_previous, network_step.zeta)
            _copy(network_step.zeta, network_step.zeta_new)
            dissipated += network_step.dissipated[0]
            network_history = True
        counts[STEPS] += 1
        if not t >= control.t_last and t - last_frame < control.save_interval:
            min_gap = min(min_gap, _smallest_gap(q, P, linear, balls))
        else:
            _record(frames, written, t, q, v, dt, iterations, min_gap, schedule, network_step, dissipated)
            written += 1
            last_frame, min_gap = t, np.inf
        if control.adaptive:
            dt = next_step_compiled(dt, err, order, iterations, control.dt_min, control.dt_max)
        else:
            dt = control.dt_fixed
        if written == frames.t.size:
            break
    clock[T], clock[DT], clock[PAST_DT] = t, dt, past_dt
    clock[LAST_FRAME], clock[MIN_GAP], clock[DISSIPATED] = last_frame, min_gap, dissipated
    counts[HISTORY] = 1 if history else 0
    counts[NETWORK_HISTORY] = 1 if network_history else 0
    return code, written


@njit(cache=True, nogil=True, no_cpython_wrapper=True, no_cfunc_wrapper=True, inline="always")
def _load(schedule, row, t):
    """Load ``row`` of the schedule at time t."""
    n = schedule.sizes[row]
    return interpolate_compiled(t, schedule.times[row, :n], schedule.values[row, :n])


@njit(cache=True, nogil=True, no_cpython_wrapper=True, no_cfunc_wrapper=True, inline="always")
def _kernel_loads(schedule, t):
    """(pressure, a_el) at time t: snapmem.dynamics.compiled_step.CompiledStep.kernel_loads of the
    schedule's loads."""
    pressure = _load(schedule, schedule.pressure, t) if schedule.pressure >= 0 else 0.0
    a_el = 0.0
    if schedule.voltage >= 0:
        a_el = electric_coefficient_compiled(_load(schedule, schedule.voltage, t), schedule.electric, schedule.square)
    return pressure, a_el


@njit(cache=True, nogil=True, no_cpython_wrapper=True, no_cfunc_wrapper=True)
def _smallest_gap(q, P, linear, balls):
    """The smallest contact gap at q [m], inf without contact (NaN if one is, as numpy's min)."""
    gaps = contact_gaps(q, P, linear, balls)
    smallest = np.inf
    for i in range(gaps.size):
        if gaps[i] != gaps[i]:
            return gaps[i]
        smallest = min(smallest, gaps[i])
    return smallest


@njit(cache=True, nogil=True, no_cpython_wrapper=True, no_cfunc_wrapper=True)
def _record(frames, i, t, q, v, dt, iterations, min_gap, schedule, network_step, dissipated):
    """Frame i: the state now, the step's dt and Newton iterations, the smallest gap since the last
    frame, every load at t, the networks' state and dissipation."""
    frames.t[i], frames.dt[i], frames.newton[i], frames.min_gap[i] = t, dt, iterations, min_gap
    for j in range(q.size):
        frames.q[i, j], frames.v[i, j] = q[j], v[j]
    for row in range(schedule.sizes.size):
        frames.loads[i, row] = _load(schedule, row, t)
    if network_step is not None:
        _copy(frames.zeta[i], network_step.zeta)
        frames.dissipated[i] = dissipated


@njit(cache=True, nogil=True, no_cpython_wrapper=True, no_cfunc_wrapper=True, inline="always")
def _copy(target, source):
    """target[...] = source for (K, 2, E) arrays, as a loop (an array assignment compiles a function of its own)."""
    for k in range(source.shape[0]):
        for i in range(2):
            for e in range(source.shape[2]):
                target[k, i, e] = source[k, i, e]


# ----------------------------------------------------------------------------------------------
# The driver's side


_enabled = [True]


@contextlib.contextmanager
def stepwise():
    """``with stepwise():`` runs take the driver's Python loop, a compiled step at a time (the
    compiled run's reference, for the tests and the benchmarks)."""
    before = _enabled[0]
    _enabled[0] = False
    try:
        yield
    finally:
        _enabled[0] = before


class CompiledRun:
    """The compiled loop of one run (:func:`run_steps`): its arrays, and the exchange of the run's
    state with the driver (:meth:`advance`)."""

    #: Frames one call records at most.
    CAPACITY = 256
    #: A call takes about this long [s] (its budget of attempts adapts to it): the driver's
    #: progress and interrupts wait no longer.
    CALL_TIME = 0.02

    def __init__(self, stepper, internal, control: Control, schedule: Schedule, names: list, defaults: dict):
        step, n = stepper.compiled, stepper.mass.size
        self.internal, self.control, self.schedule = internal, control, schedule
        self._names, self._defaults = names, defaults           # the schedule's loads (rows of its tables)
        self.run = Run(clock=np.zeros(6), counts=np.zeros(8, dtype=np.int64), q=np.empty(n), v=np.empty(n),
                       a=np.empty(n), q_past=np.empty(n), v_past=np.empty(n))
        term = step.viscous_term
        shape = (0, 2, 0) if term is None else (term.networks, 2, step.plan.edges.shape[0])
        self.network_step = self._viscous = None
        if term is not None:           # the networks' arrays for the run, as the compiled step's (same types)
            self.network_step = NetworkStep(zeta=np.empty(shape), zeta_previous=np.empty(shape),
                                            coefficients=np.zeros(7), viscosities=np.array(term.viscosities, dtype=float),
                                            zeta_new=np.empty(shape), dissipated=np.zeros(1))
            self._viscous = Viscous(visc_mu=np.array(term.moduli, dtype=float), visc_jlim=step.viscous.visc_jlim,
                                    visc_c=np.empty(term.networks), zeta_hat=np.empty(shape),
                                    zeta_warm=np.empty(shape), zeta_warm_exp=np.empty(shape))
        c = self.CAPACITY
        self.frames = Frames(t=np.empty(c), q=np.empty((c, n)), v=np.empty((c, n)), dt=np.empty(c),
                             newton=np.empty(c, dtype=np.int64), min_gap=np.empty(c),
                             loads=np.empty((c, schedule.sizes.size)), zeta=np.empty((c, *shape)),
                             dissipated=np.empty(c))
        self._fixed = (np.ascontiguousarray(stepper._mass_free, dtype=float),
                       np.ascontiguousarray(stepper._damping_free, dtype=float), step.plan, *step.terms)
        self.budget = 8                     # attempts a call (grows to about CALL_TIME a call)
        self._newton_code = CONVERGED

    def advance(self, state, recorder) -> int:
        """One call of the compiled loop from the driver's ``state`` (snapmem.dynamics.driver._RunState,
        advanced in place), its frames handed to ``recorder``: how the call ended (PAUSED, FINISHED,
        MAX_STEPS, DT_MIN, PYTHON_ATTEMPT)."""
        run, internal, network_step = self.run, self.internal, self.network_step
        clock, counts = run.clock, run.counts
        clock[T], clock[DT], clock[LAST_FRAME], clock[MIN_GAP] = state.t, state.dt, recorder.last_t, recorder.min_gap
        counts[STEPS:CUTS + 1] = state.steps, state.rejected, state.iterations, state.fallbacks, state.cuts
        run.q[:], run.v[:], run.a[:] = state.q, state.v, state.a_prev
        counts[HISTORY] = state.history is not None
        if state.history is not None:
            run.q_past[:], run.v_past[:] = state.history[0], state.history[1]
            clock[PAST_DT] = state.history[2]
        if network_step is not None:
            term = internal.terms[0]
            network_step.zeta[...] = term.zeta
            network_step.zeta_previous[...] = term.zeta if internal.previous is None else internal.previous[0]
            counts[NETWORK_HISTORY] = internal.previous is not None
            clock[DISSIPATED] = internal.dissipated
        start = time.perf_counter()
        code, written = run_steps(*self._arguments())
        elapsed = time.perf_counter() - start
        if code == PAUSED and written < self.CAPACITY and elapsed < 0.5 * self.CALL_TIME:
            self.budget = min(2 * self.budget, 1 << 20)
        elif elapsed > 2.0 * self.CALL_TIME:
            self.budget = max(1, self.budget // 2)
        state.t, state.dt = float(clock[T]), float(clock[DT])
        state.steps, state.rejected, state.iterations, state.fallbacks, state.cuts = (
            int(c) for c in counts[STEPS:CUTS + 1])
        state.q, state.v, state.a_prev = run.q.copy(), run.v.copy(), run.a.copy()
        state.history = ((run.q_past.copy(), run.v_past.copy(), float(clock[PAST_DT])) if counts[HISTORY]
                         else None)
        recorder.last_t, recorder.min_gap = float(clock[LAST_FRAME]), float(clock[MIN_GAP])
        if network_step is not None:
            internal.adopt(network_step.zeta, network_step.zeta_previous if counts[NETWORK_HISTORY] else None,
                           clock[DISSIPATED])
        if written:
            recorder.add_frames(self._block(written), self._loads(written))
        self._newton_code = int(counts[NEWTON_CODE])
        return int(code)

    def _arguments(self) -> tuple:
        """run_steps' arguments for the next call."""
        return (self.run, self.control, self.schedule, self.frames, self.budget, *self._fixed, self._viscous,
                self.network_step)

    def newton_reason(self) -> str:
        """Why the last solve of a run that ended at dt_min failed (the Newton report's reason)."""
        return OUTCOMES[self._newton_code][1]

    def _block(self, written: int) -> dict:
        """The frames of the last call, as the recorder's columns (copies)."""
        f = self.frames
        block = {"t": f.t[:written].copy(), "q": f.q[:written].copy(), "v": f.v[:written].copy(),
                 "dt": f.dt[:written].copy(), "newton": f.newton[:written].copy(),
                 "min_gap": f.min_gap[:written].copy()}
        if self.network_step is not None:
            block["zeta"], block["dissipation"] = f.zeta[:written].copy(), f.dissipated[:written].copy()
        return block

    def _loads(self, written: int) -> list:
        """Every frame's resolved loads (the scene's defaults, the schedule's values at its time)."""
        names, defaults = self._names, self._defaults
        rows = self.frames.loads[:written, : len(names)].tolist()
        return [{**defaults, **dict(zip(names, row))} for row in rows]

    @classmethod
    def of(cls, stepper, internal, loads, scene, options, t0: float, t_end: float, t_last: float,
           stop) -> "CompiledRun | None":
        """The compiled run of a simulation from t0 to t_end [s] (it ends at t >= t_last), or None
        where the driver's Python loop must run (see the module's docstring)."""
        step = getattr(stepper, "compiled", None)
        parts = getattr(loads, "parts", None)
        if (not _enabled[0] or stop is not None or type(step) is not CompiledStep or parts is None
                or not all(type(p) in (PiecewiseLinear, Constant) for p in parts.values())
                or getattr(SCHEME_BY_NAME[options.scheme], "kind", None) not in KINDS):
            return None
        if internal.terms and (len(internal.terms) != 1 or step.viscous_term is not internal.terms[0]):
            return None
        defaults = scene.resolve_loads({})
        tables = dict(parts)                     # a table per load the kernels or the frames read
        for name, needed in (("pressure", step.has_pressure), ("voltage", bool(step.electric))):
            if needed and name not in tables:
                tables[name] = Constant(float(defaults[name]))
        names = list(tables)
        width = max(len(p.times) if type(p) is PiecewiseLinear else 1 for p in tables.values()) if names else 1
        times, values = np.zeros((len(names), width)), np.zeros((len(names), width))
        sizes = np.zeros(len(names), dtype=np.int64)
        for row, name in enumerate(names):
            part = tables[name]
            ts, vs = (part.times, part.values) if type(part) is PiecewiseLinear else ((0.0,), (part.value,))
            sizes[row] = len(ts)
            times[row, :len(ts)], values[row, :len(vs)] = ts, vs
        breaks = np.array([b for b in getattr(loads, "breakpoints", []) if t0 < b < t_end], dtype=float)
        schedule = Schedule(breaks=np.ascontiguousarray(breaks), times=times, values=values, sizes=sizes,
                            pressure=names.index("pressure") if step.has_pressure else -1,
                            voltage=names.index("voltage") if step.electric else -1,
                            electric=np.array(step.electric, dtype=float), square=SQUARE)
        scheme = SCHEME_BY_NAME[options.scheme]
        kinds = [next(s for s in SCHEME_BY_NAME.values() if getattr(s, "kind", None) == k) for k in KINDS]
        newton = options.newton
        control = Control(
            scheme=scheme.kind, start=np.array([getattr(s, "start", s).kind for s in kinds], dtype=np.int64),
            fallback=np.array([-1 if s.fallback is None else s.fallback.kind for s in kinds], dtype=np.int64),
            order=np.array([s.order for s in kinds], dtype=np.int64),
            error_constant=np.array([s.error_constant for s in kinds], dtype=float),
            adaptive=bool(options.adaptive), tol=float(options.tol), dt_min=float(options.dt_min),
            dt_max=float(options.dt_max), dt_fixed=float(options.dt), save_interval=float(options.save_interval),
            max_steps=int(options.max_steps), t_end=float(t_end), t_last=float(t_last),
            length=float(scene.meridian.size), newton_tol=float(stepper.tol), size=float(stepper._size),
            increment_tol=float(stepper.increment_tol), max_iterations=int(newton.max_iterations),
            max_cuts=int(newton.max_cuts))
        loop = cls(stepper, internal, control, schedule, [n for n in names if n in parts], defaults)
        # not in numba's cache yet: the Python loop this time, the compiled one after a background
        # compile (snapmem._lazy's first-use policy; a cold run_steps costs 3-5 s over the time step's)
        if isinstance(run_steps, Kernel) and not run_steps.ready(loop._arguments()):
            return None
        return loop
