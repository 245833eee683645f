"""Property-based tests (hypothesis) over random shapes, meshes, materials, loads and states:
gradients and Hessians match finite differences, the energy is invariant under a z translation, and
the solver either converges to a state whose residual is below its tolerance or says it failed."""

import numpy as np
from hypothesis import HealthCheck, assume, event, given, settings
from hypothesis import strategies as st

from snapmem import build_scene, equilibrium, solve
from snapmem.model.materials import LAWS
from snapmem.model.meridian import disc, sphere, torus
from snapmem.solvers.newton import STATUSES, NewtonOptions
from snapmem.model.scene import Scene
from snapmem.model.terms import Electric, PressureWork, Stretching

SETTINGS = dict(deadline=None, derandomize=True, suppress_health_check=[HealthCheck.too_slow])


@st.composite
def meridians(draw):
    """A disc, sphere or torus of random size and mesh, with its boundary conditions."""
    shape = draw(st.sampled_from(["disc", "sphere", "torus"]))
    size = draw(st.floats(0.1, 20.0))
    nodes = draw(st.integers(5, 16))
    if shape == "disc":
        m = disc(size, nodes)
        return m, [0, 1, 2 * (nodes - 1)]
    if shape == "sphere":
        m = sphere(size, nodes)
        return m, [0, 1, 2 * (nodes - 1)]
    m = torus(size, draw(st.floats(0.05, 0.9)) * size, nodes)
    return m, [1]


@st.composite
def laws(draw):
    """Every registered law: its declared example with each parameter scaled by a random factor
    in [0.5, 2] (which keeps a bound at 0), then given a random shear modulus."""
    cls = LAWS[draw(st.sampled_from(list(LAWS)))][0]
    example = cls.example()
    values = {p.name: getattr(example, p.name) * draw(st.floats(0.5, 2.0)) for p in cls.parameters}
    return cls.from_parameters(**cls.with_modulus(values, draw(st.floats(0.1, 10.0))))


@st.composite
def scenes_and_states(draw):
    """A scene with every energy term, random loads, and a random admissible state near a stretch."""
    m, fixed = draw(meridians())
    H = draw(st.floats(0.01, 0.2)) * m.size
    law = draw(laws())
    scene = Scene(m, H, [Stretching(law), Electric(1.0, H), PressureWork()], fixed=fixed,
                  loads={"pressure": draw(st.floats(-1.0, 1.0)) * law.mu * H / m.size,
                         "voltage": draw(st.floats(0.0, 0.5)) * H * np.sqrt(law.mu)})
    rng = np.random.default_rng(draw(st.integers(0, 2 ** 32 - 1)))
    q = m.q * draw(st.floats(0.8, 1.5))
    q = q + rng.normal(scale=0.03 * m.size / m.nodes, size=q.size)
    q[fixed] = m.q[fixed]
    assume(scene.inadmissible(q) is None)
    return scene, q, rng


@settings(max_examples=40, **SETTINGS)
@given(scenes_and_states())
def test_gradient_and_hessian_match_finite_differences(case):
    scene, q, rng = case
    ev = scene.evaluate(q)
    h = 1e-6 * scene.meridian.size
    v = np.zeros_like(q)
    v[scene.free] = rng.normal(size=scene.n_free)
    # directional derivative of the energy, and K v against a difference of gradients
    slope = (scene.energy(q + h * v) - scene.energy(q - h * v)) / (2 * h)
    scale = np.abs(ev.gradient).max() * np.abs(v).sum() + abs(ev.energy) / scene.meridian.size
    assert abs(slope - ev.gradient @ v) <= 1e-6 * scale
    Kv = (scene.gradient(q + h * v) - scene.gradient(q - h * v))[scene.free] / (2 * h)
    exact = ev.stiffness.matvec(v[scene.free])
    assert np.abs(Kv - exact).max() <= 1e-5 * (np.abs(exact).max() + np.abs(ev.residual).max() / scene.meridian.size)


@settings(max_examples=40, **SETTINGS)
@given(scenes_and_states(), st.floats(-100.0, 100.0))
def test_energy_is_invariant_under_a_z_translation(case, shift):
    scene, q, _ = case
    moved = q.copy()
    moved[1::2] += shift * scene.meridian.size
    a, b = scene.evaluate(q, order=1), scene.evaluate(moved, order=1)
    scale = abs(a.energy) + np.abs(a.gradient).max() * scene.meridian.size
    assert abs(b.energy - a.energy) <= 1e-9 * scale
    np.testing.assert_allclose(b.gradient, a.gradient, rtol=0, atol=1e-9 * np.abs(a.gradient).max())


def check_outcome(scene, eq, options=NewtonOptions()):
    """Converged means the residual there is below tolerance; otherwise a failure status."""
    report = eq.report
    event(f"status: {report.status}")
    assert report.status in STATUSES
    assert np.all(np.isfinite(eq.q))
    if report.converged:
        residual = scene.evaluate(eq.q, eq.loads, order=1).residual
        assert np.abs(residual).max() <= options.tol * scene.force_scale
        assert report.status == "converged"
    else:
        assert report.status != "converged" and report.reason


@settings(max_examples=40, **SETTINGS)
@given(scenes_and_states())
def test_newton_from_a_random_state_converges_or_says_why_not(case):
    scene, q, _ = case
    eq = solve(scene, q0=q, options=NewtonOptions(max_iterations=15))
    check_outcome(scene, eq)


@settings(max_examples=12, **SETTINGS)
@given(st.sampled_from(["plate", "balloon", "torus"]), st.integers(5, 15),
       st.sampled_from(list(LAWS)), st.floats(-0.5, 3.0), st.floats(0.0, 0.6))
def test_equilibrium_from_rest_converges_or_says_why_not(name, nodes, material, p_over_limit, E_hat):
    """Pressures from -0.5 to 3 times a rough limit pressure, voltages to 0.6: some have no answer."""
    limit = {"plate": 0.05, "balloon": 0.014, "torus": 0.04}[name]
    scene = build_scene(name, nodes=nodes, material=material, Jlim=20.0, E_hat=E_hat,
                        pressure=p_over_limit * limit)
    check_outcome(scene, equilibrium(scene))
