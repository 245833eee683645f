"""Contact barriers: derivatives against finite differences over barrier widths 1e-5 to 1e-1,
steps that never cross a gap of zero, contact forces, and the bordered matrix of a rigid body."""

import numpy as np
import pytest

from snapmem.kernels.banded import BandedMatrix
from snapmem.kernels.bordered import BodyMatrix
from snapmem.model.contact import CONTACT_EXAMPLES, Ball, Plane, Rod, Shell, barrier, contact_report
from snapmem.model.meridian import sphere, torus
from snapmem.model.scene import Scene
from snapmem.model.terms import TERMS, PressureWork, Stretching
from snapmem.model.materials import make_law


def test_barrier_derivatives_and_smoothness():
    dhat = 1e-3
    d = np.linspace(1e-6, 2e-3, 997)
    b, b1, b2 = barrier(d, dhat)
    h = 1e-9
    bp, b1p, _ = barrier(d + h, dhat)
    bm, b1m, _ = barrier(d - h, dhat)
    inside = np.abs(d - dhat) > 2 * h
    np.testing.assert_allclose(b1[inside], ((bp - bm) / (2 * h))[inside], rtol=1e-5, atol=1e-12)
    np.testing.assert_allclose(b2[inside], ((b1p - b1m) / (2 * h))[inside], rtol=1e-5, atol=1e-9)
    assert np.all(b[d >= dhat] == 0) and np.all(b1[d >= dhat] == 0) and np.all(b2[d >= dhat] == 0)
    assert np.all(b[d < dhat] > 0) and np.all(b1[d < dhat] < 0)
    assert barrier(np.array([0.0, -1.0]), dhat, 0)[0].tolist() == [np.inf, np.inf]


def test_contact_terms_are_registered():
    for name in ("contact_rod", "contact_shell", "contact_plane", "contact_ball"):
        assert name in TERMS


def _placed(kind, x, dhat):
    """A term of ``kind`` placed so that its nearest node sits at 0.3 dhat and a few more within dhat."""
    r, z = x[:, 0], x[:, 1]
    if kind == "contact_rod":
        return Rod(kappa=2.0, dhat=dhat, radius=r.min() - 0.3 * dhat)
    if kind == "contact_shell":
        return Shell(kappa=2.0, dhat=dhat, radius=r.max() + 0.3 * dhat)
    if kind == "contact_plane":
        return Plane(kappa=2.0, dhat=dhat, z0=z.min() - 0.3 * dhat, nodes=tuple(range(1, len(x) + 1)))
    top = int(np.argmax(z))
    zb = z[top] + 0.5 + 0.3 * dhat
    mass = 2.0 if kind == "contact_ball_body" else None
    return Ball(kappa=2.0, dhat=dhat, radius=0.5, z0=zb, mass=mass, gravity=-10.0)


@pytest.mark.parametrize("dhat", [1e-5, 1e-4, 1e-3, 1e-2, 1e-1])
@pytest.mark.parametrize("kind", list(CONTACT_EXAMPLES))
def test_contact_derivatives_over_barrier_widths(kind, dhat):
    """Gradient and Hessian of each registered contact kind, with a node deep in the barrier."""
    rng = np.random.default_rng(7)
    m = torus(10.0, 2.0, 12) if kind in ("contact_rod", "contact_shell") else sphere(10.0, 11)
    fixed = [1] if m.closed else [0, 1, 2 * (m.nodes - 1)]
    q0 = m.q * 1.1 + rng.normal(scale=0.05, size=m.q.size)
    q0[fixed] = m.q[fixed]
    x = q0.reshape(-1, 2)
    if kind == "contact_plane":          # the plane under a free node, not the fixed south pole
        x = x[1:]
    term = _placed(kind, x, dhat)
    scene = Scene(m, 0.1, [PressureWork(), term], fixed=fixed)
    q = np.concatenate([q0, [b.z0 for b in scene.bodies]])
    ev = scene.evaluate(q)
    assert ev.energy > 0 and np.isfinite(ev.energy)
    h = 1e-3 * 0.3 * dhat
    eye = np.eye(q.size)
    g_fd = np.array([(scene.energy(q + h * e) - scene.energy(q - h * e)) / (2 * h) for e in eye])
    g = ev.gradient
    assert np.max(np.abs(g - g_fd)) <= 1e-5 * np.max(np.abs(g))
    K_fd = np.array([(scene.gradient(q + h * e) - scene.gradient(q - h * e)) / (2 * h) for e in eye]).T
    K_fd = K_fd[np.ix_(scene.free, scene.free)]
    K = ev.stiffness.to_dense()
    assert np.max(np.abs(K - K_fd)) <= 1e-5 * np.max(np.abs(K))
    np.testing.assert_allclose(K, K.T, rtol=0, atol=1e-12 * np.max(np.abs(K)))
    if kind == "contact_ball_body":
        assert isinstance(ev.stiffness, BodyMatrix) and ev.stiffness.n == scene.n_free
        assert np.any(ev.stiffness.border != 0)


