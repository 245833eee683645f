"""What a cold ``snapmem simulate`` runs as Python instead of compiling (issue 17): the kernels of
snapmem.dynamics that Python calls once a step or once a run (``interpret_uncached``), and their
twins, which must give the compiled kernels' numbers bit for bit (tests/test_python_twins.py's rule)."""

import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
import pytest

import snapmem._lazy as lazy
import snapmem.dynamics.compiled_newton as compiled_newton
import snapmem.dynamics.compiled_measures as measures
import snapmem.dynamics.step_arithmetic as arithmetic
from snapmem import build_scene
from snapmem.catalog.robots import experiment
from snapmem.dynamics.compiled_step import CompiledStep

ROOT = Path(__file__).resolve().parents[1]
# the Kernels (their module names are rebound to numba's dispatchers once they compile)
FRAMES = measures.frames_membrane
ARITHMETIC = {name: getattr(arithmetic, name) for name in ("bdf2_anchor", "largest_change", "largest_entry",
                                                            "step_outcome")}
ALWAYS = (measures.frames_contacts, compiled_newton.time_step)


def compiled(kernel):
    return getattr(kernel, "dispatcher", kernel)


def same(a, b):
    return np.array_equal(np.asarray(a), np.asarray(b), equal_nan=True)


@pytest.mark.parametrize("seed", range(8))
def test_step_arithmetic_twins_are_the_kernels_bit_for_bit(seed):
    rng = np.random.default_rng(seed)
    n = int(rng.integers(1, 40))
    q, v, qp, vp = (rng.standard_normal(n) * 10.0 ** rng.integers(-8, 8) for _ in range(4))
    if seed % 2:
        q[rng.integers(n)] = np.nan                   # NaN propagates as the loop's does
        v[rng.integers(n)] = -np.inf
    coefficients = (1.5, -2.0, 0.5) if seed % 3 else tuple(float(c) for c in rng.standard_normal(3))
    kernel = ARITHMETIC["bdf2_anchor"]
    for got, expected in zip(kernel._twin(q, v, qp, vp, *coefficients), compiled(kernel)(q, v, qp, vp, *coefficients)):
        assert same(got, expected) and got.dtype == expected.dtype and got.shape == (n,)
    for free in (np.arange(n), rng.permutation(n)[: max(1, n // 2)], np.zeros(0, dtype=np.int64)):
        change, entry = ARITHMETIC["largest_change"], ARITHMETIC["largest_entry"]
        assert same(change._twin(q, qp, free), compiled(change)(q, qp, free))
        assert same(entry._twin(v, free), compiled(entry)(v, free))
        assert type(change._twin(q, qp, free)) is float
        for n_node_dofs in (0, n // 2, n):          # a step's outcome, as the schemes take it
            outcome = ARITHMETIC["step_outcome"]
            for kind in (arithmetic.BACKWARD_ABSOLUTE, arithmetic.BACKWARD_RELATIVE, arithmetic.MIDPOINT):
                args = (kind, q, v, qp, 0.25, 0.5, vp, free, n_node_dofs)
                got, expected = outcome._twin(*args), compiled(outcome)(*args)
                assert all(same(a, b) for a, b in zip(got, expected)) and type(got[3]) is float
                assert got[0].shape == (n,)


def frames(scene, loads, count=24, seed=0):
    """Frames near the scene's reference (stretched by up to 20%), with loads (resolved) per frame."""
    step = CompiledStep.of(scene)
    rng = np.random.default_rng(seed)
    q0 = scene.reference_state()
    Q = np.array([q0 * (1.0 + 0.2 * k / count) + 1e-4 * rng.standard_normal(q0.size) for k in range(count)])
    coefficients = np.array([step.kernel_loads(scene.resolve_loads(loads(k))) for k in range(count)],
                            dtype=float).reshape(-1, 2)
    return step, np.ascontiguousarray(Q), coefficients[:, 0].copy(), coefficients[:, 1].copy()


def torus_snap():
    ex = experiment("torus_snap")                     # Mooney-Rivlin, pressure ramp, no contact
    return ex.scene, lambda k: ex.loads(0.3 * k)


def voltage_torus():                                  # prestretched, voltage off in every third frame
    return (build_scene("torus", ("voltage",), nodes=31, prestretch=1.15),
            lambda k: {"pressure": 0.05 * k, "voltage": 0.0 if k % 3 == 0 else 40.0 * k})


def robot(name, **params):
    def case():
        ex = experiment(name, **params)
        return ex.scene, lambda k: ex.loads(0.05 * ex.t_end * k)
    case.__name__ = name
    return case


@pytest.mark.parametrize("case", [torus_snap, voltage_torus, robot("gripper_rod", voltage=1000.0), robot("ball_throw")])
def test_frames_twin_is_the_kernel_bit_for_bit(case):
    """The membrane's part by the twin and compiled; the contacts' part (compiled) after either."""
    step, Q, pressure, a_el = frames(*case())
    general_law, linear, balls = step.terms
    assert general_law is None
    if case is voltage_torus:
        assert step.plan.law_stretch is not None and 0.0 in a_el and (a_el != 0.0).any()
    got = FRAMES._twin(Q, step.plan, None, pressure, a_el)
    expected = compiled(FRAMES)(Q, step.plan, None, pressure, a_el)
    for a, b in zip(got, expected):
        assert same(a, b) and a.shape == (len(Q),)
    entry = measures.frames_measures(Q, step.plan, *step.terms, pressure, a_el)
    if linear is None and balls is None:
        assert same(entry[0], expected[0]) and same(entry[1], expected[1]) and entry[2].shape == (len(Q), 0)
        return
    energies = got[0].copy(), expected[0].copy()
    after_twin = measures.frames_contacts(Q, step.plan, linear, balls, energies[0])
    after_kernel = measures.frames_contacts(Q, step.plan, linear, balls, energies[1])
    assert same(energies[0], energies[1]) and same(energies[0], entry[0])
    for a, b, c in zip(after_twin, after_kernel, entry[2:]):
        assert same(a, b) and same(a, c)


def test_a_gent_scenes_frames_compile(monkeypatch):
    """The twin covers the laws linear in the invariants: numpy's log on arrays rounds differently
    from numba's (the C library's) in some 1% of values on this machine's SIMD, so Gent's frames
    run compiled, with their old numbers."""
    monkeypatch.setattr(FRAMES, "_twin", lambda *args: pytest.fail("the twin ran"))
    gent = build_scene("balloon", ("voltage",), nodes=21, material="gent")
    step, Q, pressure, a_el = frames(gent, lambda k: {"pressure": 0.01 * k, "voltage": 30.0 * k}, count=6)
    assert step.terms[0] is not None and step.terms[1:] == (None, None)
    entry = measures.frames_measures(Q, step.plan, *step.terms, pressure, a_el)
    expected = compiled(FRAMES)(Q, step.plan, step.terms[0], pressure, a_el)
    assert same(entry[0], expected[0]) and same(entry[1], expected[1])


def test_python_of_binds_the_kernels_a_formula_names_to_their_python():
    """A formula's module names may be numba dispatchers already (made by a compiled caller);
    called on arrays they would compile for arrays. python_of's copy calls their Python."""
    import snapmem.kernels.assembly as assembly
    compiled(assembly.linear_law_density)                  # rebinds linear_law_terms' callees to dispatchers
    inner = assembly._invariant_derivatives
    before = list(getattr(inner, "signatures", []))
    lam = np.linspace(0.8, 2.0, 12).reshape(3, 4)
    got = lazy.python_of(assembly.linear_law_terms)(lam, lam[:, ::-1].copy(), 0.4, 0.1)
    assert list(getattr(inner, "signatures", [])) == before        # nothing compiled for arrays
    expected = compiled(assembly.linear_law_density)(lam.ravel(), lam[:, ::-1].ravel(), 0.4, 0.1)
    for a, b in zip(got, expected):
        assert same(np.ravel(a), b)
    assert lazy.python_of(assembly.linear_law_terms) is lazy.python_of(assembly.linear_law_terms).py_func


def test_the_background_compile_describes_the_plan_and_its_named_tuples():
    """frames_membrane's arguments (the Plan, a named tuple) rebuild to the same numba types, so the
    at-exit compile (compile_jobs) compiles it for the next process."""
    numba = pytest.importorskip("numba")
    step, Q, pressure, a_el = frames(*voltage_torus(), count=2)
    for args in [(Q, step.plan, None, pressure, a_el), (step.plan.weight, np.arange(3), 1.5, (step.plan, None))]:
        descriptions = [lazy._tupled(json.loads(json.dumps(lazy._plain(lazy._describe(a))))) for a in args]
        assert [numba.typeof(lazy._example(d)) for d in descriptions] == [numba.typeof(a) for a in args]


def test_interpret_uncached_is_snapmems_option_and_the_steps_kernels_always_compile(monkeypatch):
    monkeypatch.setitem(lazy._policy, "compile", False)
    kernel = lazy.njit(cache=True, interpret_uncached=True)(lambda x: x)
    kernel.__module__ = "snapmem.dynamics.example"
    assert "interpret_uncached" not in kernel.options and lazy._interpret_when_uncached(kernel)
    for each in (*ARITHMETIC.values(), FRAMES):
        assert each.interpret_uncached and each._twin is not None and lazy._interpret_when_uncached(each)
    for each in ALWAYS:                               # (Kernels unless compiled before collection)
        assert not isinstance(each, lazy.Kernel) or not lazy._interpret_when_uncached(each)


@pytest.mark.slow
def test_a_cold_simulate_writes_the_warm_ones_arrays():
    """``snapmem simulate torus_snap`` with an empty cache (the frames' measures and the step
    arithmetic as Python) and again compiled: every array of the npz the same, meta but its wall time."""
    env = {k: v for k, v in os.environ.items() if k != "SNAPMEM_COLD"}
    env.update(PYTHONPATH=str(ROOT), SNAPMEM_BACKGROUND_COMPILE="0")
    code = ("import sys, snapmem._lazy as lazy\nfrom snapmem.cli import main\nmain(sys.argv[1:])\n"
            "print('@' + ' '.join(lazy.interpreted()))")
    with tempfile.TemporaryDirectory() as cache:
        env["NUMBA_CACHE_DIR"] = cache
        outputs = []
        for cold in (True, False):
            out = os.path.join(cache, f"{cold}.npz")
            done = subprocess.run([sys.executable, "-c", code, "simulate", "torus_snap", "--out", out],
                                  capture_output=True, text=True, cwd=ROOT, timeout=900,
                                  env=env if cold else dict(env, SNAPMEM_COLD="compile"))
            assert done.returncode == 0, done.stderr[-3000:]
            interpreted = done.stdout.rsplit("@", 1)[1].split()
            assert ("snapmem.dynamics.compiled_measures.frames_membrane" in interpreted) == cold
            outputs.append(dict(np.load(out, allow_pickle=True)))
    cold, warm = outputs
    assert cold.keys() == warm.keys()
    for key in cold:
        if key == "meta":
            a, b = json.loads(str(cold[key])), json.loads(str(warm[key]))
            a.pop("wall_time"), b.pop("wall_time")
            assert a == b
        else:
            assert same(cold[key], warm[key]) and cold[key].dtype == warm[key].dtype, key
