"""A law defined outside the package works everywhere with one call: a one-term Ogden law,
registered with snapmem.register_law, used by name and as an instance in every scene and on the
command line, checked by the derivative tests for free, and its balloon's limit pressure against
the exact thin-sphere formula."""

from dataclasses import dataclass

import numpy as np
import pytest

import snapmem
import snapmem.materials
from snapmem import Law, MooneyRivlin, Parameter, build_scene
from snapmem.cli import main
from snapmem.continuation import trace
from snapmem.errors import SnapmemError
from snapmem.model.materials import LAWS, Density
from snapmem.reference import exact

from conftest import SHAPES
from test_derivatives import check_declaration, check_law

R, H = 10.0, 0.1                 # the balloon scene's defaults


@dataclass(frozen=True)
class Ogden(Law):
    """One-term Ogden law W = 2 mu / a^2 (l1^a + l2^a + (l1 l2)^-a - 3), shear modulus mu.

    Attributes
    ----------
    mu : float
        Shear modulus [Pa], > 0.
    alpha : float
        Exponent a, > 0 (a = 2 is neo-Hookean).
    """

    mu: float
    alpha: float
    parameters = (Parameter("mu", 1.0, "Pa", "shear modulus", minimum=0.0, open_min=True),
                  Parameter("alpha", 1.5, "", "Ogden exponent a", minimum=0.0, open_min=True))

    @classmethod
    def example(cls):
        return cls(mu=1.0, alpha=1.5)

    def density(self, lam1, lam2):
        a, k = self.alpha, 2.0 * self.mu / self.alpha
        s = (lam1 * lam2) ** -a                                   # lam3^a
        return Density(w=k / a * (lam1 ** a + lam2 ** a + s - 3.0),
                       w1=k * (lam1 ** (a - 1) - s / lam1),
                       w2=k * (lam2 ** (a - 1) - s / lam2),
                       w11=k * ((a - 1) * lam1 ** (a - 2) + (1 + a) * s / lam1 ** 2),
                       w12=2.0 * self.mu * s / (lam1 * lam2),
                       w22=k * ((a - 1) * lam2 ** (a - 2) + (1 + a) * s / lam2 ** 2))


snapmem.register_law(Ogden)


@dataclass(frozen=True)
class HalfModulusNeoHookean(Law):
    """W = c10 (I1 - 3), shear modulus 2 c10: a law without a parameter named mu (scenes set its
    modulus by scaling its parameters in Pa)."""

    c10: float
    parameters = (Parameter("c10", 0.5, "Pa", "constant of I1 - 3", minimum=0.0, open_min=True),)

    @property
    def mu(self):
        return 2.0 * self.c10

    def density(self, lam1, lam2):
        return snapmem.NeoHookean(2.0 * self.c10).density(lam1, lam2)


snapmem.register_law(HalfModulusNeoHookean)


def thin_sphere_pressure(law, lam):
    """p / mu of the uniformly inflated thin sphere: (H / (R lam^2)) dW(lam, lam)/dlam, where
    dW(lam, lam)/dlam = W_1 + W_2 at lam1 = lam2 = lam."""
    d = law.density(np.asarray(lam, float), np.asarray(lam, float))
    return H / (R * lam ** 2) * (d.w1 + d.w2) / law.mu


def ogden_limit_point(a, mu=1.0):
    """(lam, p/mu) of the pressure maximum of the Ogden balloon, by hand: dW(lam, lam)/dlam =
    (4 mu / a)(lam^(a-1) - lam^(-2a-1)), so p ~ lam^(a-3) - lam^(-2a-3), which has a maximum
    (then falls to 0) for 0 < a < 3, at lam^(3a) = (2a + 3)/(3 - a)."""
    lam = ((2 * a + 3) / (3 - a)) ** (1 / (3 * a))
    return lam, H / (R * lam ** 2) * 4 / a * (lam ** (a - 1) - lam ** (-2 * a - 1))


def test_registered_by_one_call_and_declared():
    assert LAWS["ogden"] == (Ogden, ("mu", "alpha"))
    assert "register_law" in snapmem.__all__
    assert snapmem.materials.register_law is snapmem.register_law
    check_declaration(Ogden)
    check_declaration(HalfModulusNeoHookean)


@pytest.mark.parametrize("shape", list(SHAPES))
@pytest.mark.parametrize("name", ["ogden", "half_modulus_neo_hookean"])
def test_registered_law_matches_finite_differences(shape, name, rng):
    """The derivative tests every registered law gets, on the user law (found by its name)."""
    check_law(LAWS[name][0].example(), shape, rng)


