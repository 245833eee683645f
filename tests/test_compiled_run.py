"""The compiled run (snapmem.dynamics.compiled_run) is the driver's loop: every array of a run and
every count the same to the bit as the driver's Python loop taking one compiled step at a time
(``stepwise``), over every scheme, contact, networks, fixed and adaptive steps, frames kept at an
interval, a resumed run, and the ends a run can have; a call that hands an attempt back to the
Python loop changes nothing either. And the formulas both loops call (the schedule's
interpolation, the step control) against what they replace."""

import dataclasses

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

import snapmem._lazy as lazy
import snapmem.dynamics.compiled_run as compiled_run
from snapmem.catalog.robots import experiment
from snapmem.dynamics.compiled_run import PYTHON_ATTEMPT, CompiledRun, stepwise
from snapmem.dynamics.driver import simulate
from snapmem.dynamics.loads import interpolate, schedule
from snapmem.dynamics.step_control import step_to_take
from snapmem.solvers.newton import NewtonOptions


def viscous(name):
    """One network, a quarter of the law's modulus, relaxing within the run (as studies/viscous_speed.py)."""
    ex = experiment(name)
    return {"viscous_mu": 0.25 * float(ex.scene.density_terms[0].law.mu), "relaxation_time": 0.1 * ex.t_end}


def run(name, t_end=None, params=None, resume_at=None, progress=None, **options):
    ex = experiment(name, **(params or {}))
    kwargs = dict(rho=ex.rho, damping=ex.damping, q0=ex.q0, v0=ex.v0, damp_bodies=ex.damp_bodies,
                  options=dataclasses.replace(ex.options, **options), progress=progress)
    t_end = ex.t_end if t_end is None else t_end
    if resume_at is None:
        return simulate(ex.scene, ex.loads, t_end, **kwargs)
    first = simulate(ex.scene, ex.loads, resume_at, **kwargs)
    again = experiment(name, **(params or {}))
    return simulate(again.scene, again.loads, t_end, resume=first.meta["resume"], **kwargs)


def assert_same_run(a, b):
    assert a.data.keys() == b.data.keys()
    for key in a.data:
        x, y = np.asarray(a[key]), np.asarray(b[key])
        assert x.dtype == y.dtype and x.shape == y.shape and np.array_equal(x, y, equal_nan=True), key
    for key in ("steps", "rejected", "euler_fallbacks", "newton_iterations", "line_search_cuts", "status", "outcome",
                "t_end", "interrupted"):
        assert a.meta[key] == b.meta[key], key
    for key in ("q", "v", "a_prev"):
        assert np.array_equal(a.meta["resume"][key], b.meta["resume"][key]), key
    assert a.meta["resume"]["dt"] == b.meta["resume"]["dt"] and a.meta["resume"]["t"] == b.meta["resume"]["t"]


CASES = {
    "ball_throw, viscous (BDF2, ball on a body, pressure ramp)": dict(name="ball_throw", params="viscous"),
    "ball_drop, midpoint (Euler fallbacks at the impact)": dict(name="ball_drop", t_end=0.8, scheme="midpoint"),
    "pump, viscous (voltage and pressure schedules, plate contact)": dict(name="pump", params="viscous"),
    "gripper_rod, Euler, fixed steps (linear contact)": dict(name="gripper_rod", t_end=2.0, scheme="euler",
                                                            adaptive=False, dt=0.01),
    "torus_snap, two networks, frames at an interval": dict(
        name="torus_snap", t_end=10.0, save_interval=0.5,
        params={"viscous_mu": [400.0, 100.0], "relaxation_time": [0.5, 4.0]}),
    "balloon under a held pressure, viscous": dict(name="balloon", t_end=8.0,
                                                   params={"pressure": 0.012, "viscous_mu": 0.5, "relaxation_time": 1.0}),
    "ball_throw, resumed at 0.9 s": dict(name="ball_throw", resume_at=0.9, params="viscous"),
    "ball_drop, max_steps": dict(name="ball_drop", max_steps=60, outcome="max_steps"),
    "ball_throw, Newton failures (steps retaken at a quarter)": dict(
        name="ball_throw", t_end=1.0, dt=1e-3, dt_min=1e-4, newton=NewtonOptions(max_iterations=1)),
    "pump, dt_min (no Newton converges in one iteration)": dict(
        name="pump", t_end=1.0, dt=1e-3, dt_min=1e-4, newton=NewtonOptions(max_iterations=1), outcome="dt_min"),
}


