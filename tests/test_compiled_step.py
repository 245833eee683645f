"""The compiled time step (snapmem.dynamics.compiled_step) against the general path it replaces: the same
incremental potential, residual and tangent as Scene.evaluate plus inertia, the same Newton
iterates, the same recorded frames, and the general path wherever a term is not covered."""

import contextlib
import dataclasses

import numpy as np
import pytest

import snapmem
import snapmem.dynamics.compiled_step as compiled_step
from snapmem.dynamics.compiled_newton import HANDED_BACK
from snapmem.dynamics.compiled_run import stepwise
from snapmem.kernels.banded import BandedMatrix
from snapmem.kernels.bordered import BodyMatrix, bordered_solve
from snapmem.kernels.linalg import REFINE_ON_CANCELLATION
from snapmem.dynamics.compiled_step import CompiledStep
from snapmem.model.contact import contact_report
from snapmem.dynamics.driver import _Stepper, lumped_masses, simulate
from snapmem.catalog.robots import events, experiment

# (scene, parameters, time at which its loads are taken): ball with a body and a plate, rod with
# electric, shell, a torus without contact, the Gent plate with electric
CASES = [("ball_throw", {"voltage": 400.0}, 1.0), ("ball_drop", {}, 0.0), ("gripper_rod", {"voltage": 1000.0}, 20.0),
         ("gripper_shell", {}, 20.0), ("torus_snap", {}, 1.0), ("pump", {}, 12.0)]


def perturbed(ex, scale=1e-4, seed=0):
    s = ex.scene
    q = ex.q0.copy() if ex.q0 is not None else s.reference_state()
    rng = np.random.default_rng(seed)
    q[s.free[: s.n_band]] += scale * s.meridian.size * rng.standard_normal(s.n_band)
    return q


@pytest.mark.parametrize("name, params, t", CASES)
def test_assembly_is_the_scenes_plus_inertia(name, params, t):
    ex = experiment(name, **params)
    s = ex.scene
    step = CompiledStep.of(s)
    assert step is not None
    loads = s.resolve_loads(ex.loads(t))
    q = perturbed(ex)
    assert s.inadmissible(q) is None
    rng = np.random.default_rng(1)
    nf = s.free.size
    inertia, momentum = rng.random(nf) * 1e3, rng.standard_normal(nf)
    anchor = q + 1e-5 * rng.standard_normal(q.size)
    energy, residual, lower, border, corner, floor = step.assemble(q, loads, inertia, anchor, momentum)
    ev = s.evaluate(q, loads, 2)
    d = (q - anchor)[s.free]
    assert energy == pytest.approx(ev.energy + 0.5 * d @ (inertia * d) - momentum @ d, rel=1e-13, abs=1e-15)
    expected = ev.residual + inertia * d - momentum
    assert np.max(np.abs(residual - expected)) <= 1e-13 * np.max(np.abs(expected))
    K = ev.stiffness
    K.add_diagonal(inertia)
    mine = BandedMatrix.from_lower(np.ascontiguousarray(lower), s.bandwidth)
    if s.bodies:
        mine = BodyMatrix(mine, border.T, corner)
    dense = K.to_dense()
    assert np.max(np.abs(mine.to_dense() - dense)) <= 1e-13 * np.max(np.abs(dense))
    assert floor == ev.residual_floor


@pytest.mark.parametrize("name, params, t", CASES)
def test_frame_measures_are_the_scenes(name, params, t):
    ex = experiment(name, **params)
    s = ex.scene
    loads = s.resolve_loads(ex.loads(t))
    q = perturbed(ex, 1e-6)
    energies, volumes, gaps_, columns = CompiledStep.of(s).measures_many(q[None], [loads])
    energy, volume, gap = float(energies[0]), float(volumes[0]), float(gaps_[0])
    report = {key: float(column[0]) for key, column in columns.items()}
    assert energy == pytest.approx(s.energy(q, loads), rel=1e-12)
    assert volume == pytest.approx(s.volume(q), rel=1e-13)
    expected = contact_report(s, q)
    assert report.keys() == expected.keys()
    for key, value in expected.items():
        assert report[key] == pytest.approx(value, rel=1e-12, abs=1e-300), key
    gaps = [value for key, value in expected.items() if key.endswith("_gap")]
    assert gap == (min(gaps) if gaps else np.inf)


