"""Viscoelastic membranes: non-equilibrium networks in series with dashpots (a Zener-type model).

The membrane's law is the *equilibrium network*. Each non-equilibrium network k adds, per unit
reference volume, a neo-Hookean energy of the elastic part of the stretch,

    W_k = (mu_k / 2) (a1^2 + a2^2 + a1^-2 a2^-2 - 3),    a_i = lam_i / xi_ki,

with xi_ki the network's internal (viscous) stretches, one pair per edge. In log strains
eps_i = ln lam_i, zeta_i = ln xi_ki, e_i = eps_i - zeta_i, the flow rule is

    eta_k A dzeta/dt = dW_k/de,    A = [[4, 2], [2, 4]],    eta_k = mu_k tau_k,

the gradient flow of the dissipation potential (eta_k / 2) zeta'^T A zeta'. A is the small-strain
stiffness of W_k in (e1, e2) divided by mu_k, so every small-strain mode relaxes at a held stretch
with the same time tau_k (``relaxation_time``). The dissipation rate eta_k zeta'^T A zeta' is >= 0.

Inside a time step of length h from the anchor zeta_hat (the scheme's, like its x_hat), the
network contributes the incremental potential

    phi_k(lam, zeta) = W_k(lam e^-zeta) + (eta_k / (2 h)) (zeta - zeta_hat)^T A (zeta - zeta_hat),

whose minimum in zeta is implicit Euler of the flow rule. The internal variables are condensed per
edge: a local Newton (convex: d2 phi / d zeta2 is positive definite) gives zeta*(lam), and the
condensed density Phi_k(lam) = phi_k(lam, zeta*(lam)) has gradient dW_k/dlam at zeta* (envelope
theorem) and the symmetric Hessian f_ee - f_ee (f_ee + eta_k A / h)^-1 f_ee in log strains. So
the global unknowns stay q, the band structure is kept and Newton sees a symmetric tangent.

Outside a time step the term is one of the two static limits of the law (``limit``):
``relaxed`` (the long-time equilibrium: the networks carry no stress, the equilibrium network
alone) or ``instantaneous`` (the glassy response: every network elastic with its internal stretches
held, at xi = 1 for a fresh membrane).
"""

from __future__ import annotations

import numpy as np

from snapmem.errors import SnapmemError, check_real
from snapmem.model.kinematics import EdgeKinematics
from snapmem.model.materials import Density
from snapmem.model.terms import DensityTerm

#: The static limits of a viscoelastic law.
VISCOUS_LIMITS = ("relaxed", "instantaneous")

#: The flow rule's metric (the small-strain stiffness of a neo-Hookean network in log strains / mu).
FLOW_METRIC = np.array([[4.0, 2.0], [2.0, 4.0]])

_LOCAL_TOL = 1e-14          # local Newton: |d zeta| below this (log strain) ends it
_LOCAL_MAX_ITERATIONS = 50


def network_log_derivatives(e1, e2, mu):
    """W_k and its first and second derivatives in the elastic log strains (e1, e2).

    W = (mu/2)(exp(2 e1) + exp(2 e2) + exp(-2 e1 - 2 e2) - 3) [Pa]; returns
    (W, f1, f2, f11, f12, f22), arrays of the broadcast shape of the inputs.
    """
    x1, x2, x3 = np.exp(2.0 * e1), np.exp(2.0 * e2), np.exp(-2.0 * (e1 + e2))
    w = 0.5 * mu * (x1 + x2 + x3 - 3.0)
    f1, f2 = mu * (x1 - x3), mu * (x2 - x3)
    f11, f22, f12 = 2.0 * mu * (x1 + x3), 2.0 * mu * (x2 + x3), 2.0 * mu * x3
    return w, f1, f2, f11, f12, f22