@pytest.mark.parametrize("kind", list(CONTACT_EXAMPLES))
def test_max_step_never_crosses_a_gap(kind):
    """Random steps toward the body: the allowed fraction leaves every gap positive, and at most
    1/0.9 of it would reach zero (the step is not cut more than the fraction to the boundary)."""
    rng = np.random.default_rng(3)
    m = torus(10.0, 2.0, 12) if kind in ("contact_rod", "contact_shell") else sphere(10.0, 11)
    x = m.q.reshape(-1, 2) * 1.05
    term = _placed(kind, x[1:] if kind == "contact_plane" else x, 1e-2)
    scene = Scene(m, 0.1, [PressureWork(), term], fixed=[1] if m.closed else [0, 1, 2 * (m.nodes - 1)])
    q = np.concatenate([x.ravel(), [b.z0 for b in scene.bodies]])
    assert scene.inadmissible(q) is None
    for _ in range(50):
        dq = rng.normal(scale=1.0, size=q.size)
        dq[list(scene.fixed)] = 0
        alpha = scene.max_step(q, dq)
        assert 0 < alpha <= 1
        assert scene.inadmissible(q + alpha * dq) is None
        if alpha < 0.9:                   # cut by a gap: going 1/0.9 further reaches it (within 1e-9)
            far = q + alpha / 0.9 * (1 + 1e-9) * dq
            assert scene.inadmissible(far) is not None


def test_contact_force_of_a_pressed_ring_balances_the_pressure():
    """A torus inflated against a rod: the rod's total force equals the pressure force on the
    contact patch only loosely, but Newton's equilibrium has zero residual and positive gaps."""
    from snapmem.solvers.newton import NewtonOptions, solve
    m = torus(0.1, 0.02, 60)
    law = make_law("mooney_rivlin", c1=4.225e5 * 7 / 16, c2=4.225e5 / 16)
    rod = Rod(kappa=1e4, dhat=1e-3, radius=0.0795)
    scene = Scene(m, 1e-4, [Stretching(law), PressureWork(), rod], fixed=[1], loads={"pressure": 0.0})
    eq = solve(scene, {"pressure": 300.0}, q0=m.q, options=NewtonOptions(max_iterations=60))
    assert eq.converged
    report = contact_report(scene, eq.q)
    assert report["rod_gap"] > 0
    assert report["rod_force"] > 0
    # the radial reaction on the rod equals the radial resultant of the membrane on the ring nodes
    x = scene.node_coordinates(eq.q)
    d = x[:, 0] - rod.radius
    assert np.all(d > 0)


def test_bordered_matrix_matches_dense():
    rng = np.random.default_rng(0)
    n, b, k = 30, 3, 2
    A = np.zeros((n, n))
    for d in range(-b, b + 1):
        v = rng.normal(size=n - abs(d))
        A += np.diag(v, d)
    A = A + A.T + np.diag(np.linspace(-3, 20, n))
    B = rng.normal(size=(n, k))
    C = rng.normal(size=(k, k))
    C = C + C.T
    M = BodyMatrix(BandedMatrix.from_dense(A, b), B, C)
    D = M.to_dense()
    assert M.n == n + k
    x = rng.normal(size=n + k)
    np.testing.assert_allclose(M.matvec(x), D @ x, rtol=1e-12, atol=1e-12)
    lu = M.factor()
    np.testing.assert_allclose(lu.solve(D @ x), x, rtol=1e-9, atol=1e-9)
    X = rng.normal(size=(n + k, 3))
    np.testing.assert_allclose(lu.solve(D @ X), X, rtol=1e-9, atol=1e-9)
    ev = np.linalg.eigvalsh(D)
    np.testing.assert_allclose(M.smallest_eigenvalues(3), ev[:3], rtol=1e-10, atol=1e-10)
    assert M.negative_count() == int(np.count_nonzero(ev < 0))


