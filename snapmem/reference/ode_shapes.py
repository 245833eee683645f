"""The boundary-value problems of the ODE reference (:mod:`snapmem.reference.membrane_ode`): a
plate, a sphere and a torus, each shot with :class:`snapmem.reference.ode_shooting.Shooter`.

Boundary-value problems and how they are shot
---------------------------------------------
* Plate (R = S, 0 <= S <= Rp, s = -1): at the axis the state is equibiaxial with apex stretch
  lam0; it starts at S = delta (``pole_offset`` times Rp) from the series
  r = lam0 delta, lam1 = lam0, psi = c delta, c = s p lam0^2 / (H (W1 + W2)) (local cap curvature),
  error O(delta^2). The rim condition is r(Rp) = Rp. A curve is traced by continuation in lam0
  (a shape quantity, so limit points in p are passed): for each lam0 the pressure p is the root
  of r(Rp; lam0, p) - Rp (secant from a predicted pressure, bracketed fallback).
* Sphere (R = R0 sin(S/R0), s = +1): from the south pole with the same series start; by symmetry
  the equator condition is psi(pi R0 / 2) = pi/2. Its answer must be the exact balloon formula.
* Torus (R = Rb + Rs cos(S/Rs), Z = Rs sin(S/Rs), s = +1): by symmetry about z = 0, integrate
  the upper half from the outer equator (S = 0: r = r_o, z = 0, psi = pi/2, lam1 = lam_o) to the
  inner equator (S = pi Rs), where z = 0 and psi = 3 pi/2. Two unknowns, two conditions, solved
  by ``scipy.optimize.root`` (hybr). A curve is traced by continuation in the outer radius r_o
  (unknowns lam_o, p), which passes the pressure maximum; the limit point is the maximum of
  p(r_o), located by Brent's method on the traced branch.

Units: lengths [m], pressure p [Pa], tensions [N/m]; normalised pressure p_hat = p / mu.
"""

from __future__ import annotations

import logging
import math

import numpy as np
from scipy.optimize import brentq, minimize_scalar, root, root_scalar

from snapmem.errors import SolverError, check_real
from snapmem.model.materials import Law, MooneyRivlin
from snapmem.reference.ode_shooting import MeridianSolution, ODEOptions, Shooter

log = logging.getLogger(__name__)


