"""Critical points classified by the turning of the parameter, their Legendre modes, the sphere's
bifurcation criterion, and branch switching at BPs (issue 16, items 1 and 2)."""

import numpy as np
import pytest
from numpy.polynomial import legendre

from snapmem.catalog.scenes import build_scene, get_spec
from snapmem.continuation import Diagram, read_diagram, trace
from snapmem.continuation.modes import legendre_mode
from snapmem.reference.exact import balloon_extrema, balloon_pressure, sphere_bifurcation_stretches


@pytest.fixture(scope="module")
def e_balloon():
    scene = get_spec("balloon").build(("pressure",), E_hat=0.4, nodes=51)
    return trace(scene, "pressure", until={"stretch": 3.2})


def test_criterion_recovers_the_pressure_extrema_and_the_known_roots():
    assert np.allclose(sphere_bifurcation_stretches(0), [lam for lam, _ in balloon_extrema()], rtol=1e-9)
    assert sphere_bifurcation_stretches(1) == [] and sphere_bifurcation_stretches(2) == []
    assert sphere_bifurcation_stretches(1, E_hat=0.4)[0] == pytest.approx(1.7725, abs=1e-4)
    assert sphere_bifurcation_stretches(2, E_hat=0.4)[0] == pytest.approx(2.9152, abs=1e-4)


def test_legendre_mode_of_pure_modes():
    scene = get_spec("balloon").build(nodes=81)
    m = scene.meridian
    theta = np.arccos(m.z / 10.0)
    for n in range(2, 7):
        u_n = legendre.legval(np.cos(theta), np.eye(n + 1)[n])
        phi = np.zeros(m.q.size)
        phi[0::2], phi[1::2] = u_n * np.sin(theta), u_n * np.cos(theta) + 0.3   # + a rigid translation
        assert legendre_mode(scene, phi) == n
    assert legendre_mode(get_spec("torus").build(nodes=40), np.ones(80)) == -1


def test_balloon_at_E_hat_0_has_two_limit_points_and_no_bp():
    branch = trace(get_spec("balloon").build(nodes=41), "pressure", until={"stretch": 10.0})
    assert list(branch.points["kind"]) == ["LP", "LP"]
    assert np.allclose(branch.points["stretch"], [1.53519, 2.59398], atol=5e-3)


def test_e_balloon_points_are_classified_by_turning(e_balloon):
    pts = e_balloon.points
    assert list(pts["kind"]) == ["LP", "BP", "BP"]
    assert list(pts["mode"]) == [-1, 1, 2]
    assert list(pts["crossed"]) == [1, 1, 1]
    # the P1 BP is exact on the up-down symmetric mesh; P2 couples to the load at mesh order
    assert pts["coupling"].iloc[1] < 1e-6 and not pts["symmetry_broken"].iloc[1]
    assert pts["symmetry_broken"].iloc[2]
    assert pts["stretch"].iloc[1] == pytest.approx(1.7725, abs=2e-3)
    # reported at the perfect problem's BP (the unfolding), not at the mesh's fold O(h) away
    assert pts["stretch"].iloc[2] == pytest.approx(2.9152, abs=5e-3)
    assert 0 < pts["imperfection"].iloc[2] < 1e-3 and np.isnan(pts["imperfection"].iloc[:2]).all()


def test_pear_bp_converges_at_second_order():
    """The P2 BP at E_hat = 0.4: the mesh's critical point (a fold of an imperfect transcritical
    bifurcation) converges as N^-1; the unfolded BP as N^-2 to the criterion's root, and the
    imperfection falls as N^-2."""
    root = sphere_bifurcation_stretches(2, E_hat=0.4)[0]
    errors, imperfections = [], []
    for n in (51, 101, 201):
        scene = get_spec("balloon").build(("pressure",), E_hat=0.4, nodes=n)
        bp = trace(scene, "pressure", until={"stretch": 3.0}).points.iloc[-1]
        assert bp["kind"] == "BP" and bp["mode"] == 2 and bp["symmetry_broken"]
        errors.append(bp["stretch"] - root)
        imperfections.append(bp["imperfection"])
    orders = np.log2(np.abs(errors[:-1]) / np.abs(errors[1:]))
    assert np.all((orders > 1.9) & (orders < 2.1)), orders
    assert np.all(np.log2(np.array(imperfections[:-1]) / imperfections[1:]) > 1.8)