@pytest.mark.parametrize("name, params, t", CASES)
def test_frame_energy_is_the_steps_potential_to_the_bit(name, params, t):
    """frames_measures sums the potential term by term in the step's order instead of calling the
    step's assembly (compile time): its energy must be the assembly's at zero inertia exactly, so
    a term added to one and not to the other fails here."""
    ex = experiment(name, **params)
    s = ex.scene
    loads = s.resolve_loads(ex.loads(t))
    step = CompiledStep.of(s)
    for seed in range(3):
        q = perturbed(ex, 1e-6, seed)
        zeros = np.zeros(s.free.size)
        assert float(step.measures_many(q[None], [loads])[0][0]) == step.assemble(q, loads, zeros, q, zeros)[0]


@pytest.mark.parametrize("k", [0, 1, 2])
def test_bordered_solve_against_dense(k):
    rng = np.random.default_rng(k)
    n, b = 40, 3
    A = np.zeros((n, n))
    for d in range(b + 1):
        v = rng.standard_normal(n - d)
        A += np.diag(v, -d) + (np.diag(v, d) if d else 0)
    A += 10 * np.eye(n)                                  # positive definite band
    lower = np.zeros((b + 1, n))
    for d in range(b + 1):
        lower[d, : n - d] = np.diagonal(A, -d)
    border = rng.standard_normal((k, n))
    corner = rng.standard_normal((k, k))
    corner = corner + corner.T - 50 * np.eye(k)           # an indefinite whole: the Schur is negative
    M = np.block([[A, border.T], [border, corner]])
    rhs = rng.standard_normal(n + k)
    x, ok = bordered_solve(lower, border, corner, rhs, REFINE_ON_CANCELLATION)     # C order, as the step's band
    assert ok
    assert np.max(np.abs(x - np.linalg.solve(M, rhs))) <= 1e-12 * np.max(np.abs(x))


def test_band_solve_is_the_bordered_solve_without_bodies():
    """A scene without bodies solves its band alone (compiled_newton.time_step): the same numbers,
    to the last bit, as the bordered solve with k = 0, and the same refusals."""
    from snapmem.kernels.bordered import band_solve
    rng = np.random.default_rng(3)
    n, b = 30, 3
    lower = np.vstack([10.0 + rng.random(n)] + [rng.standard_normal(n) for _ in range(b)])    # C, as the step's
    rhs = rng.standard_normal(n)
    x, ok = band_solve(lower, rhs)
    y, ok_bordered = bordered_solve(lower, np.zeros((0, n)), np.zeros((0, 0)), rhs, REFINE_ON_CANCELLATION)
    assert ok and ok_bordered and np.array_equal(x, y)
    dense = BandedMatrix.from_lower(lower, b).to_dense()
    assert np.max(np.abs(dense @ x - rhs)) <= 1e-12 * np.max(np.abs(rhs))
    tiny = lower.copy()
    tiny[0, 0], tiny[1, 0] = 1e-12, 1.0                   # growth: both refuse
    assert not band_solve(tiny, rhs)[1]
    assert not bordered_solve(tiny, np.zeros((0, n)), np.zeros((0, 0)), rhs, REFINE_ON_CANCELLATION)[1]


@pytest.mark.parametrize("name, linear, balls, general", [
    ("torus_snap", False, False, False), ("gripper_rod", True, False, False), ("ball_drop", True, True, False),
    ("pump", False, False, True)])
def test_the_step_compiles_only_the_terms_its_scene_has(name, linear, balls, general):
    """(general_law, linear, balls) are None for the kinds a scene has not (numba prunes their code),
    and hold what the scene declared otherwise."""
    step = CompiledStep.of(experiment(name).scene)
    law, lin, ball = step.terms
    assert (law is not None, lin is not None, ball is not None) == (general, linear, balls)
    if lin is not None:
        assert lin.lin_axis.size >= 1 and lin.lin_ptr[-1] == lin.lin_nodes.size
    if ball is not None:
        assert ball.ball_radius.size >= 1 and ball.ball_coef.shape == (ball.ball_radius.size, step.plan.edges.shape[0])
    if law is not None:
        assert law.law_kind == step.plan.law_kind and np.array_equal(law.law_params, step.plan.law_params)


