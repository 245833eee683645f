"""The shooting machinery of the ODE reference (:mod:`snapmem.reference.membrane_ode`): the
membrane-of-revolution ODE, its integration and the measures of a solution.

Formulation
-----------
A membrane of revolution has the reference meridian (R(S), Z(S)), S the reference arclength
[m], thickness H [m], and the deformed meridian (r(S), z(S)) with tangent angle psi (measured
from the +r direction). The principal stretches are

    lam1 = sqrt(r'^2 + z'^2)  (meridional),   lam2 = r / R  (hoop),   ' = d/dS,

so r' = lam1 cos psi, z' = lam1 sin psi. The potential is

    Pi = int 2 pi R H W(lam1, lam2) dS - p s int pi r^2 z' dS,

with W the strain energy per unit reference volume plus the electric term
W_el = -(eps/2)(phi/H)^2 lam1^2 lam2^2 = -(mu/2) E_hat^2 lam1^2 lam2^2 (minus: voltage held by a
source, MODEL.md section 2), and s = +1 when the enclosed region lies to the left of the
direction of integration (sphere from its south pole, torus counter-clockwise), s = -1 for the
plate integrated from the axis to the rim. Its Euler-Lagrange equations, written with the
meridional force per radian Q = r T1 = R H W1 (W1 = dW/dlam1, T1 = (H/lam2) W1,
T2 = (H/lam1) W2), are the classical membrane equations

    Q' = H W2 cos psi                                 (tangential equilibrium)
    Q psi' = s p r lam1 - H W2 sin psi                (normal: T1 k1 + T2 k2 = p)

and since Q = R H W1(lam1, lam2), the first one gives lam1' through W11, W12. The state
y = (r, z, psi, lam1, V) obeys

    r'    = lam1 cos psi
    z'    = lam1 sin psi
    psi'  = (s p r lam1 - H W2 sin psi) / (R H W1)
    lam1' = (W2 cos psi - R' W1 - R W12 lam2') / (R W11),   lam2' = (r' - lam2 R') / R
    V'    = s pi r^2 z'                               (enclosed volume, signed as in snapmem)

integrated with ``scipy.integrate.solve_ivp`` (DOP853 by default, tolerances in
:class:`ODEOptions`). Events stop an integration where r or W1 (the meridional tension) reaches
zero, so a shot that fails reports it instead of returning garbage.

Units: lengths [m], pressure p [Pa], tensions [N/m]; normalised pressure p_hat = p / mu.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy.integrate import solve_ivp
from scipy.optimize import minimize_scalar

from snapmem.errors import SolverError, check_int, check_real
from snapmem.model.materials import Law


@dataclass(frozen=True)
class ODEOptions:
    """Tolerances of the shooting solutions.

    Attributes
    ----------
    rtol : float
        Relative tolerance of ``solve_ivp`` (default 1e-11).
    atol : float
        Absolute tolerance on the scaled state (lengths / reference size, angles [rad],
        stretches, volume / size^3) (default 1e-13).
    method : str
        ``solve_ivp`` method (default 'DOP853').
    pole_offset : float
        Start of the integration off a pole, as a fraction of the reference size (default 1e-6);
        the series start is accurate to O(pole_offset^2).
    xtol : float
        Tolerance of the shooting root finders on their (scaled) unknowns (default 1e-13).
    samples : int
        Points at which a solution is sampled for its measures (default 801).
    """

    rtol: float = 1e-11
    atol: float = 1e-13
    method: str = "DOP853"
    pole_offset: float = 1e-6
    xtol: float = 1e-13
    samples: int = 801

    def __post_init__(self):
        check_real("rtol", self.rtol, minimum=0.0, min_inclusive=False)
        check_real("atol", self.atol, minimum=0.0, min_inclusive=False)
        check_real("pole_offset", self.pole_offset, minimum=0.0, maximum=0.1, min_inclusive=False)
        check_real("xtol", self.xtol, minimum=0.0, min_inclusive=False)
        check_int("samples", self.samples, minimum=11)


@dataclass(frozen=True)
class MeridianSolution:
    """One equilibrium of the continuous membrane, sampled along the reference arclength.

    Attributes
    ----------
    pressure : float
        p [Pa].
    S, r, z, psi, lam1, lam2, T1, T2 : ndarray (M,)
        Reference arclength [m], deformed coordinates [m], tangent angle [rad], stretches,
        principal tensions [N/m], over the integrated part of the meridian (the torus: its upper
        half, outer to inner equator).
    measures : dict
        'volume' [m^3], 'u_max' [m] (largest displacement of a material point), 'stretch_max',
        'min_tension' [N/m], 'taut', and 'deflection' (plate: apex height), 'apex_stretch'
        (plate, sphere) or 'outer_radius', 'inner_radius', 'outer_stretch' (torus).
    """

    pressure: float
    S: np.ndarray
    r: np.ndarray
    z: np.ndarray
    psi: np.ndarray
    lam1: np.ndarray
    lam2: np.ndarray
    T1: np.ndarray
    T2: np.ndarray
    measures: dict = field(default_factory=dict)


class Shooter:
    """Shared right-hand side, integration and measures of an axisymmetric membrane; a shape
    (:mod:`snapmem.reference.ode_shapes`) gives its reference meridian, :meth:`reference`.

    Parameters
    ----------
    law : Law
        Strain energy density W(lam1, lam2) [Pa].
    H : float
        Reference thickness [m].
    E_hat : float
        Normalised electric load (phi/H) sqrt(eps/mu); adds W_el = -(mu/2) E_hat^2 lam1^2 lam2^2.
    size : float
        Reference length scale [m] (tolerance scaling).
    sign : {+1, -1}
        Orientation of the enclosed region relative to the direction of integration.
    options : ODEOptions
    """

    def __init__(self, law: Law, H: float, E_hat: float, size: float, sign: int, options: ODEOptions):
        self.law = law
        self.H = check_real("H", H, minimum=0.0, min_inclusive=False)
        self.E_hat = check_real("E_hat", E_hat, minimum=0.0)
        self.mu = float(law.mu)
        self._a = 0.5 * self.mu * self.E_hat ** 2          # W_el = -a lam1^2 lam2^2
        self.size = float(size)
        self.sign = float(sign)
        self.options = options
        L = self.size
        self._atol = options.atol * np.array([L, L, 1.0, 1.0, L ** 3])

    # -- constitutive law with the electric term -------------------------------------------
    def derivatives(self, lam1, lam2):
        """(W1, W2, W11, W12) of the total density at (lam1, lam2) [Pa] (floats or arrays)."""
        scalar = np.ndim(lam1) == 0 and np.ndim(lam2) == 0
        lam1, lam2 = np.asarray(lam1, dtype=float), np.asarray(lam2, dtype=float)
        d = self.law.density(lam1, lam2)
        a = self._a
        out = (d.w1 - 2.0 * a * lam1 * lam2 * lam2, d.w2 - 2.0 * a * lam1 * lam1 * lam2,
               d.w11 - 2.0 * a * lam2 * lam2, d.w12 - 4.0 * a * lam1 * lam2)
        return tuple(float(v) for v in out) if scalar else out

    def reference(self, S):
        """(R, dR/dS, Z) of the reference meridian at arclength S [m]."""
        raise NotImplementedError

    # -- the ODE ---------------------------------------------------------------------------
    def rhs(self, S, y, p):
        """dy/dS of y = (r, z, psi, lam1, V) at pressure p [Pa]."""
        r, _z, psi, lam1, _v = y
        if not (math.isfinite(psi) and lam1 > 0.0 and r > 0.0):
            return [math.nan] * 5                            # solve_ivp then fails: status -1
        R, dR, _ = self.reference(S)
        lam2 = r / R
        w1, w2, w11, w12 = self.derivatives(lam1, lam2)
        c, s = math.cos(psi), math.sin(psi)
        dr, dz = lam1 * c, lam1 * s
        dlam2 = (dr - lam2 * dR) / R
        return [dr, dz,
                (self.sign * p * r * lam1 / self.H - w2 * s) / (R * w1),
                (w2 * c - dR * w1 - R * w12 * dlam2) / (R * w11),
                self.sign * math.pi * r * r * dz]

    def integrate(self, S0, S1, y0, p, dense=False, options=None):
        """Integrate from S0 to S1; stops (status 1) where r or the meridional tension vanish."""
        opt = options or self.options
        floor = 1e-9 * self.size

        def radius(S, y, p):
            return y[0] - floor

        def tension(S, y, p):
            R, _, _ = self.reference(S)
            return self.derivatives(y[3], y[0] / R)[0]

        def winding(S, y, p):                   # a meridian that turns more than twice: a bad shot
            return 4.0 * math.pi - abs(y[2])

        radius.terminal = tension.terminal = winding.terminal = True
        atol = opt.atol * np.array([self.size, self.size, 1.0, 1.0, self.size ** 3])
        with np.errstate(all="ignore"):
            return solve_ivp(self.rhs, (S0, S1), y0, method=opt.method, rtol=opt.rtol, atol=atol,
                             args=(p,), events=(radius, tension, winding), dense_output=dense)

    def pole_start(self, lam0, p, options=None):
        """(delta, y0): series start of an integration from a pole at apex stretch lam0."""
        opt = options or self.options
        delta = opt.pole_offset * self.size
        R, _, _ = self.reference(delta)
        w1, w2, _, _ = self.derivatives(lam0, lam0)
        if not w1 > 0.0:
            raise SolverError(f"apex stretch {lam0:g}: the pole is not taut (W1 = {w1:.3g} <= 0; a "
                              "voltage compresses the membrane there), no membrane solution")
        c = self.sign * p * lam0 * lam0 / (self.H * (w1 + w2))
        ds = lam0 * delta
        return delta, [lam0 * R, 0.5 * c * ds * ds, c * delta, lam0, 0.0]

    def sample(self, sol, S0, S1, p, z_shift=0.0, volume_factor=1.0) -> MeridianSolution:
        """Sample a dense solution and compute its measures."""
        S = np.linspace(S0, S1, self.options.samples)
        r, z, psi, lam1, V = sol.sol(S)
        z = z - z_shift
        R, _, Z = self.reference(S)
        lam2 = r / R
        w1, w2, _, _ = self.derivatives(lam1, lam2)
        T1, T2 = self.H * w1 / lam2, self.H * w2 / lam1
        disp2 = (r - R) ** 2 + (z - Z) ** 2
        k = int(np.argmax(disp2))
        u_max = math.sqrt(disp2[k])
        if 0 < k < S.size - 1:                       # refine the maximum between samples
            def neg(s):
                rr, zz = sol.sol(s)[:2]
                RR, _, ZZ = self.reference(s)
                return -((rr - RR) ** 2 + (zz - z_shift - ZZ) ** 2)
            res = minimize_scalar(neg, bounds=(S[k - 1], S[k + 1]), method="bounded",
                                  options={"xatol": 1e-12 * self.size})
            u_max = max(u_max, math.sqrt(-res.fun))
        min_t = float(min(T1.min(), T2.min()))
        measures = {"volume": float(volume_factor * V[-1]), "u_max": u_max,
                    "stretch_max": float(max(lam1.max(), lam2.max())),
                    "min_tension": min_t, "taut": bool(min_t > 0)}
        return MeridianSolution(float(p), S, r, z, psi, lam1, lam2, T1, T2, measures)


def e_hat(voltage: float, H: float, permittivity: float, mu: float) -> float:
    """Normalised electric load E_hat = (phi/H) sqrt(eps/mu) of a voltage phi [V] on thickness H [m]."""
    return voltage / H * math.sqrt(permittivity / mu)


def table(solutions, names=("volume", "u_max", "min_tension")) -> dict:
    """Branch as columns {'pressure': (M,), name: (M,), ...}, one row per solution."""
    out = {"pressure": np.array([sol.pressure for sol in solutions])}
    for name in names:
        out[name] = np.array([sol.measures[name] for sol in solutions])
    return out