def test_trace_passes_through_an_imperfect_bp_where_the_mesh_branch_turns():
    """With the free support at N = 101 the mesh's uniform branch turns back at the P2 point
    (onto the pear branch): the trace takes it as the imperfect BP it is and goes on along the
    uniform branch to the P3 BP, instead of wandering on the pear branch."""
    scene = get_spec("balloon").build(("pressure",), E_hat=0.4, nodes=101, support="free")
    branch = trace(scene, "pressure", until={"stretch": 3.7})
    pts = branch.points
    assert branch.outcome.value == "target_reached"
    assert list(pts["kind"]) == ["LP", "BP", "BP", "BP"] and list(pts["mode"]) == [-1, 1, 2, 3]
    assert pts["stretch"].iloc[2] == pytest.approx(2.9152, abs=2e-3)
    assert pts["stretch"].iloc[3] == pytest.approx(sphere_bifurcation_stretches(3, E_hat=0.4)[0], abs=3e-3)
    # on the uniform branch beyond it: the exact pressure of the sphere at the end
    end = branch.table.iloc[-1]
    assert end["pressure"] == pytest.approx(balloon_pressure(end["stretch"], E_hat=0.4), rel=5e-3)


def test_plate_under_voltage_has_no_limit_point():
    scene = get_spec("plate").build(("voltage",), nodes=31)
    branch = trace(scene, "voltage", until={"voltage": 1.2})
    assert np.all(np.diff(branch.table["voltage"]) >= 0)            # the voltage only rises
    assert len(branch.points) >= 1 and (branch.points["kind"] != "LP").all()


def _shape_deviation(branch, p):
    q = branch.scene_state(p)
    r, z = q[0::2], q[1::2]
    rho = np.hypot(r, z - 0.5 * (z[0] + z[-1]))
    return (rho.max() - rho.min()) / rho.mean()


def test_switching_at_the_pear_bp_lands_on_a_non_spherical_branch(e_balloon, tmp_path):
    diagram = e_balloon.switch(2, until={"stretch_max": 3.5})
    assert isinstance(diagram, Diagram) and len(diagram.branches) == 3
    p_bp = e_balloon.points["pressure"].iloc[2]
    uniform = max(_shape_deviation(e_balloon, p) for p in e_balloon.states if p.s < e_balloon.points["s"].iloc[2])
    deviations = []
    for child in diagram.branches[1:]:
        assert child.states[0].lam == pytest.approx(p_bp, rel=0.05)
        for p in child.states:
            q = child.scene_state(p)
            residual = child.scene.evaluate(q, {**child.scene.loads, "pressure": p.lam}, 1).residual
            assert np.max(np.abs(residual)) < 1e-8 * child.scene.force_scale
        deviations.append(max(_shape_deviation(child, p) for p in child.states))
    assert max(deviations) > 10 * uniform                     # a pear, far beyond the mesh's error
    diagram.save(tmp_path / "d.csv")
    back = read_diagram(tmp_path / "d.csv")
    assert sorted(back.table["branch"].unique()) == [0, 1, 2]
    assert [(c.parent, c.row, c.child) for c in back.connections] == [(0, 2, 1), (0, 2, 2)]
    assert np.allclose(back.states["b1_lam"], [p.lam for p in diagram.branches[1].states])


def test_switching_at_the_p1_pitchfork_gives_mirror_halves(e_balloon):
    diagram = e_balloon.switch(1, until={"stretch_max": 2.2})
    (plus, minus) = diagram.branches[1:]
    a, b, c = (plus.stats["switch"][k] for k in "abc")
    assert abs(a) < 1e-5 * (abs(b) + abs(c))                 # a pitchfork: phi . D2F[u, u] = 0 by symmetry
    for half in (plus, minus):
        assert half.states[0].lam == pytest.approx(e_balloon.points["pressure"].iloc[1], rel=1e-3)
    # the mirror image (reflection + translation) of one half is the other: same pressures at the end
    assert plus.table["pressure"].iloc[-1] == pytest.approx(minus.table["pressure"].iloc[-1], rel=1e-6)
    assert max(_shape_deviation(plus, p) for p in plus.states) > 1e-2


