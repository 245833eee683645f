"""Every registered law and term: gradient and Hessian against central differences, Hessian
symmetry and Taylor remainders of slope 2, on random perturbed states of all three shapes."""

import numpy as np
import pytest

from snapmem.model.materials import LAWS, Gent, Law, make_law
from snapmem.model.parameters import Parameter
from snapmem.model.scene import Scene
from snapmem.model.terms import TERMS, Stretching

from conftest import SHAPES, perturbed

H = 0.2
LOADS = {"pressure": 0.03, "voltage": 0.07}


def scene_with(shape, terms):
    make, fixed = SHAPES[shape]
    m = make()
    return Scene(m, H, terms, fixed=fixed(m.nodes), loads={k: v for k, v in LOADS.items()
                                                             if any(k in t.loads for t in terms)})


def fd_gradient(scene, q, h):
    return np.array([(scene.energy(q + h * e) - scene.energy(q - h * e)) / (2 * h) for e in np.eye(q.size)])


def fd_hessian(scene, q, h):
    cols = [(scene.gradient(q + h * e) - scene.gradient(q - h * e)) / (2 * h) for e in np.eye(q.size)]
    return np.array(cols).T[np.ix_(scene.free, scene.free)]


def check_derivatives(scene, q):
    h = 1e-6 * scene.meridian.size
    ev = scene.evaluate(q)
    g_fd = fd_gradient(scene, q, h)
    assert np.max(np.abs(ev.gradient - g_fd)) <= 1e-6 * np.max(np.abs(ev.gradient))
    K = ev.stiffness.to_dense()
    K_fd = fd_hessian(scene, q, h)
    assert np.max(np.abs(K - K_fd)) <= 1e-6 * np.max(np.abs(K))
    np.testing.assert_allclose(K, K.T, rtol=0, atol=1e-13 * np.max(np.abs(K)))


def taylor_slopes(scene, q, rng):
    """Slopes of |E(q+tv)-E-t g.v| and |g(q+tv)-g-t K v| against t (both should be 2)."""
    v = np.zeros_like(q)
    v[scene.free] = rng.normal(size=scene.free.size) * 0.01 * scene.meridian.size
    ev = scene.evaluate(q)
    Kv = ev.stiffness.matvec(v[scene.free])
    ts = np.logspace(-1, -4, 4)
    r1 = [abs(scene.energy(q + t * v) - ev.energy - t * ev.gradient @ v) for t in ts]
    r2 = [np.linalg.norm(scene.evaluate(q + t * v, order=1).residual - ev.residual - t * Kv) for t in ts]
    return np.polyfit(np.log(ts), np.log(r1), 1)[0], np.polyfit(np.log(ts), np.log(r2), 1)[0]


def check_law(law, shape, rng):
    """A law's stretching energy on a perturbed state of ``shape``: gradient and Hessian against
    central differences, Taylor remainders of slope 2 (also used on laws defined by the tests)."""
    scene = scene_with(shape, [Stretching(law)])
    q = perturbed(scene.meridian, list(scene.fixed), rng, stretch=1.2)
    check_derivatives(scene, q)
    s1, s2 = taylor_slopes(scene, q, rng)
    assert 1.9 < s1 < 2.1 and 1.9 < s2 < 2.1


@pytest.mark.parametrize("shape", list(SHAPES))
@pytest.mark.parametrize("law", list(LAWS))
def test_every_law_matches_finite_differences(shape, law, rng):
    check_law(LAWS[law][0].example(), shape, rng)


@pytest.mark.parametrize("shape", list(SHAPES))
@pytest.mark.parametrize("term", list(TERMS))
def test_every_term_matches_finite_differences(shape, term, rng):
    scene = scene_with(shape, [Stretching(make_law("neo_hookean", mu=1.0)), TERMS[term](H)])
    q = perturbed(scene.meridian, list(scene.fixed), rng)
    check_derivatives(scene, q)
    s1, s2 = taylor_slopes(scene, q, rng)
    assert 1.9 < s1 < 2.1 and 1.9 < s2 < 2.1


@pytest.mark.parametrize("term", list(TERMS))
def test_load_derivative_matches_finite_differences(term, rng):
    scene = scene_with("torus", [Stretching(make_law("neo_hookean", mu=1.0)), TERMS[term](H)])
    q = perturbed(scene.meridian, list(scene.fixed), rng)
    for name in TERMS[term](H).loads:
        dl = 1e-6
        up = scene.evaluate(q, {name: LOADS[name] + dl}, order=1).residual
        down = scene.evaluate(q, {name: LOADS[name] - dl}, order=1).residual
        exact = scene.load_derivative(q, name)
        np.testing.assert_allclose(exact, (up - down) / (2 * dl), rtol=0, atol=1e-7 * np.max(np.abs(exact)))