def test_thin_sphere_formula_reproduces_the_exact_mooney_rivlin_balloon():
    lam = np.linspace(1.01, 4.0, 50)
    np.testing.assert_allclose(thin_sphere_pressure(MooneyRivlin(0.4375, 0.0625), lam),
                               exact.balloon_pressure(lam), rtol=1e-12)
    law = Ogden(1.0, 1.5)           # and the Ogden density against the closed form by hand
    np.testing.assert_allclose(thin_sphere_pressure(law, lam),
                               H / (R * lam ** 2) * 4 / 1.5 * (lam ** 0.5 - lam ** -4), rtol=1e-12)


def test_the_ogden_balloon_has_a_limit_point():
    lam_lp, p_lp = ogden_limit_point(1.5)
    lam = np.linspace(1.0 + 1e-6, 10.0, 20001)
    p = thin_sphere_pressure(Ogden(1.0, 1.5), lam)
    i = int(np.argmax(p))
    assert 0 < i < lam.size - 1 and p[-1] < 0.5 * p[i]           # rises, peaks, falls
    assert lam[i] == pytest.approx(lam_lp, abs=1e-3) and p[i] == pytest.approx(p_lp, rel=1e-6)


@pytest.mark.parametrize("how", ["by name", "as an instance"])
def test_ogden_balloon_limit_pressure_is_exact_within_the_mesh_error(how):
    scene = (build_scene("balloon", nodes=101, material="ogden", mu=1.0, alpha=1.5) if how == "by name"
             else build_scene("balloon", nodes=101, law=Ogden(mu=1.0, alpha=1.5)))
    assert scene.parameters["material"] == "ogden" and scene.parameters["alpha"] == 1.5
    branch = trace(scene, "pressure", until={"stretch": 2.0})
    lp = branch.limit_points().iloc[0]
    lam_lp, p_lp = ogden_limit_point(1.5)
    assert abs(lp["pressure"] / p_lp - 1) < 2e-4 and abs(lp["stretch"] / lam_lp - 1) < 2e-3


def test_every_scene_takes_a_law_instance():
    law = Ogden(mu=4.0e5, alpha=1.8)
    for name in snapmem.SCENES:
        scene = build_scene(name, law=law, nodes=21)
        stretching = [t for t in scene.terms if isinstance(t, snapmem.Stretching)]
        assert stretching and all(t.law == law for t in stretching), name      # one per membrane
        assert scene.parameters["material"] == "ogden" and scene.parameters["mu"] == 4.0e5
        assert "c1" not in scene.parameters


def test_scene_mu_sets_the_modulus_of_a_law_without_a_parameter_mu():
    default = build_scene("balloon", nodes=11, material="half_modulus_neo_hookean")
    assert default.terms[0].law == HalfModulusNeoHookean(0.5)        # mu = 2 (c1 + c2) = 1
    assert build_scene("balloon", nodes=11, material="half_modulus_neo_hookean", mu=3.0).terms[0].law.mu == 3.0


@pytest.mark.parametrize("params,words", [
    ({"law": Ogden(1.0, 1.5), "material": "gent"}, ["set one of them"]),
    ({"law": Ogden(1.0, 1.5), "alpha": 2.0}, ["alpha", "instance"]),
    ({"law": "ogden"}, ["instance"]),
    ({"material": "ogden", "alpha": -1.0}, ["alpha = -1", "> 0"]),
    ({"material": "mooney_rivlin", "alpha": 2.0}, ["alpha", "no such parameter"]),
])
def test_bad_law_inputs_name_what_is_wrong(params, words):
    with pytest.raises(SnapmemError) as info:
        build_scene("balloon", nodes=11, **params)
    assert all(w in str(info.value) for w in words), str(info.value)


def test_command_line_takes_the_law_by_name_and_checks_its_range(capsys):
    args = ["equilibrium", "balloon", "--set", "nodes=31", "--set", "material=ogden", "--pressure", "0.01"]
    assert main(args + ["--set", "alpha=1.5"]) == 0
    assert "converged: True" in capsys.readouterr().out
    assert main(args + ["--set", "alpha=0"]) == 2
    assert "alpha = 0" in capsys.readouterr().err
    assert main(["scenes"]) == 0
    assert "alpha = 1.5  ogden: Ogden exponent a" in capsys.readouterr().out