@pytest.mark.parametrize("case", CASES)
def test_the_compiled_run_is_the_python_loop_to_the_bit(case):
    spec = dict(CASES[case])
    if spec.get("params") == "viscous":
        spec["params"] = viscous(spec["name"])
    outcome = spec.pop("outcome", "completed")
    calls = []
    fast = run(**spec, progress=lambda t, t_end: calls.append(t))
    with stepwise():
        slow = run(**spec)
    assert_same_run(fast, slow)
    assert fast.meta["outcome"] == outcome and calls == sorted(calls)
    assert fast.meta["steps"] > 10 or outcome == "dt_min"


def test_attempts_handed_back_to_the_python_loop_change_nothing(monkeypatch):
    """Every other call hands its first attempt back (as where the compiled Newton hands a step
    back): the driver's Python loop takes it, and the run goes on compiled, with the same numbers."""
    spec = dict(name="ball_throw", params=viscous("ball_throw"))
    with stepwise():
        slow = run(**spec)
    real, calls = compiled_run.run_steps, {"n": 0, "handed": 0}

    def sometimes_handed_back(*args):
        calls["n"] += 1
        if calls["n"] % 2:
            calls["handed"] += 1
            return PYTHON_ATTEMPT, 0
        return real(*args)

    monkeypatch.setattr(compiled_run, "run_steps", sometimes_handed_back)
    monkeypatch.setattr(CompiledRun, "CALL_TIME", 0.0)         # a few attempts a call: many exchanges
    assert_same_run(run(**spec), slow)
    assert calls["handed"] > 10


def test_a_run_with_a_stop_condition_or_a_callable_load_takes_the_python_loop():
    ex = experiment("ball_throw")
    args = (ex.scene, ex.loads, 0.1)
    kwargs = dict(rho=ex.rho, damping=ex.damping, q0=ex.q0, options=ex.options, damp_bodies=ex.damp_bodies)
    ran = []
    real = CompiledRun.advance

    def advance(self, *a):
        ran.append(1)
        return real(self, *a)

    with pytest.MonkeyPatch.context() as m:
        m.setattr(CompiledRun, "advance", advance)
        simulate(*args, **kwargs)
        assert ran
        ran.clear()
        simulate(*args, stop=lambda t, q, v: False, **kwargs)
        simulate(ex.scene, lambda t: ex.loads(t), 0.1, **{k: v for k, v in kwargs.items()})
        assert not ran


def test_a_cold_run_takes_the_python_loop_and_compiles_the_loop_in_the_background(monkeypatch):
    """snapmem._lazy's first-use policy: not in numba's cache (and kernels not compiled at first
    call), the run takes the Python loop and run_steps is noted for the compile at exit."""
    kernel = lazy.njit(cache=True, nogil=True)(compiled_run.run_steps.py_func)
    monkeypatch.setattr(compiled_run, "run_steps", kernel)
    monkeypatch.setitem(lazy._policy, "compile", False)
    monkeypatch.setattr(lazy, "_in_cache", lambda k: False)
    monkeypatch.setattr(lazy, "_seen", {})
    monkeypatch.setenv("SNAPMEM_BACKGROUND_COMPILE", "0")
    ex = experiment("ball_throw")
    from snapmem.dynamics.stepper import _InternalState, _Stepper
    from snapmem.dynamics.driver import lumped_masses
    mass = lumped_masses(ex.scene, ex.rho)
    stepper = _Stepper(ex.scene, mass, 0.0 * mass, ex.options)
    internal = _InternalState(ex.scene, ex.q0, stepper.compiled)
    assert CompiledRun.of(stepper, internal, ex.loads, ex.scene, ex.options, 0.0, 1.0, 1.0, None) is None
    assert (compiled_run.__name__, "run_steps") in lazy._seen
    monkeypatch.setitem(lazy._policy, "compile", True)
    assert CompiledRun.of(stepper, internal, ex.loads, ex.scene, ex.options, 0.0, 1.0, 1.0, None) is not None


times = st.lists(st.floats(-5, 20, allow_nan=False), min_size=1, max_size=6).map(sorted)


@settings(max_examples=300, deadline=None)
@given(times=times, data=st.data())
def test_interpolate_is_numpys_interp(times, data):
    values = data.draw(st.lists(st.floats(-1e6, 1e6, allow_nan=False) | st.sampled_from([np.inf, -np.inf]),
                                min_size=len(times), max_size=len(times)))
    probes = [*times, *data.draw(st.lists(st.floats(-10, 30, allow_nan=False), max_size=5)), np.nan]
    for t in probes:
        with np.errstate(invalid="ignore"):
            expected = np.interp(t, times, values)
            got = interpolate(t, tuple(times), tuple(values))
        assert got == expected or (np.isnan(got) and np.isnan(expected)), (t, times, values)