@pytest.mark.parametrize("gap", [1e-1, 1e-2, 1e-3, 1e-4])
def test_gent_near_its_lock(gap, rng):
    """Equibiaxial stretch chosen so that I1 - 3 = Jlim (1 - gap): derivatives still exact."""
    Jlim = 5.0
    target = 3 + Jlim * (1 - gap)
    lam = np.sqrt(np.roots([2, -target, 0, 1]).real.max())      # 2 lam^2 + lam^-4 = I1
    scene = scene_with("sphere", [Stretching(Gent(1.0, Jlim))])
    q = scene.meridian.q * lam
    check_derivatives_gent = scene.evaluate(q)
    assert np.isfinite(check_derivatives_gent.energy)
    h = 1e-4 * gap * scene.meridian.size / lam
    g_fd = fd_gradient(scene, q, h)
    g = check_derivatives_gent.gradient
    assert np.max(np.abs(g - g_fd)) <= 1e-6 * np.max(np.abs(g))
    K_fd = fd_hessian(scene, q, h)
    K = check_derivatives_gent.stiffness.to_dense()
    assert np.max(np.abs(K - K_fd)) <= 1e-5 * np.max(np.abs(K))


def check_declaration(cls):
    """A law class declares documented parameters its constructor takes, defaults and an example
    within their ranges, and a positive shear modulus."""
    assert issubclass(cls, Law) and cls.parameters
    for p in cls.parameters:
        assert isinstance(p, Parameter) and p.doc and p.kind in (float, int)
    names = [p.name for p in cls.parameters]
    assert len(set(names)) == len(names)
    for law in (cls.from_parameters(), cls.example()):
        assert type(law) is cls and law.mu > 0
        values = {name: getattr(law, name) for name in names}
        assert all(p.check(values[p.name]) == values[p.name] for p in cls.parameters)
        assert cls.from_parameters(**values) == law
        rescaled = cls.from_parameters(**cls.with_modulus(values, 3.0 * law.mu))
        assert rescaled.mu == pytest.approx(3.0 * law.mu, rel=1e-14)


@pytest.mark.parametrize("law", list(LAWS))
def test_every_law_declares_its_parameters_and_an_example(law):
    check_declaration(LAWS[law][0])
    assert LAWS[law][1] == tuple(p.name for p in LAWS[law][0].parameters)


@pytest.mark.parametrize("name,extra", [("balloon", {"E_hat": 0.2}), ("torus", {}),
                                        ("plate", {"material": "gent", "Jlim": 20.0}),
                                        ("balloon", {"material": "yeoh", "c2": -0.01, "c3": 0.002})])
def test_compiled_assembly_matches_the_numpy_reference(name, extra, rng):
    """The compiled kernels (snapmem.kernels) against the numpy expressions they fuse."""
    from snapmem import build_scene
    scene = build_scene(name, nodes=41, pressure=0.013, **extra)
    assert scene._compilable
    q = scene.reference_state() * 1.2
    q[scene.free] += rng.normal(scale=0.05, size=scene.n_free)
    assert_compiled_matches_numpy(scene, q, 1e-13)


def assert_compiled_matches_numpy(scene, q, tol):
    """The scene's energy, gradient and stiffness at q by the compiled kernels and by numpy."""
    import snapmem
    fast = scene.evaluate(q)
    scene._kinematics_cache = None
    with snapmem.reference_path():
        slow = scene.evaluate(q)
    assert fast.energy == pytest.approx(slow.energy, rel=1e-13)
    np.testing.assert_allclose(fast.gradient, slow.gradient, rtol=0, atol=tol * np.abs(slow.gradient).max())
    K1, K2 = fast.stiffness.to_dense(), slow.stiffness.to_dense()
    np.testing.assert_allclose(K1, K2, rtol=0, atol=tol * np.abs(K2).max())


@pytest.mark.parametrize("law", list(LAWS))
def test_laws_take_scalars_and_arrays_alike(law):
    """Scalars (as an ODE solver passes them) take the numpy path, arrays the compiled one."""
    model = LAWS[law][0].example()
    arrays = model.density(np.array([1.3, 1.1]), np.array([1.2, 0.9]))
    scalar = model.density(1.3, 1.2)
    for name in ("w", "w1", "w2", "w11", "w12", "w22"):
        assert float(getattr(scalar, name)) == pytest.approx(float(getattr(arrays, name)[0]), rel=1e-13)


@pytest.mark.parametrize("name,t_end", [("ball_drop", 0.3), ("gripper_rod", 18.0)])
def test_compiled_assembly_matches_the_numpy_reference_with_contact(name, t_end):
    """Scenes with node terms and a rigid body: the compiled membrane plus the node terms against the
    numpy membrane plus the same node terms, at a state in contact (ball pressing; torus on its rod)."""
    from snapmem.model.contact import contact_report
    from snapmem.catalog.robots import experiment, run
    scene = experiment(name, nodes=31).scene
    q = run(name, nodes=31, t_end=t_end).final_q
    assert any(v > 0 for k, v in contact_report(scene, q).items() if k.endswith("_force"))
    assert_compiled_matches_numpy(scene, q, 1e-12)
