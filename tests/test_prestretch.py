"""Prestretch (issue 15): a membrane mounted at prestretch lp is the stress-free one of the mounted
shape divided by lp, thickness H lp^2, seen from its mounted state."""

import numpy as np
import pytest

from snapmem.catalog.registry import build_scene
from snapmem.continuation import trace
from snapmem.model.local_checks import local_state
from snapmem.model.materials import Gent, MooneyRivlin
from snapmem.model.prestretch import Prestretched
from snapmem.reference.exact import balloon_limit_point, balloon_pressure

R, H = 10.0, 0.1


def test_prestretched_density_is_the_chain_rule_of_the_law():
    """Central differences of W(lp1 lam1, lp2 lam2), unequal prestretches, near Gent's lock."""
    law = Prestretched(Gent(mu=1.0, Jlim=20.0), 1.3, 0.8)
    lam1, lam2 = np.array([0.9, 1.4, 2.2]), np.array([1.1, 1.7, 2.4])
    d, h = law.density(lam1, lam2), 1e-6
    for first, (a, b) in (("w1", (h, 0)), ("w2", (0, h))):
        up, down = law.density(lam1 + a, lam2 + b), law.density(lam1 - a, lam2 - b)
        np.testing.assert_allclose(getattr(d, first), (up.w - down.w) / (2 * h), rtol=1e-7)
        second = ("w11", "w12") if first == "w1" else ("w12", "w22")
        np.testing.assert_allclose(getattr(d, second[0]), (up.w1 - down.w1) / (2 * h), rtol=1e-6)
        np.testing.assert_allclose(getattr(d, second[1]), (up.w2 - down.w2) / (2 * h), rtol=1e-6)
    base = Gent(mu=1.0, Jlim=20.0)
    assert np.array_equal(law.admissible(np.array([3.2, 3.6]), np.array([1.0, 1.0])),
                          base.admissible(np.array([1.3 * 3.2, 1.3 * 3.6]), np.array([0.8, 0.8])))


def test_prestretch_one_is_the_stress_free_scene():
    a, b = build_scene("plate", nodes=11, E_hat=0.1), build_scene("plate", nodes=11, E_hat=0.1, prestretch=1.0)
    assert type(a.terms[0].law) is type(b.terms[0].law) is MooneyRivlin


@pytest.mark.parametrize("prestretch", [1.5, 2.0])
def test_mounted_balloon_is_the_smaller_thicker_stress_free_one(prestretch):
    """Same state q, same voltage: the residual, the stiffness and the local checks of the balloon of
    radius R mounted at lp equal those of the stress-free balloon of radius R/lp, thickness H lp^2."""
    lp, phi = prestretch, 0.02
    mounted = build_scene("balloon", nodes=21, R=R, H=H, prestretch=lp, voltage=phi)
    free = build_scene("balloon", nodes=21, R=R / lp, H=H * lp ** 2, voltage=phi)
    q = mounted.meridian.q * 1.2
    q[1::2] *= 1.1                                    # not uniform
    a, b = mounted.evaluate(q), free.evaluate(q)
    scale = np.abs(b.residual).max()
    np.testing.assert_allclose(a.residual, b.residual, atol=1e-12 * scale)
    np.testing.assert_allclose(a.stiffness.to_dense(), b.stiffness.to_dense(), atol=1e-11 * np.abs(b.stiffness.to_dense()).max())
    sa, sb = local_state(mounted, q), local_state(free, q)
    assert sa.ellipticity == pytest.approx(sb.ellipticity, rel=1e-12)
    assert sa.tension == pytest.approx(sb.tension, rel=1e-12) and sa.stretch == pytest.approx(sb.stretch, rel=1e-12)


@pytest.mark.parametrize("prestretch", [1.5])
def test_prestretched_balloon_curve_and_limit_point(prestretch):
    """p(lam) of the balloon mounted at lp is the exact formula at lp lam with R/lp and H lp^2: it
    rests at lam = 1/lp at p = 0 and its limit point sits at lam_LP / lp (lam from the mounted state)."""
    lp = prestretch
    branch = trace(build_scene("balloon", nodes=41, prestretch=lp), "pressure", until={"stretch": 2.0})
    t = branch.table
    assert t["pressure"].iloc[0] == 0.0 and t["stretch"].iloc[0] == pytest.approx(1.0 / lp, rel=1e-12)
    exact = balloon_pressure(lp * t["stretch"].to_numpy(), R=R / lp, H=H * lp ** 2)
    lam_lp, p_lp = balloon_limit_point(R=R / lp, H=H * lp ** 2)
    # N = 41: the stress-free balloon's curve is within 2e-4 of the exact one (test_studies); in
    # units of its own limit pressure, that is 1.4e-2 relative at most
    assert np.max(np.abs(t["pressure"] - exact)) < 1.4e-2 * 0.2 * p_lp
    lps = branch.limit_points()
    assert lps["pressure"].iloc[0] == pytest.approx(p_lp, rel=1e-3)
    assert lps["stretch"].iloc[0] == pytest.approx(lam_lp / lp, rel=2e-3)
    assert p_lp == pytest.approx(lp ** 3 * balloon_limit_point()[1], rel=1e-12)   # 4 H0 / R0 = lp^3 (4 H / R)


@pytest.mark.parametrize("bad", [{"prestretch": 0.0}, {"prestretch_2": -1.0}, {"stretch_limit": 0.5},
                                 {"E_breakdown": 0.0}])
def test_bad_prestretch_and_limits_are_one_clear_error(bad):
    from snapmem.errors import SnapmemError
    name = next(iter(bad))
    with pytest.raises(SnapmemError, match=name):
        build_scene("balloon", nodes=11, **bad)


@pytest.mark.parametrize("scene", ["balloon", "plate", "pump", "torus"])
@pytest.mark.parametrize("compressed", [{"prestretch": 0.9}, {"prestretch": 1.3, "prestretch_2": 0.99},
                                        {"prestretch_1": 0.5}])
def test_a_compressed_mount_is_refused_and_says_why(scene, compressed):
    """A prestretch below 1 would mount the membrane in compression, where a membrane (no bending
    stiffness) wrinkles: refused, naming the parameter, its value and the reason, not traced as
    a curve of spurious limit points (a plate at 0.9 gave dozens in a state unstable from the start)."""
    from snapmem.errors import SnapmemError
    name, value = [(k, v) for k, v in compressed.items() if v < 1][0]
    with pytest.raises(SnapmemError, match=rf"{name} = {value}: must be >= 1 \(.*compressed"):
        build_scene(scene, **compressed)
    assert build_scene(scene, **{k: 1.0 for k in compressed}).terms[0].law is not None   # 1 is the stress-free mount


def test_unequal_prestretch_is_the_law_at_the_total_stretch():
    """prestretch_1 and prestretch_2 reach the law as (lp1, lp2); prestretch fills the one not given."""
    law = build_scene("plate", nodes=11, prestretch=1.4, prestretch_2=1.1).terms[0].law
    assert isinstance(law, Prestretched) and (law.lp1, law.lp2) == (1.4, 1.1)
    assert law.mu == pytest.approx(1.0)