class PlateODE(Shooter):
    """Clamped circular plate inflated by pressure, solved by shooting from the apex.

    Parameters
    ----------
    R : float
        Plate radius [m] (default 7.5, MODEL.md's validation plate).
    H : float
        Thickness [m] (default 0.5).
    law : Law
        Strain energy density (default Mooney-Rivlin c1 = 0.4, c2 = 0.1, so mu = 1).
    E_hat : float
        Normalised electric load (see :func:`e_hat`).
    options : ODEOptions
    """

    def __init__(self, R: float = 7.5, H: float = 0.5, law: Law | None = None, E_hat: float = 0.0,
                 options: ODEOptions = ODEOptions()):
        self.R = check_real("R", R, minimum=0.0, min_inclusive=False)
        super().__init__(law or MooneyRivlin(0.4, 0.1), H, E_hat, self.R, -1, options)

    def reference(self, S):
        return S, 1.0 if np.ndim(S) == 0 else np.ones_like(S), 0.0 * S

    def shoot(self, lam0: float, p: float, dense: bool = False, options=None):
        """Integrate from the apex (stretch lam0, pressure p [Pa]) to the rim S = R."""
        delta, y0 = self.pole_start(lam0, p, options)
        return self.integrate(delta, self.R, y0, p, dense, options)

    def rim_residual(self, lam0: float, p: float, options=None) -> float:
        """(r(R) - R) / R, or -1 - (fraction of the plate not reached) if the shot stopped early."""
        sol = self.shoot(lam0, p, options=options)
        if sol.status != 0:
            return -1.0 - (self.R - sol.t[-1]) / self.R
        return (sol.y[0, -1] - self.R) / self.R

    def pressure(self, lam0: float, guess: float | None = None, options=None) -> float:
        """Pressure p [Pa] at which the apex stretch is lam0 (> 1).

        Secant iteration from ``guess`` (default: the small-deflection estimate), then a
        bracketed search if the secant fails.
        """
        opt = options or self.options
        if guess is None:
            guess = self._small_deflection_pressure(lam0)
        f = lambda p: self.rim_residual(lam0, p, opt)      # noqa: E731
        try:
            sol = root_scalar(f, x0=guess, x1=guess * (1 + 1e-4), method="secant",
                              xtol=opt.xtol * abs(guess), maxiter=60)
            if sol.converged and abs(f(sol.root)) < 1e3 * opt.rtol:
                return float(sol.root)
        except (ValueError, ArithmeticError):
            pass
        lo, hi = 0.0, guess
        while f(hi) > 0:
            lo, hi = hi, 2.0 * hi
        return float(brentq(f, lo, hi, xtol=opt.xtol * hi, rtol=4 * np.finfo(float).eps))

    def _small_deflection_pressure(self, lam0):
        """Pressure of a spherical cap with apex stretch lam0 (a starting guess) [Pa]."""
        e = lam0 - 1.0
        w = self.R * math.sqrt(2.0 * max(e, 1e-12))          # cap height with that stretch
        return 8.0 * self.mu * self.H * e * w / self.R ** 2 * 1.5

    def solution(self, lam0: float, p: float) -> MeridianSolution:
        """Sampled solution with measures ('deflection' = apex height above the rim [m])."""
        delta, y0 = self.pole_start(lam0, p)
        sol = self.integrate(delta, self.R, y0, p, dense=True)
        if sol.status != 0:
            raise SolverError(f"plate shot lam0 = {lam0:g}, p = {p:g} stopped at S = {sol.t[-1]:g} "
                              "(radius or meridional tension reached zero)")
        z_rim = sol.y[1, -1]
        out = self.sample(sol, delta, self.R, p, z_shift=z_rim, volume_factor=1.0)
        out.measures.update({"deflection": float(-z_rim), "apex_stretch": float(lam0),
                             "rim_error": float(sol.y[0, -1] / self.R - 1.0)})
        return out

    def at_apex_stretch(self, lam0: float, guess: float | None = None) -> MeridianSolution:
        """Equilibrium with apex stretch lam0."""
        return self.solution(lam0, self.pressure(lam0, guess))

    def at_pressure(self, p: float, lam0_guess: float | None = None) -> MeridianSolution:
        """Equilibrium at pressure p [Pa] on the branch of increasing apex stretch (below a limit)."""
        opt = self.options
        if lam0_guess is None:
            lam0_guess = brentq(lambda l: self._small_deflection_pressure(l) - p, 1.0 + 1e-12, 50.0)
        f = lambda l: self.rim_residual(l, p)        # noqa: E731
        sol = root_scalar(f, x0=lam0_guess, x1=lam0_guess * (1 + 1e-3), method="secant",
                          xtol=opt.xtol, maxiter=60)
        if not sol.converged:
            raise SolverError(f"plate at p = {p:g}: shooting on the apex stretch did not converge")
        return self.solution(float(sol.root), p)

    def branch(self, lam0_values, options=None) -> list[tuple[float, float, float]]:
        """States (lam0, p, deflection) at the given apex stretches (ascending, > 1).

        Continuation in lam0: each pressure starts from the secant prediction of the two before
        it. The deflection [m] comes from one more (non-dense) shot at the converged pressure.
        """
        out = []
        for lam0 in np.asarray(lam0_values, dtype=float):
            guess = None
            if len(out) >= 2:
                (l1, p1, _), (l2, p2, _) = out[-2:]
                guess = p2 + (p2 - p1) * (lam0 - l2) / (l2 - l1)
            elif out:
                guess = out[-1][1] * (lam0 - 1.0) / (out[-1][0] - 1.0)
            p = self.pressure(lam0, guess, options)
            sol = self.shoot(lam0, p, options=options)
            out.append((float(lam0), p, float(-sol.y[1, -1])))
        return out

    def pressure_extremum(self, rows, kind: str = "max", xtol: float = 1e-10) -> MeridianSolution:
        """The pressure maximum (``kind='max'``, a limit point) or minimum of the branch.

        ``rows`` are three consecutive rows (lam0, p, ...) of :meth:`branch` whose middle one has
        the largest (max) or smallest (min) pressure. Brent's method then locates the extremum
        of p(lam0), each pressure solved from the nearest known one; p is stationary there, so
        its value is accurate to the shooting tolerance while lam0 is located to about
        sqrt(xtol).
        """
        sign = -1.0 if kind == "max" else 1.0
        known = {float(r[0]): float(r[1]) for r in rows}

        def f(lam0):
            near = min(known, key=lambda k: abs(k - lam0))
            known[float(lam0)] = self.pressure(lam0, known[near])
            return sign * known[float(lam0)] / self.mu

        a, b, c = (float(r[0]) for r in rows)
        res = minimize_scalar(f, bracket=(a, b, c), method="brent", options={"xtol": xtol})
        lam0 = float(res.x)
        return self.solution(lam0, known[lam0] if lam0 in known else self.pressure(lam0, known[b]))

    def trace(self, lam0_values) -> list[MeridianSolution]:
        """Sampled solutions at the given apex stretches (ascending, > 1), continuation in lam0."""
        return [self.solution(lam0, p) for lam0, p, _ in self.branch(lam0_values)]