def test_bordered_solve_hands_back_what_ldlt_cannot_take():
    n, b = 6, 1
    lower = np.zeros((b + 1, n))
    lower[0] = [1e-12, 1.0, 1.0, 1.0, 1.0, 1.0]          # a tiny pivot before a large coupling: growth
    lower[1, :-1] = 1.0
    _, ok = bordered_solve(lower, np.zeros((0, n)), np.zeros((0, 0)), np.ones(n), REFINE_ON_CANCELLATION)
    assert not ok
    lower[0, 0] = 2.0
    border, corner = np.zeros((1, n)), np.zeros((1, 1))   # singular: a body coupled to nothing, no mass
    _, ok = bordered_solve(lower, border, corner, np.ones(n + 1), REFINE_ON_CANCELLATION)
    assert not ok


def _one_step(options, compiled=True):
    """One time step of ball_throw from a perturbed state, with the inertia of a 1 ms step: (y, report)."""
    ex = experiment("ball_throw", voltage=400.0)
    s = ex.scene
    loads = s.resolve_loads(ex.loads(1.0))
    q = perturbed(ex, 1e-4, seed=3)
    mass = lumped_masses(s, ex.rho)
    v = np.zeros_like(q)
    v[s.free[: s.n_band]] = 0.05 * np.random.default_rng(4).standard_normal(s.n_band)
    with contextlib.ExitStack() as stack:
        if not compiled:
            stack.enter_context(snapmem.reference_path())
        stepper = _Stepper(s, mass, ex.damping * mass, options)
        assert (stepper.compiled is not None) == compiled
        return stepper.solve(q, v, 1e-3, loads)


@pytest.mark.parametrize("newton_fraction", [0.0, 0.1])
def test_newton_solve_matches_the_general_path(newton_fraction):
    """The compiled step and the general one: same y, iterations, cuts, with the residual test
    alone (newton_fraction 0) and with the increment test as well."""
    options = dataclasses.replace(experiment("ball_throw").options, newton_fraction=newton_fraction)
    y_c, rep_c = _one_step(options)
    y_p, rep_p = _one_step(options, compiled=False)
    assert rep_c.converged and rep_p.converged
    assert rep_c.status == rep_p.status == "converged"
    assert rep_c.iterations == rep_p.iterations >= (3 if newton_fraction == 0.0 else 1)
    assert rep_c.step_cuts == rep_p.step_cuts
    size = experiment("ball_throw").scene.meridian.size
    assert np.max(np.abs(y_c - y_p)) <= 1e-12 * size


def test_the_increment_test_stops_newton_within_its_tolerance():
    """With the increment test (newton_fraction 0.1) Newton stops earlier, at a state whose distance
    from the fully converged one (the residual test alone, to newton.tol) is within the test's
    tolerance newton_fraction tol L, on the compiled step and the general one alike."""
    base = experiment("ball_throw").options
    exact, full = _one_step(dataclasses.replace(base, newton_fraction=0.0))
    size = experiment("ball_throw").scene.meridian.size
    for compiled in (True, False):
        y, report = _one_step(dataclasses.replace(base, newton_fraction=0.1), compiled)
        assert report.converged and report.iterations < full.iterations
        assert 0.0 < np.max(np.abs(y - exact)) <= 0.1 * base.tol * size


