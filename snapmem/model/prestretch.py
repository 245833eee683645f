"""A law mounted prestretched: the membrane's reference shape is its mounted one, and the law is
evaluated at the total stretch from the stress-free state (issue 15; docs/MODEL.md).

With prestretches lp1, lp2 (meridional, hoop) and stretches lam1, lam2 measured from the mounted
state, the energy per unit (mounted, = stress-free: incompressible) volume is W(lp1 lam1, lp2
lam2); its derivatives in (lam1, lam2) carry the factors lp_i (first) and lp_i lp_j (second).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from snapmem.errors import SnapmemError
from snapmem.kernels.laws import prestretch_chain
from snapmem.model.materials import Density, Law


@dataclass(frozen=True)
class Prestretched(Law):
    """A law evaluated at the total stretch of a membrane mounted prestretched (issue 15).

    The meridian, its reference lengths and radii and the thickness H are those of the mounted
    state, itself reached from the stress-free one by the principal prestretches (lp1, lp2)
    (meridional, hoop). With (lam1, lam2) the stretches relative to the mounted state, the total
    stretches relative to the stress-free state are Lam_i = lp_i lam_i, and

        W'(lam1, lam2) = W(lp1 lam1, lp2 lam2),
        W'_1 = lp1 W_1,  W'_2 = lp2 W_2,
        W'_11 = lp1^2 W_11,  W'_12 = lp1 lp2 W_12,  W'_22 = lp2^2 W_22,

    derivatives of W taken at (Lam1, Lam2). W is per unit stress-free volume; the material is
    incompressible, so the mounted volume 2 pi r_m l H (r_m = lp2 r_m0, l = lp1 l0,
    H = H0 / (lp1 lp2)) is the stress-free one and the scene's weights need no factor. The
    electric term -(eps/2)(phi/H)^2 lam1^2 lam2^2 with the mounted H equals
    -(eps/2)(phi/H0)^2 Lam1^2 Lam2^2 and needs none either. W' is isotropic in (lam1, lam2)
    only if lp1 = lp2; :func:`total_density` takes a density back to the total stretches, where
    the local checks (snapmem.model.local_checks) are made.

    Attributes
    ----------
    law : Law
        The material's law, of the total stretch.
    lp1, lp2 : float
        Meridional and hoop prestretches (> 0; 1, 1 is the stress-free mounting).
    """

    law: Law
    lp1: float = 1.0
    lp2: float = 1.0

    def __post_init__(self):
        if not isinstance(self.law, Law):
            raise SnapmemError(f"Prestretched law = {self.law!r}: must be a snapmem Law")
        for name in ("lp1", "lp2"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and np.isfinite(value) and value > 0):
                raise SnapmemError(f"prestretch {name} = {value!r}: must be a real number > 0")

    @property
    def mu(self) -> float:
        """The material's initial shear modulus [Pa] (that of the stress-free state)."""
        return self.law.mu

    def density(self, lam1, lam2) -> Density:
        lp1, lp2 = self.lp1, self.lp2
        d = self.law.density(lp1 * lam1, lp2 * lam2)
        return Density(*prestretch_chain.py_func(d.w, d.w1, d.w2, d.w11, d.w12, d.w22, lp1, lp2))

    def admissible(self, lam1, lam2):
        return self.law.admissible(self.lp1 * lam1, self.lp2 * lam2)


def prestretches(law: Law) -> tuple[float, float]:
    """(lp1, lp2) of a :class:`Prestretched` law, (1, 1) for any other."""
    return (law.lp1, law.lp2) if isinstance(law, Prestretched) else (1.0, 1.0)


def total_density(dens: Density, lp1: float, lp2: float) -> Density:
    """A density in the mounted stretches (lam1, lam2) as one in the total stretches
    Lam_i = lp_i lam_i: derivatives divided by the chain-rule factors of :class:`Prestretched`."""
    if lp1 == 1.0 and lp2 == 1.0:
        return dens
    return Density(dens.w, dens.w1 / lp1, dens.w2 / lp2, dens.w11 / (lp1 * lp1), dens.w12 / (lp1 * lp2),
                   dens.w22 / (lp2 * lp2))