class ViscousNetworks(DensityTerm):
    """Non-equilibrium neo-Hookean networks with their internal stretches, one pair per edge and network.

    The term is stateful: ``zeta`` (K, 2, E) holds the committed log internal stretches ln xi of
    the networks (meridional, hoop) on every edge, zero (xi = 1) for a fresh membrane. The time
    stepper opens a step with :meth:`begin_step` (its length h and the anchor zeta_hat), reads the
    step's internal stretches with :meth:`internal`, commits with :meth:`commit` and closes with
    :meth:`end_step`; outside a step the term is its static ``limit``.

    Parameters
    ----------
    moduli : sequence of float
        Shear moduli mu_k of the networks [Pa], > 0.
    times : sequence of float
        Relaxation times tau_k [s], > 0, one per modulus.
    limit : {'relaxed', 'instantaneous'}
        What the term is outside a time step (statics).
    """

    def __init__(self, moduli, times, limit: str = "relaxed"):
        moduli = [moduli] if np.ndim(moduli) == 0 else list(moduli)
        times = [times] if np.ndim(times) == 0 else list(times)
        if len(moduli) != len(times) or not moduli:
            raise SnapmemError(f"viscous_mu = {moduli!r}, relaxation_time = {times!r}: give one relaxation "
                               "time per network modulus (as many values in each, at least one)")
        self.moduli = np.array([check_real(f"viscous_mu[{i}]", m, minimum=0.0, min_inclusive=False)
                                for i, m in enumerate(moduli)])
        self.times = np.array([check_real(f"relaxation_time[{i}]", t, minimum=0.0, min_inclusive=False)
                               for i, t in enumerate(times)])
        if limit not in VISCOUS_LIMITS:
            raise SnapmemError(f"viscous_limit = {limit!r}: must be one of {', '.join(VISCOUS_LIMITS)}")
        self.limit = limit
        self.viscosities = self.moduli * self.times          # eta_k [Pa s]
        self.zeta: np.ndarray | None = None                  # (K, 2, E), set on first use
        self._step: tuple[float, np.ndarray] | None = None    # (h, zeta_hat) inside a time step
        self._warm: np.ndarray | None = None                  # the last local solution (a Newton start)

    @property
    def networks(self) -> int:
        return self.moduli.size

    # ------------------------------------------------------------------------------------------
    # state
    def state(self, edges: int) -> np.ndarray:
        """The committed log internal stretches (K, 2, E) (zeros, xi = 1, until a step commits)."""
        if self.zeta is None or self.zeta.shape[2] != edges:
            self.zeta = np.zeros((self.networks, 2, edges))
        return self.zeta

    def reset(self, zeta: np.ndarray | None = None) -> None:
        """Forget the history: internal stretches back to 1 (or to exp(``zeta``))."""
        self.zeta = None if zeta is None else np.array(zeta, dtype=float)
        self._step = self._warm = None

    def begin_step(self, h: float, zeta_hat: np.ndarray) -> None:
        """Open a time step: the incremental potential of step h [s] anchored at zeta_hat (K, 2, E)."""
        self._step = (float(h), np.asarray(zeta_hat, dtype=float))
        self._warm = None

    def end_step(self) -> None:
        self._step = self._warm = None

    def commit(self, zeta: np.ndarray) -> None:
        """Take ``zeta`` (K, 2, E) as the new state (after an accepted step)."""
        self.zeta = np.array(zeta, dtype=float)

    # ------------------------------------------------------------------------------------------
    # the local problem
    def internal(self, kin: EdgeKinematics) -> np.ndarray:
        """zeta*(lam) (K, 2, E) of the open step: the minimiser of the incremental potential."""
        if self._step is None:
            raise SnapmemError("ViscousNetworks.internal: no time step is open (begin_step first)")
        h, zeta_hat = self._step
        eps = np.log(np.stack([kin.lam1, kin.lam2]))            # (2, E)
        mu = self.moduli[:, None, None]
        c = (self.viscosities / h)[:, None]                        # eta_k / h, (K, 1)
        zeta = (self._warm if self._warm is not None and self._warm.shape == zeta_hat.shape else zeta_hat).copy()
        for _ in range(_LOCAL_MAX_ITERATIONS):
            e = eps[None] - zeta
            _, f1, f2, f11, f12, f22 = network_log_derivatives(e[:, 0], e[:, 1], mu[:, 0])
            d = zeta - zeta_hat
            g1 = -f1 + c * (4.0 * d[:, 0] + 2.0 * d[:, 1])
            g2 = -f2 + c * (2.0 * d[:, 0] + 4.0 * d[:, 1])
            k11, k12, k22 = f11 + 4.0 * c, f12 + 2.0 * c, f22 + 4.0 * c
            det = k11 * k22 - k12 * k12
            step1 = (k22 * g1 - k12 * g2) / det
            step2 = (k11 * g2 - k12 * g1) / det
            zeta[:, 0] -= step1
            zeta[:, 1] -= step2
            if max(np.abs(step1).max(), np.abs(step2).max()) < _LOCAL_TOL:
                break
        else:
            raise SnapmemError("viscous networks: the local flow-rule solve did not converge "
                               f"in {_LOCAL_MAX_ITERATIONS} iterations (stretches out of range?)")
        self._warm = zeta
        return zeta

    def step_dissipation(self, zeta_new_mid: np.ndarray, dt: float, weight: np.ndarray) -> float:
        """Energy dissipated by the dashpots over a step of length dt [s] [J].

        dt eta_k r^T A r summed over networks and edges (weighted by the edges' reference volumes
        ``weight`` (E,) [m^3]), with r = (zeta* - zeta_hat) / h the step's flow rate."""
        h, zeta_hat = self._step
        r = (zeta_new_mid - zeta_hat) / h
        quad = 4.0 * r[:, 0] ** 2 + 4.0 * r[:, 0] * r[:, 1] + 4.0 * r[:, 1] ** 2
        return float(dt * np.sum(self.viscosities[:, None] * quad * weight[None]))

    # ------------------------------------------------------------------------------------------
    # the density
    def density(self, kin, loads) -> Density:
        """The condensed incremental potential in a time step; else the static ``limit``."""
        zero = 0.0 * kin.lam1
        if self._step is None and self.limit == "relaxed":
            return Density(zero, zero, zero, zero, zero, zero)
        lam = np.stack([kin.lam1, kin.lam2])
        eps = np.log(lam)
        zeta = self.state(kin.lam1.size) if self._step is None else self.internal(kin)
        e = eps[None] - zeta
        mu = self.moduli[:, None]
        w, f1, f2, f11, f12, f22 = network_log_derivatives(e[:, 0], e[:, 1], mu)
        if self._step is not None:                     # condense: f_ee - f_ee (f_ee + c A)^-1 f_ee
            h, zeta_hat = self._step
            c = (self.viscosities / h)[:, None]
            d = zeta - zeta_hat
            w = w + 0.5 * c * (4.0 * d[:, 0] ** 2 + 4.0 * d[:, 0] * d[:, 1] + 4.0 * d[:, 1] ** 2)
            k11, k12, k22 = f11 + 4.0 * c, f12 + 2.0 * c, f22 + 4.0 * c
            det = k11 * k22 - k12 * k12
            i11, i12, i22 = k22 / det, -k12 / det, k11 / det
            # F K^-1 F with F = [[f11, f12], [f12, f22]] symmetric
            a11, a12 = f11 * i11 + f12 * i12, f11 * i12 + f12 * i22
            a21, a22 = f12 * i11 + f22 * i12, f12 * i12 + f22 * i22
            s11 = a11 * f11 + a12 * f12
            s12 = a11 * f12 + a12 * f22
            s22 = a21 * f12 + a22 * f22
            f11, f12, f22 = f11 - s11, f12 - s12, f22 - s22
        # sum the networks, then log strains -> stretches: w_i = f_i / lam_i,
        # w_ij = (f_ij - delta_ij f_i) / (lam_i lam_j)
        w, f1, f2, f11, f12, f22 = (x.sum(axis=0) for x in (w, f1, f2, f11, f12, f22))
        l1, l2 = kin.lam1, kin.lam2
        return Density(w, f1 / l1, f2 / l2, (f11 - f1) / (l1 * l1), f12 / (l1 * l2), (f22 - f2) / (l2 * l2))

    def compiled(self, scene):
        """None: the compiled time step does not cover the viscous networks (the general path runs)."""
        return None


def viscous_terms(scene) -> list:
    """The scene's :class:`ViscousNetworks` terms."""
    return [t for t in scene.terms if isinstance(t, ViscousNetworks)]
