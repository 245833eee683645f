"""Loss of ellipticity and loss of tension: the local conditions against a brute-force rank-one
convexity test of the membrane energy W(F), and as events of a trace (MODEL.md section 7)."""

from types import SimpleNamespace

import numpy as np
import pytest

from snapmem.continuation import trace
from snapmem.continuation.branch import Outcome, PointKind
from snapmem.model.local_checks import ellipticity_margins, local_state
from snapmem.model.materials import make_law
from snapmem.model.terms import Electric
from snapmem.reference.exact import sphere_bifurcation_stretches, sphere_ellipticity_loss
from snapmem.scenes import build_scene

C1, C2 = 0.4375, 0.0625          # mu = 1


def _density(l1, l2, e_hat):
    """W_eff of Mooney-Rivlin 1/7 with the electric term, through snapmem's own law and term."""
    kin = SimpleNamespace(lam1=np.atleast_1d(np.asarray(l1, float)), lam2=np.atleast_1d(np.asarray(l2, float)))
    return (make_law("mooney_rivlin", c1=C1, c2=C2).density(kin.lam1, kin.lam2)
            + Electric(1.0, 1.0).density(kin, {"voltage": e_hat}))     # eps = H = 1, mu = 1: phi = E_hat


def _w_of_F(F, e_hat):
    """W_eff of a 3x2 tangent map F: its singular values are the principal stretches."""
    s = np.linalg.svd(F, compute_uv=False)
    return float(_density(s[0], s[1], e_hat).w[0])


def _min_rank_one_curvature(l1, l2, e_hat, h=1e-4):
    """min over unit a in R^3, N in R^2 of d2/de2 W(F + e a N^T) (central differences), F = diag."""
    F = np.zeros((3, 2))
    F[0, 0], F[1, 1] = l1, l2
    w0 = _w_of_F(F, e_hat)
    worst = np.inf
    for theta in np.linspace(0, np.pi, 13):
        N = np.array([np.cos(theta), np.sin(theta)])
        for u in np.linspace(0, np.pi, 9):
            for v in np.linspace(0, 2 * np.pi, 12, endpoint=False):
                a = np.array([np.sin(u) * np.cos(v), np.sin(u) * np.sin(v), np.cos(u)])
                d = np.outer(a, N)
                worst = min(worst, (_w_of_F(F + h * d, e_hat) - 2 * w0 + _w_of_F(F - h * d, e_hat)) / h ** 2)
    return worst


@pytest.mark.parametrize("l1, l2, e_hat", [(1.3, 1.1, 0.0), (2.0, 2.3, 0.5), (2.9, 2.6, 0.5), (1.6, 2.8, 0.45),
                                           (3.0, 1.2, 0.3), (2.5, 2.5 * (1 + 1e-8), 0.5), (2.8, 2.8, 0.5),
                                           (1.1, 0.85, 0.0)])
def test_conditions_agree_with_rank_one_convexity(l1, l2, e_hat):
    """The five in-plane conditions and the two tensions decide strong ellipticity exactly as the
    minimum second derivative of W(F) along every rank-one direction does."""
    dens = _density(l1, l2, e_hat)
    margin = float(ellipticity_margins(np.array([l1]), np.array([l2]), dens, 1.0)[0])
    tension = min(dens.w1[0] / l1, dens.w2[0] / l2)
    brute = _min_rank_one_curvature(l1, l2, e_hat)
    assert abs(margin) > 1e-3 and abs(brute) > 1e-3          # the cases are not on the boundary
    assert (margin > 0 and tension > 0) == (brute > 0)


def test_equibiaxial_loss_is_the_large_n_limit_of_the_criterion():
    """On the sphere ellipticity is lost where W11 = 0 (2.668 at E_hat = 0.5), which the P_n
    roots approach as n grows, and the margins change sign there."""
    lam_le = sphere_ellipticity_loss(E_hat=0.5)
    assert lam_le == pytest.approx(2.6679, abs=5e-4)
    lam = np.array([lam_le * (1 - 1e-6), lam_le * (1 + 1e-6)])
    margins = ellipticity_margins(lam, lam, _density(lam, lam, 0.5), 1.0)
    assert margins[0] > 0 > margins[1]
    gaps = np.array([lam_le - sphere_bifurcation_stretches(n, E_hat=0.5, lam_max=lam_le)[-1] for n in (10, 20, 40, 80)])
    assert np.all(gaps > 0) and np.all(np.diff(gaps) < 0) and gaps[-1] < 0.25 * gaps[0]


def test_high_voltage_balloon_ends_at_loss_of_ellipticity():
    """MR 1/7 at E_hat = 0.5: the trace stops at loss of ellipticity near stretch 2.668, says so,
    and reports nothing past it."""
    scene = build_scene("balloon", nodes=41, E_hat=0.5)
    branch = trace(scene, "pressure", until={"stretch": 4.0})
    assert branch.outcome is Outcome.ELLIPTICITY_LOST
    assert "loss of ellipticity" in branch.status and "ill-posed" in branch.status
    last = branch.states[-1]
    assert last.kind is PointKind.LE and last.located
    assert branch.points["kind"].iloc[-1] == "LE"
    assert branch.points["s"].max() == pytest.approx(last.s) and branch.table["s"].max() == pytest.approx(last.s)
    check = local_state(scene, make_state(branch, last), None)
    assert abs(check.ellipticity) < 1e-8
    assert check.stretch == pytest.approx(sphere_ellipticity_loss(E_hat=0.5), rel=0.01)


def make_state(branch, point):
    from snapmem.continuation.problems import make_problem
    return make_problem(branch.scene, branch.control).state(point.x, point.lam)[0]


def test_loss_of_tension_is_recorded_and_the_trace_goes_on():
    """The plate under voltage wrinkles (a principal tension reaches zero) before it loses
    ellipticity: the point is located (kind LT, zero tension) and the trace continues past it."""
    scene = build_scene("plate", ("voltage",), nodes=31, pressure=0.01)
    branch = trace(scene, "voltage", until={"voltage": 1.5})
    kinds = list(branch.points["kind"])
    assert "LT" in kinds
    lt = branch.points[branch.points["kind"] == "LT"].iloc[0]
    assert abs(lt["min_tension"]) <= 1e-9 * scene.mu * scene.thickness
    assert branch.table["s"].max() > lt["s"]                  # went on
    assert branch.outcome is Outcome.ELLIPTICITY_LOST        # and stopped later, where the model fails