@pytest.mark.parametrize("scheme", ["euler", "midpoint", "bdf2"])
def test_the_schemes_outcome_computed_in_the_steps_call_is_the_schemes_own(scheme):
    """Asked for it, the compiled step computes the scheme's outcome of the step (new state,
    acceleration, error estimate, the membrane's size) in the same call: to the bit what
    Scheme.outcome gives from the same y, which the stepper then hands out."""
    from snapmem.dynamics.schemes import SCHEME_BY_NAME
    ex = experiment("ball_throw", voltage=400.0)
    s = ex.scene
    loads = s.resolve_loads(ex.loads(1.0))
    q, past = perturbed(ex, 1e-4, seed=3), perturbed(ex, 1e-4, seed=5)
    mass = lumped_masses(s, ex.rho)
    rng = np.random.default_rng(4)
    v, v_past, a_prev = (np.zeros_like(q) for _ in range(3))
    for each in (v, v_past, a_prev):
        each[s.free[: s.n_band]] = 0.05 * rng.standard_normal(s.n_band)
    anchor = SCHEME_BY_NAME[scheme].anchor(q, v, 1.0, 1e-3, (past, v_past, 8e-4))
    stepper = _Stepper(s, mass, ex.damping * mass, ex.options)
    y, report = stepper.solve(anchor.q, anchor.v, anchor.h, loads, current=anchor.start,
                              outcome=(*anchor.scheme.compiled_outcome(anchor), a_prev))
    assert report.converged and stepper.compiled.outcome[0] is y
    got = stepper.outcome(anchor, y, a_prev, s.free, s.n_node_dofs)
    expected = anchor.scheme.outcome(anchor, y, a_prev, s.free, s.n_node_dofs)
    for a, b in zip(got, expected):
        assert np.array_equal(a, b)
    assert (got[0] is y) == (scheme != "midpoint") and got[3] > 0.0
    assert stepper.outcome(anchor, y.copy(), a_prev, s.free, s.n_node_dofs)[3] == got[3]   # the scheme's, then


def test_simulation_matches_the_general_path():
    ex = experiment("ball_throw")

    def run():
        return simulate(ex.scene, ex.loads, 1.7, rho=ex.rho, damping=ex.damping, q0=ex.q0, options=ex.options,
                        damp_bodies=ex.damp_bodies)

    fast = run()
    with snapmem.reference_path():
        general = run()
    assert fast.meta["newton_iterations"] == general.meta["newton_iterations"]
    assert fast.data.keys() == general.data.keys()
    for key in ("q", "potential", "ball_force", "plane_gap", "min_gap"):
        assert np.max(np.abs(fast[key] - general[key])) <= 1e-8 * np.max(np.abs(general[key])), key
    ev_f, ev_g = events(fast), events(general)
    assert ev_f["snap"] == pytest.approx(ev_g["snap"], rel=1e-9)


def test_uncovered_terms_take_the_general_path(reference_path):
    assert CompiledStep.of(experiment("ball_drop").scene) is None                       # the reference path


def test_a_term_without_a_declaration_takes_the_general_path():
    assert CompiledStep.of(experiment("pump", material="yeoh", c1=0.5).scene) is None     # a law it does not know


def test_domain_is_the_scenes_at_gents_lock():
    """The plate stretched equibiaxially past the Gent lock (I1 - 3 = 2 lam^2 + lam^-4 - 3 = Jlim = 270
    at lam = 11.7) leaves the domain; short of it, it is inside: as Scene.inadmissible says."""
    from snapmem.dynamics.compiled_assembly import admissible
    ex = experiment("pump")
    s = ex.scene
    step = CompiledStep.of(s)
    q0 = s.reference_state()
    for factor, inside in ((11.5, True), (11.9, False)):
        q = q0 * factor
        assert (s.inadmissible(q) is None) == inside
        assert admissible(q, step.plan, *step.terms) == inside


def test_a_step_handed_back_runs_on_the_general_path(monkeypatch):
    """Where the kernel cannot trust its LDL^T it hands the step back (HANDED_BACK): the stepper
    then solves it by the general Newton, and the run is the general path's. (The driver's loop a
    step at a time, which calls the time step from Python; tests/test_compiled_run.py hands the
    compiled run's attempts back to it.)"""
    ex = experiment("gripper_rod")
    kwargs = dict(rho=ex.rho, damping=ex.damping, q0=ex.q0, options=ex.options, damp_bodies=ex.damp_bodies)
    with snapmem.reference_path():
        general = simulate(ex.scene, ex.loads, 5.0, **kwargs)
    calls = []

    def hand_back(*args):
        calls.append(1)
        return args[0], HANDED_BACK, 0, 0, np.nan, args[0], args[0], args[0], np.nan, np.nan

    monkeypatch.setattr(compiled_step, "time_step", hand_back)
    with stepwise():
        handed = simulate(ex.scene, ex.loads, 5.0, **kwargs)
    assert len(calls) == handed.meta["steps"] + handed.meta["rejected"] > 10
    assert handed.meta["newton_iterations"] == general.meta["newton_iterations"]
    assert np.array_equal(handed["q"], general["q"])