@pytest.mark.parametrize("dhat", [1e-5, 1e-3, 1e-1])
@pytest.mark.parametrize("mass", [None, 2.0])
@pytest.mark.parametrize("dimple", [0.0, 1.5])
def test_ball_edge_distance_derivatives(dhat, mass, dimple):
    """Ball against edges (point-segment distance): a dimpled pole makes the centre project inside
    the pole's edges (the line case); a round pole makes it an end node (the node case)."""
    rng = np.random.default_rng(11)
    m = sphere(10.0, 11)
    fixed = [0, 1, 2 * (m.nodes - 1)]
    q0 = m.q * 1.1 + rng.normal(scale=0.02, size=m.q.size)
    q0[fixed] = m.q[fixed]
    q0[-1] -= dimple                              # lower the north pole: a dimple under the ball
    x = q0.reshape(-1, 2)
    zc = x[:, 1].max() + 0.5
    for _ in range(30):                           # place the ball so the nearest edge is 0.3 dhat away
        d, g, _ = Ball(kappa=2.0, dhat=dhat, radius=0.5, z0=zc, meridian=m).edge_gap(x, np.array([]), 1)
        i = int(np.argmin(d))
        zc -= (d[i] - 0.3 * dhat) / (-1.0 if abs(g[i, 1] + g[i, 3]) < 1e-12 else -(g[i, 1] + g[i, 3]))
    term = Ball(kappa=2.0, dhat=dhat, radius=0.5, z0=zc, mass=mass, gravity=-10.0, meridian=m)
    scene = Scene(m, 0.1, [PressureWork(), term], fixed=fixed)
    q = np.concatenate([q0, [b.z0 for b in scene.bodies]])
    gaps = term.gaps(scene.node_coordinates(q), q[scene.n_node_dofs:])
    assert gaps.min() == pytest.approx(0.3 * dhat, rel=1e-3)
    e = m.edges[int(np.argmin(gaps))]                 # where the centre projects on the nearest edge
    a, b = x[e[0]], x[e[1]]
    t = np.dot(np.array([0.0, zc]) - a, b - a) / np.dot(b - a, b - a)
    assert (0 < t < 1) == (dimple > 0)
    ev = scene.evaluate(q)
    assert ev.energy > 0 and np.isfinite(ev.energy)
    h = 1e-3 * 0.3 * dhat
    eye = np.eye(q.size)
    g_fd = np.array([(scene.energy(q + h * e) - scene.energy(q - h * e)) / (2 * h) for e in eye])
    assert np.max(np.abs(ev.gradient - g_fd)) <= 1e-5 * np.max(np.abs(ev.gradient))
    K_fd = np.array([(scene.gradient(q + h * e) - scene.gradient(q - h * e)) / (2 * h) for e in eye]).T
    K = ev.stiffness.to_dense()
    assert np.max(np.abs(K - K_fd[np.ix_(scene.free, scene.free)])) <= 1e-5 * np.max(np.abs(K))


def test_a_long_edge_cannot_pass_through_the_ball():
    """Two nodes either side of the ball: node gaps are positive, the edge between them is not."""
    m = sphere(10.0, 11)
    x = m.q.reshape(-1, 2).copy()
    ball_nodes = Ball(kappa=1.0, dhat=0.1, radius=1.0, z0=0.0)
    ball_edges = Ball(kappa=1.0, dhat=0.1, radius=1.0, z0=0.0, meridian=m)
    x[5] = (3.0, 0.0)
    x[4], x[6] = (0.5, -2.0), (0.5, 2.0)          # edges 4-5 and 5-6 fine; now make one cross the ball
    x[3] = (0.2, -5.0)
    x[4] = (0.3, 5.0)                             # edge 3-4 runs along the axis through the ball
    assert ball_nodes.admissible(x, np.array([])) is None
    assert "edge 3" in ball_edges.admissible(x, np.array([]))


@pytest.mark.parametrize("mass", [None, 0.5])
def test_compiled_ball_edge_barrier_matches_the_numpy_edge_gaps(mass):
    """snapmem.kernels.contact.ball_edge_barrier against Ball.edge_gap (numpy) and barrier(), on a
    dimpled cap where the centre projects inside edges (line case) and onto nodes (end case)."""
    from scipy.optimize import brentq

    from snapmem.kernels.contact import ball_edge_barrier, ball_edge_gaps
    m = sphere(0.1, 41)
    x = m.q.reshape(-1, 2).copy()
    x[:, 1] -= 0.02 * np.exp(-(x[:, 0] / 0.06) ** 2)            # a dimple under the ball
    for dhat in (1e-3, 1e-2, 3e-2):                              # the nearest edge 0.3 dhat away
        zc = brentq(lambda z: ball_edge_gaps(x, m.edges, z, 0.05).min() - 0.3 * dhat, 0.1, 0.3, xtol=1e-14)
        ball = Ball(kappa=1e4, dhat=dhat, radius=0.05, z0=zc, mass=mass, gravity=-10.0, meridian=m)
        y = np.array([zc])
        d, g, h = ball.edge_gap(x, y, 2)
        np.testing.assert_allclose(ball_edge_gaps(x, m.edges, zc, 0.05), d, rtol=0, atol=1e-15)
        coef = ball.kappa * ball._edge_area / dhat
        energy, which, grad, hess = ball_edge_barrier(x, m.edges, zc, 0.05, dhat, coef, mass is not None, 2)
        np.testing.assert_array_equal(which, np.flatnonzero(d < dhat))
        a, b = x[m.edges[which, 0]], x[m.edges[which, 1]]
        t = np.einsum("ij,ij->i", np.stack([-a[:, 0], zc - a[:, 1]], 1), b - a) / np.einsum("ij,ij->i", b - a, b - a)
        assert np.any((t > 0) & (t < 1)) and np.any(t >= 1)          # both the line and the end case
        c = coef[which]
        b0, b1, b2 = barrier(d[which], dhat)
        assert energy == pytest.approx(float(c @ b0), rel=1e-13)
        np.testing.assert_allclose(grad, (c * b1)[:, None] * g[which], rtol=1e-12, atol=1e-12 * np.abs(grad).max())
        ref = ((c * b2)[:, None, None] * g[which][:, :, None] * g[which][:, None, :]
               + (c * b1)[:, None, None] * h[which]).transpose(1, 2, 0)
        np.testing.assert_allclose(hess, ref, rtol=1e-12, atol=1e-12 * np.abs(ref).max())
