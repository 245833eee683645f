"""The classical reference: axisymmetric membrane equilibrium as ODEs, solved by shooting.

This is the approach the paper contrasts itself with (Yang & Feng 1970; Adkins & Rivlin 1952),
written independently of snapmem's discrete model so that it can serve as its reference. It
shares only the constitutive law objects of :mod:`snapmem.model.materials`.

The formulation (the membrane equations as a first-order ODE in the reference arclength, its
integration and the measures of a solution) is in :mod:`snapmem.reference.ode_shooting`; the
boundary-value problems of a plate, a sphere and a torus, and how each is shot, in
:mod:`snapmem.reference.ode_shapes`. This module gathers their public names.

Units: lengths [m], pressure p [Pa], tensions [N/m]; normalised pressure p_hat = p / mu.

What it gives (tests/test_membrane_ode.py checks each)
-----------------------------------------------------
* sphere: the exact balloon formula (snapmem.reference.exact) to 1e-12 relative;
* torus of MODEL.md (Rb = 10, Rs = 2, H = 0.1, c1 = 0.4375, c2 = 0.0625): limit pressure
  p_hat = 0.0409097492646 at outer radius 15.54116 (u_max / Rb = 0.35412), the same to 2e-12
  with tolerances a hundred times tighter;
* Gent pump plate at 300 V (E_hat = 0.14142): pressure maximum 79.9027579 Pa at apex stretch
  2.1145 (deflection 0.11237 m), minimum 34.78158 Pa at apex stretch 9.782 (0.38466 m);
* snapmem's discrete answers (plate deflection and volume, torus outer radius, volume, u_max,
  and its located limit pressures) converge to these as N^-2.

Example::

    from snapmem.reference.membrane_ode import TorusODE
    lp = TorusODE().limit_point()
    lp.pressure, lp.measures["outer_radius"]        # 0.04090974926, 15.5412
"""

from snapmem.reference.ode_shapes import PlateODE, SphereODE, TorusODE
from snapmem.reference.ode_shooting import MeridianSolution, ODEOptions, e_hat, table

__all__ = ["MeridianSolution", "ODEOptions", "PlateODE", "SphereODE", "TorusODE", "e_hat", "table"]