def test_a_schedule_lands_on_its_kinks_and_reads_its_parts():
    loads = schedule(pressure=[(0, 0), (5, 0), (20, 150)], voltage=300.0)
    assert loads(10.0) == {"pressure": 50.0, "voltage": 300.0} and loads.breakpoints == [0.0, 5.0, 20.0]
    assert [type(p).__name__ for p in loads.parts.values()] == ["PiecewiseLinear", "Constant"]
    assert step_to_take(4.0, 2.0, 30.0, loads.breakpoints) == 1.0            # lands on t = 5
    assert step_to_take(5.0, 2.0, 30.0, loads.breakpoints) == 2.0            # already on it
    assert step_to_take(29.0, 0.9995, 30.0, loads.breakpoints) == 1.0        # no sliver before t_end
    assert step_to_take(29.5, 2.0, 30.0, loads.breakpoints) == 0.5


def _compiled_copy(kernel, arity):
    """A Python-callable njit function of ``arity`` arguments that calls the inlined formula
    ``kernel`` (which has no Python entry point of its own)."""
    numba = pytest.importorskip("numba")
    inner = getattr(kernel, "dispatcher", kernel)
    names = ", ".join(f"a{i}" for i in range(arity))
    namespace = {"inner": inner}
    exec(f"def call({names}):\n    return inner({names})", namespace)
    return numba.njit(namespace["call"])


def _formula_cases(rng):
    """(name, Python formula, its compiled copy, argument tuples) of every formula both loops call."""
    from snapmem.dynamics import compiled_step, loads, step_arithmetic, step_control
    times = np.array([0.0, 1.5, 1.5, 4.0, 10.0])
    values = np.array([0.0, 2.0, -3.0, 5.5, 5.5])
    dts = 10.0 ** rng.uniform(-6, 0, 200)
    errs = 10.0 ** rng.uniform(-4, 3, 200)
    return [
        ("interpolate", loads.interpolate, loads.interpolate_compiled,
         [(float(t), times, values) for t in np.concatenate([rng.uniform(-2, 12, 200), times])]),
        ("electric_coefficient", compiled_step.electric_coefficient, compiled_step.electric_coefficient_compiled,
         [(float(phi), np.array([1.7e-7, 3.1e-9]), compiled_step.SQUARE) for phi in rng.uniform(-5e3, 5e3, 4000)]),
        ("scheme_step", step_arithmetic.scheme_step, step_arithmetic.scheme_step_compiled,
         [(k, float(t), float(dt), float(p)) for k in (0, 1, 2)
          for t, dt, p in zip(rng.uniform(0, 5, 60), dts, dts[::-1])]),
        ("step_to_take", step_control.step_to_take, step_control.step_to_take_compiled,
         [(float(t), float(dt), 10.0, times) for t, dt in zip(rng.uniform(0, 10, 200), 10 * dts)]),
        ("shrunk_step", step_control.shrunk_step, step_control.shrunk_step_compiled,
         [(float(dt), float(1.0 + e), o, 1e-9) for dt, e, o in zip(dts, errs, [1, 2] * 100)]),
        ("next_step", step_control.next_step, step_control.next_step_compiled,
         [(float(dt), float(e), o, i, 1e-9, 0.05) for dt, e, o, i in zip(dts, errs, [1, 2] * 100, range(200))]),
        ("error_ratio", step_control.error_ratio, step_control.error_ratio_compiled,
         [(float(e), 1e-4, 0.05, float(s)) for e, s in zip(errs, rng.uniform(0, 0.1, 200))]),
    ]


@pytest.mark.parametrize("index", range(7))
def test_each_formula_gives_the_same_bits_compiled(index):
    """The formulas both loops call, in Python and as the kernel inlines them: the same numbers to
    the bit (a constant exponent would not be: electric_coefficient takes it as an argument)."""
    name, python, kernel, cases = _formula_cases(np.random.default_rng(index))[index]
    compiled = _compiled_copy(kernel, len(cases[0]))
    for args in cases:
        expected, got = python(*args), compiled(*args)
        assert np.array_equal(np.asarray(expected, dtype=float), np.asarray(got, dtype=float)), (name, args)