def test_balloon_bifurcations_study(tmp_path):
    import importlib.util
    from pathlib import Path
    import pandas as pd
    path = Path(__file__).resolve().parents[1] / "studies" / "balloon_bifurcations.py"
    spec = importlib.util.spec_from_file_location("balloon_bifurcations", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    module.main(["--quick", "--out", str(tmp_path)])
    t = pd.read_csv(tmp_path / "balloon_bifurcations.csv")
    pear = t[(t["mode"] == 2) & (t["nodes"] == 201)].iloc[0]
    assert 1.9 < pear["observed_order"] < 2.1 and abs(pear["error"]) < 3e-4
    assert pear["criterion_stretch"] == pytest.approx(2.91518, abs=1e-5)
    assert (tmp_path / "balloon_bifurcations.png").exists()


class _Transcritical:
    """Pi = x1^3/3 - lam x1^2/2 + eps x1 + x2^2/2 - eps2 x2 + gamma x1^2 x2: a transcritical
    bifurcation at lam = 2 gamma x2 on x1 = 0 when eps = 0; eps is its imperfection."""

    lam_scale = 1.0
    x_weight = np.ones(2)
    control = "lam"

    def __init__(self, eps=0.0, eps2=0.0, gamma=0.3):
        self.eps, self.eps2, self.gamma = eps, eps2, gamma

    def evaluate(self, x, lam, order=2, with_floor=False):
        from snapmem.kernels.banded import BandedMatrix
        x1, x2 = x
        g = self.gamma
        F = np.array([x1 * x1 - lam * x1 + self.eps + 2 * g * x1 * x2, x2 - self.eps2 + g * x1 * x1])
        K = BandedMatrix.from_dense(np.array([[2 * x1 - lam + 2 * g * x2, 2 * g * x1], [2 * g * x1, 1.0]]), 1)
        return F, K

    def dF_dlam(self, x, lam):
        return np.array([-x[0], 0.0])

    def inadmissible(self, x, lam):
        return None

    def stiffness(self, J):
        return J


_TOY_SCENE = type("ToyScene", (), {"force_scale": 1.0, "meridian": type("M", (), {"size": 1.0})()})()


def test_unfolding_finds_the_perfect_transcritical_point():
    """From near the fold of the imperfect problem (x1 = sqrt(eps), lam = 2 sqrt(eps) for
    gamma = 0), the unfolding returns the perfect BP: sigma psi cancels the imperfection along
    psi, and the BP sits where the trivial branch x1 = 0 of the perfect problem loses stability."""
    from snapmem.continuation.unfold import unfold_bifurcation
    eps, eps2, gamma = 1e-4, 0.02, 0.3
    pb = _Transcritical(eps, eps2, gamma)
    x0, lam0 = np.array([np.sqrt(eps), eps2]), 2 * np.sqrt(eps) + 2 * gamma * eps2
    K = pb.evaluate(x0, lam0)[1].to_dense()
    psi = np.linalg.eigh(K)[1][:, 0]
    x, lam, sigma, v = unfold_bifurcation(pb, _TOY_SCENE, x0, lam0, psi)
    psi = psi / np.linalg.norm(psi)
    sigma_exact = -eps / psi[0]
    x2 = eps2 - sigma_exact * psi[1]
    assert sigma == pytest.approx(sigma_exact, rel=1e-6)            # the residual tolerance is 1e-10
    assert abs(x[0]) < 1e-8 and x[1] == pytest.approx(x2, rel=1e-8)
    assert lam == pytest.approx(2 * gamma * x2, rel=1e-6)             # the mesh fold was 2 sqrt(eps) away
    assert abs(v @ pb.dF_dlam(x, lam)) < 1e-12


def test_switching_direction_at_a_transcritical_point():
    """Keller's equation at the perfect transcritical point: a = 2, b = -1, c = 0; the new
    branch leaves along x1 = lam (direction (1, 0, 1)), not along the null vector alone."""
    from snapmem.continuation.branch import Point
    from snapmem.continuation.options import ContinuationOptions
    from snapmem.continuation.switching import bifurcation_direction
    from snapmem.continuation.tracer import Tracer
    pb = _Transcritical()
    tracer = Tracer(pb, ContinuationOptions(), _TOY_SCENE)
    # at lam = 0 K is exactly singular and the band LU of the bordered solve stops: just beside it
    c = Point(np.zeros(2), 1e-9, tangent=np.array([0.0, 0.0, 1.0]))
    d, (a, b, cc), fold = bifurcation_direction(tracer, c, np.array([1.0, 0.0]))
    assert not fold
    assert a == pytest.approx(2.0, rel=1e-6) and b == pytest.approx(-1.0, rel=1e-6) and abs(cc) < 1e-8
    assert np.allclose(np.abs(d), [2 ** -0.5, 0.0, 2 ** -0.5], atol=1e-6) and d[0] * d[2] > 0


def test_a_slack_start_locates_no_critical_point_from_its_rounding_eigenvalue():
    """The voltage-loaded torus at p = 0 carries no tension, so K at the start is singular and its
    eigenvalue nearest zero is rounding: -1.8e-10 at E_hat = 0.1538, N = 200 (+6e-11 at the other
    E_hat of Fig. 5a). Its sign used to count as an unstable start and put a BP at p = 4.7e-12.
    The start's inertia is undetermined (negative_eigs -1); the first critical point is the LP."""
    scene = build_scene("torus", nodes=200, E_hat=0.1538, with_loads=("voltage",))
    branch = trace(scene, "pressure", until={"u_max": 10.0})
    table = branch.table
    assert table["negative_eigs"].iloc[0] == -1 and table["negative_eigs"].iloc[1] == 0
    kinds = table.loc[table["point"] != "", "point"].tolist()
    assert kinds[0] == "LP"
    assert abs(table.loc[table["point"] == "LP", "pressure"].iloc[0] - 0.0391602) < 1e-6