# ------------------------------------------------------------------------------------------
class SphereODE(Shooter):
    """Spherical balloon, shot from the south pole to the equator (the trivial check).

    Parameters
    ----------
    R : float
        Sphere radius [m] (default 10).
    H : float
        Thickness [m] (default 0.1).
    law : Law
        Default Mooney-Rivlin c1 = 0.4375, c2 = 0.0625.
    E_hat : float
    options : ODEOptions
    """

    def __init__(self, R: float = 10.0, H: float = 0.1, law: Law | None = None, E_hat: float = 0.0,
                 options: ODEOptions = ODEOptions()):
        self.R = check_real("R", R, minimum=0.0, min_inclusive=False)
        super().__init__(law or MooneyRivlin(0.4375, 0.0625), H, E_hat, self.R, +1, options)

    def reference(self, S):
        t = S / self.R
        return self.R * np.sin(t), np.cos(t), -self.R * np.cos(t)

    def equator_residual(self, lam0: float, p: float) -> float:
        """psi at the equator minus pi/2 [rad] (or -10 if the shot stopped)."""
        delta, y0 = self.pole_start(lam0, p)
        sol = self.integrate(delta, 0.5 * math.pi * self.R, y0, p)
        return sol.y[2, -1] - 0.5 * math.pi if sol.status == 0 else -10.0

    def pressure(self, lam0: float) -> float:
        """Pressure p [Pa] at which the pole stretch is lam0 (secant from the uniform guess)."""
        w1 = self.derivatives(lam0, lam0)[0]
        guess = 0.9 * 2.0 * self.H * w1 / (lam0 * lam0 * self.R)   # 0.9 x the uniform sphere's p
        sol = root_scalar(lambda p: self.equator_residual(lam0, p), x0=guess, x1=guess * 1.01,
                          method="secant", xtol=self.options.xtol * guess, maxiter=60)
        if not sol.converged:
            raise SolverError(f"sphere at lam0 = {lam0:g}: shooting did not converge")
        return float(sol.root)

    def solution(self, lam0: float, p: float) -> MeridianSolution:
        delta, y0 = self.pole_start(lam0, p)
        sol = self.integrate(delta, 0.5 * math.pi * self.R, y0, p, dense=True)
        out = self.sample(sol, delta, 0.5 * math.pi * self.R, p, volume_factor=2.0)
        out.measures["apex_stretch"] = float(lam0)
        return out


