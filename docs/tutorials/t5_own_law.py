"""Tutorial 5: your own strain-energy law.

A law is a frozen dataclass deriving from :class:`snapmem.Law`: its parameters declared (name,
default, unit, range), and its density W(lam1, lam2) with the first and second derivatives in the
two principal stretches. :func:`snapmem.register_law` makes it known by name everywhere (scenes,
``--set material=ogden``, the derivative tests); the kinematics and the chain rule are the
package's. Here a one-term Ogden law, whose balloon has its limit point where
lam^(3a) = (2a + 3)/(3 - a) (by hand from W; docs/MODEL.md gives the thin-sphere pressure).

    python docs/tutorials/t5_own_law.py [--quick]
    snapmem trace balloon --set material=ogden --set alpha=1.5 --until stretch_max=3   # (with the law registered)
"""

from dataclasses import dataclass

import snapmem
from snapmem import Law, Parameter, build_scene
from snapmem.continuation import trace
from snapmem.model.materials import Density

from _common import parse


@dataclass(frozen=True)
class Ogden(Law):
    """One-term Ogden law W = 2 mu / a^2 (l1^a + l2^a + (l1 l2)^-a - 3).

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


if "ogden" not in snapmem.LAWS:
    snapmem.register_law(Ogden)


def ogden_limit_point(a, mu=1.0, R=10.0, H=0.1):
    """(lam, p) at the pressure maximum of the thin Ogden balloon: p = (H / (R lam^2)) dW(lam, lam)/dlam."""
    lam = ((2 * a + 3) / (3 - a)) ** (1 / (3 * a))
    return lam, mu * H / (R * lam ** 2) * 4 / a * (lam ** (a - 1) - lam ** (-2 * a - 1))


def main(argv=None):
    args = parse(__doc__, argv)
    law = Ogden(mu=1.0, alpha=1.5)
    scene = build_scene("balloon", nodes=41 if args.quick else 201, law=law)
    branch = trace(scene, "pressure", until={"stretch_max": 3.0})
    lp = branch.limit_points().iloc[0]
    lam_exact, p_exact = ogden_limit_point(law.alpha, law.mu)
    print(f"Ogden balloon (a = {law.alpha}): limit p = {lp['control']:.6g} (by hand {p_exact:.6g}), "
          f"stretch {lp['stretch_max']:.5g} (by hand {lam_exact:.5g})")
    return lp, (lam_exact, p_exact)


if __name__ == "__main__":
    main()