# ------------------------------------------------------------------------------------------
class TorusODE(Shooter):
    """Toroidal membrane inflated by pressure, upper half shot from the outer to the inner equator.

    Parameters
    ----------
    Rb : float
        Axis to the centre of the cross-section [m] (default 10).
    Rs : float
        Cross-section radius [m], < Rb (default 2).
    H : float
        Thickness [m] (default 0.1).
    law : Law
        Default Mooney-Rivlin c1 = 0.4375, c2 = 0.0625 (mu = 1).
    E_hat : float
        Normalised electric load.
    options : ODEOptions
    """

    def __init__(self, Rb: float = 10.0, Rs: float = 2.0, H: float = 0.1, law: Law | None = None,
                 E_hat: float = 0.0, options: ODEOptions = ODEOptions()):
        self.Rb = check_real("Rb", Rb, minimum=0.0, min_inclusive=False)
        self.Rs = check_real("Rs", Rs, minimum=0.0, maximum=self.Rb, min_inclusive=False,
                             max_inclusive=False)
        super().__init__(law or MooneyRivlin(0.4375, 0.0625), H, E_hat, self.Rs, +1, options)
        self.S_end = math.pi * self.Rs

    def reference(self, S):
        t = S / self.Rs
        return self.Rb + self.Rs * np.cos(t), -np.sin(t), self.Rs * np.sin(t)

    def shoot(self, r_o, lam_o, p, dense=False, options=None):
        """Integrate the upper half from the outer equator (radius r_o, stretch lam_o) at p [Pa]."""
        return self.integrate(0.0, self.S_end, [r_o, 0.0, 0.5 * math.pi, lam_o, 0.0], p, dense, options)

    def residual(self, r_o, lam_o, p, options=None) -> np.ndarray:
        """(z / Rs, psi - 3 pi/2) at the inner equator; large values if the shot stopped."""
        sol = self.shoot(r_o, lam_o, p, options=options)
        if sol.status != 0:
            return np.array([10.0, 10.0]) * (1 + (self.S_end - sol.t[-1]) / self.S_end)
        return np.array([sol.y[1, -1] / self.Rs, sol.y[2, -1] - 1.5 * math.pi])

    def _solve(self, fun, x0, what, options=None):
        opt = options or self.options
        sol = root(fun, x0, method="hybr", options={"xtol": opt.xtol, "maxfev": 200})
        if not np.max(np.abs(sol.fun)) <= 1e3 * opt.rtol:       # hybr may stall at round-off
            raise SolverError(f"torus {what}: shooting did not converge ({sol.message.strip()}, "
                              f"residual {np.max(np.abs(sol.fun)):.2e})")
        return sol.x

    def at_outer_radius(self, r_o: float, guess, options=None) -> tuple[float, float]:
        """(lam_o, p) of the equilibrium with outer radius r_o [m], from a guess (lam_o, p)."""
        scale = self.mu * self.H / self.Rs                   # pressure scale [Pa]
        x = self._solve(lambda x: self.residual(r_o, x[0], x[1] * scale, options),
                        np.array([guess[0], guess[1] / scale]), f"at r_o = {r_o:g}", options)
        return float(x[0]), float(x[1] * scale)

    def _linear_guess(self, p):
        """(r_o, lam_o) of small-strain membrane theory at the outer equator (a starting guess).

        Statics give T1 = p Rs (Ro + Rb) / (2 Ro), T2 = p Rs / 2 there; incompressible plane
        stress gives the strains e1 = (2 T1 - T2) / (6 mu H), e2 = (2 T2 - T1) / (6 mu H), the
        voltage adding its compressive 2 a H = mu E_hat^2 H to what the elastic stress carries.
        """
        Ro = self.Rb + self.Rs
        T1, T2 = p * self.Rs * (Ro + self.Rb) / (2 * Ro), 0.5 * p * self.Rs
        T1, T2 = T1 + 2.0 * self._a * self.H, T2 + 2.0 * self._a * self.H
        k = 6.0 * self.mu * self.H
        return np.array([Ro * (1.0 + (2 * T2 - T1) / k), 1.0 + (2 * T1 - T2) / k])

    def at_pressure(self, p: float, guess=None, options=None) -> tuple[float, float]:
        """(r_o, lam_o) of the equilibrium at pressure p [Pa] > 0 below the limit point.

        Without a guess (r_o, lam_o), continues in pressure from 0.2 p (small-strain start).
        """
        if guess is None:                   # march in pressure from a linear-theory start
            xs = []
            for pk in p * np.array([0.2, 0.35, 0.5, 0.65, 0.8, 0.9]):
                x0 = self._linear_guess(pk) if not xs else xs[-1] if len(xs) < 2 else 2 * xs[-1] - xs[-2]
                xs.append(self._solve(lambda y: self.residual(y[0], y[1], pk, options), x0,
                                      f"at p = {pk:g}", options))
            guess = 2 * xs[-1] - xs[-2] if p > 0 else xs[-1]
        x = self._solve(lambda y: self.residual(y[0], y[1], p, options), np.asarray(guess, float),
                        f"at p = {p:g}", options)
        return float(x[0]), float(x[1])

    def solution(self, r_o: float, lam_o: float, p: float) -> MeridianSolution:
        """Sampled solution with measures ('outer_radius', 'inner_radius' [m], ...)."""
        sol = self.shoot(r_o, lam_o, p, dense=True)
        if sol.status != 0:
            raise SolverError(f"torus shot r_o = {r_o:g}, lam_o = {lam_o:g}, p = {p:g} stopped early")
        out = self.sample(sol, 0.0, self.S_end, p, volume_factor=2.0)
        out.measures.update({"outer_radius": float(r_o), "inner_radius": float(sol.y[0, -1]),
                             "outer_stretch": float(lam_o),
                             "closure_error": float(max(abs(sol.y[1, -1]) / self.Rs,
                                                        abs(sol.y[2, -1] - 1.5 * math.pi)))})
        return out

    def seeds(self, r_o_first: float, options=None):
        """Two solved states [(r_o, lam_o, p), ...] with outer radius below r_o_first [m].

        Solved at pressures p_s and 0.9 p_s, p_s halved from 0.1 mu H / Rs until r_o(p_s) is
        below ``r_o_first``; they seed the secant predictor of the continuation in r_o.
        """
        p = 0.1 * self.mu * self.H / self.Rs
        for _ in range(4):
            r_a, lam_a = self.at_pressure(p, options=options)
            if r_a < r_o_first:
                r_b, lam_b = self.at_pressure(0.9 * p, (r_a, lam_a), options)
                return [(r_b, lam_b, 0.9 * p), (r_a, lam_a, p)]
            p *= 0.5
        raise SolverError(f"r_o = {r_o_first:g}: too close to the reference outer radius to trace from")

    def branch(self, r_o_values, options=None) -> list[tuple[float, float, float]]:
        """States (r_o, lam_o, p) at the given outer radii (ascending) by continuation in r_o.

        The outer radius grows monotonically along the inflation branch (checked: p(r_o) is
        single-valued), so it parametrises the branch through its pressure maximum. Each point
        starts from the secant prediction of the two before it.
        """
        r_o_values = np.asarray(r_o_values, dtype=float)
        known = [(r, np.array([lam, p])) for r, lam, p in self.seeds(r_o_values[0], options)]
        out = []
        for r_o in r_o_values:
            (r1, x1), (r2, x2) = known[-2:]
            guess = x2 + (x2 - x1) * (r_o - r2) / (r2 - r1)
            lam_o, p = self.at_outer_radius(r_o, guess, options)
            known.append((r_o, np.array([lam_o, p])))
            out.append((float(r_o), lam_o, p))
        return out

    def trace(self, r_o_values) -> list[MeridianSolution]:
        """Sampled solutions at the given outer radii (ascending), through the limit point."""
        return [self.solution(*state) for state in self.branch(r_o_values)]

    def limit_point(self, r_range=None, n_scan: int = 16, xtol: float = 1e-7) -> MeridianSolution:
        """The pressure maximum of the inflation branch (the torus's limit point).

        Scans p(r_o) on ``n_scan`` outer radii over ``r_range`` (default Ro (1.01, 1.5)), then
        maximises p(r_o) by Brent's method to relative ``xtol`` in r_o. p is stationary there,
        so an error dr in r_o changes p by only p'' dr^2 / 2: with xtol = 1e-7, below 1e-12
        relative, the shooting tolerance.

        Raises
        ------
        SolverError
            If p(r_o) has no interior maximum over the scanned range.
        """
        Ro = self.Rb + self.Rs
        lo, hi = r_range or (1.01 * Ro, 1.5 * Ro)
        grid = np.linspace(lo, hi, n_scan)
        states = []
        try:
            for state in self.branch(grid):
                states.append(state)
                if len(states) > 2 and state[2] < states[-2][2]:
                    break                               # passed the maximum
        except SolverError as exc:
            log.info("torus limit scan stopped: %s", exc)
        ps = np.array([s[2] for s in states])
        k = int(np.argmax(ps))
        if k == 0 or k == len(ps) - 1:
            raise SolverError(f"no interior pressure maximum of the torus for r_o in [{lo:g}, {hi:g}]")
        r_grid = np.array([s[0] for s in states])
        cache = {}

        def neg_p(r_o):
            j = int(np.argmin(np.abs(r_grid - r_o)))
            lam_o, p = self.at_outer_radius(r_o, states[j][1:])
            cache[float(r_o)] = (lam_o, p)
            return -p / self.mu

        res = minimize_scalar(neg_p, bracket=(r_grid[k - 1], r_grid[k], r_grid[k + 1]), method="brent",
                              options={"xtol": xtol})
        r_lp = float(res.x)
        lam_o, p = cache[r_lp] if r_lp in cache else self.at_outer_radius(r_lp, states[k][1:])
        out = self.solution(r_lp, lam_o, p)
        log.info("torus limit point: p_hat = %.12g at r_o = %.10g", p / self.mu, r_lp)
        return out
