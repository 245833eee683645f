"""Viscoelastic membranes: non-equilibrium networks in series with dashpots (a Zener-type model).

The membrane's law is the *equilibrium network*. Each non-equilibrium network k adds, per unit
reference volume, a neo-Hookean energy of the elastic part of the stretch,

    W_k = (mu_k / 2) (a1^2 + a2^2 + a1^-2 a2^-2 - 3),    a_i = lam_i / xi_ki,

or a Gent one, -(mu_k Jlim_k / 2) ln(1 - (I1(a) - 3) / Jlim_k), for a finite lock Jlim_k
(``viscous_Jlim``); the formulas are snapmem.kernels.viscous's, which the compiled time step
evaluates too,

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

from snapmem._lazy import python_of
from snapmem.errors import SnapmemError, check_real
from snapmem.kernels import viscous as _kernel
from snapmem.kernels.switch import compiled
from snapmem.model.kinematics import EdgeKinematics
from snapmem.model.materials import Density
from snapmem.model.terms import DensityTerm, ViscousDeclaration

#: The static limits of a viscoelastic law.
VISCOUS_LIMITS = ("relaxed", "instantaneous")

#: The flow rule's metric (the small-strain stiffness of a neo-Hookean network in log strains / mu).
FLOW_METRIC = np.array([[4.0, 2.0], [2.0, 4.0]])



def network_log_derivatives(e1, e2, mu, jlim=np.inf):
    """W_k and its first and second derivatives in the elastic log strains (e1, e2): (W, f1, f2,
    f11, f12, f22) [Pa], neo-Hookean (``jlim`` inf) or Gent (snapmem.kernels.viscous)."""
    return python_of(_kernel.network_log_derivatives)(e1, e2, mu, jlim)


class ViscousNetworks(DensityTerm):
    """Non-equilibrium networks (neo-Hookean or Gent) with their internal stretches, one pair per edge and network.

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
    jlims : sequence of float, optional
        Gent locks Jlim_k of the networks (> 0; inf, the default, is neo-Hookean), one per modulus.
    """

    def __init__(self, moduli, times, limit: str = "relaxed", jlims=None):
        moduli = [moduli] if np.ndim(moduli) == 0 else list(moduli)
        times = [times] if np.ndim(times) == 0 else list(times)
        if len(moduli) != len(times) or not moduli:
            raise SnapmemError(f"viscous_mu = {moduli!r}, relaxation_time = {times!r}: give one relaxation "
                               "time per network modulus (as many values in each, at least one)")
        self.moduli = np.array([check_real(f"viscous_mu[{i}]", m, minimum=0.0, min_inclusive=False)
                                for i, m in enumerate(moduli)])
        self.times = np.array([check_real(f"relaxation_time[{i}]", t, minimum=0.0, min_inclusive=False)
                               for i, t in enumerate(times)])
        jlims = [np.inf] * len(moduli) if jlims is None else ([jlims] if np.ndim(jlims) == 0 else list(jlims))
        if len(jlims) != len(moduli):
            raise SnapmemError(f"viscous_Jlim = {jlims!r}: give one Gent lock per network modulus "
                               f"({len(moduli)} values; inf is neo-Hookean)")
        self.jlims = np.array([np.inf if j == np.inf else check_real(f"viscous_Jlim[{i}]", j, minimum=0.0,
                                                                     min_inclusive=False)
                               for i, j in enumerate(jlims)])
        if limit not in VISCOUS_LIMITS:
            raise SnapmemError(f"viscous_limit = {limit!r}: must be one of {', '.join(VISCOUS_LIMITS)}")
        self.limit = limit
        self.viscosities = self.moduli * self.times          # eta_k [Pa s]
        self.zeta: np.ndarray | None = None                  # (K, 2, E), set on first use
        self._step: tuple[float, np.ndarray] | None = None    # (h, zeta_hat) inside a time step
        self._warm: np.ndarray | None = None                  # the last local solution (a Newton start)
        self._solved: tuple | None = None                     # (y, zeta*(y)) handed over by the compiled step

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
        self._step = self._warm = self._solved = None

    def begin_step(self, h: float, zeta_hat: np.ndarray) -> None:
        """Open a time step: the incremental potential of step h [s] anchored at zeta_hat (K, 2, E)."""
        self._step = (float(h), np.asarray(zeta_hat, dtype=float))
        self._warm = self._solved = None

    def end_step(self) -> None:
        self._step = self._warm = self._solved = None

    @property
    def open_step(self) -> tuple[float, np.ndarray] | None:
        """(h [s], zeta_hat (K, 2, E)) of the open time step, or None outside a step."""
        return self._step

    def hand_over(self, y: np.ndarray, zeta: np.ndarray) -> None:
        """The step's solve (the compiled one) ended at y with the internal stretches ``zeta`` (K, 2,
        E) = zeta*(y): :meth:`internal_at` ``y`` returns them without solving again."""
        self._solved = (y, zeta)

    def commit(self, zeta: np.ndarray) -> None:
        """Take ``zeta`` (K, 2, E) as the new state (after an accepted step). The array is kept, not
        copied: the stepper writes it again only once it is neither the state nor the history."""
        self.zeta = np.asarray(zeta, dtype=float)

    # ------------------------------------------------------------------------------------------
    # the local problem
    def _coefficients(self, h: float) -> np.ndarray:
        """c_k = eta_k / h [Pa] of a step of length h."""
        return self.viscosities / h

    def internal(self, kin: EdgeKinematics) -> np.ndarray:
        """zeta*(lam) (K, 2, E) of the open step: the minimiser of the incremental potential."""
        if self._step is None:
            raise SnapmemError("ViscousNetworks.internal: no time step is open (begin_step first)")
        h, zeta_hat = self._step
        eps1, eps2 = np.log(kin.lam1), np.log(kin.lam2)
        start = self._warm if self._warm is not None and self._warm.shape == zeta_hat.shape else zeta_hat
        zeta = np.empty_like(zeta_hat)
        for k, c in enumerate(self._coefficients(h)):
            z1, z2, ok = python_of(_kernel.network_internal)(eps1, eps2, start[k, 0], start[k, 1], zeta_hat[k, 0],
                                                             zeta_hat[k, 1], self.moduli[k], self.jlims[k], c)
            if not ok:
                raise SnapmemError("viscous networks: the local flow-rule solve did not converge in "
                                   f"{_kernel.LOCAL_MAX_ITERATIONS} iterations (stretches out of range?)")
            zeta[k, 0], zeta[k, 1] = z1, z2
        self._warm = zeta
        return zeta

    def internal_at(self, y: np.ndarray, scene) -> np.ndarray:
        """zeta*(y) of the open step at the state y of ``scene``: the compiled solve's hand-over
        (:meth:`hand_over`) if it ended at this very y, else :meth:`internal`."""
        if self._solved is not None and self._solved[0] is y:
            return self._solved[1]
        return self.internal(scene.kinematics(y))

    def stored_energy(self, kin: EdgeKinematics, zeta: np.ndarray, weight: np.ndarray) -> float:
        """The networks' elastic energy [J] at the stretches ``kin`` with the internal log stretches
        ``zeta`` (K, 2, E) held, weighted by the edges' reference volumes ``weight`` (E,) [m^3]."""
        kernel = _kernel.stored_energy if compiled() else _kernel.stored_energy.py_func
        return float(kernel(kin.lam1, kin.lam2, np.ascontiguousarray(zeta), self.moduli, self.jlims, weight))

    # ------------------------------------------------------------------------------------------
    # the density
    def density(self, kin, loads) -> Density:
        """The condensed incremental potential in a time step; else the static ``limit``."""
        zero = 0.0 * kin.lam1
        if self._step is None and self.limit == "relaxed":
            return Density(zero, zero, zero, zero, zero, zero)
        eps1, eps2 = np.log(kin.lam1), np.log(kin.lam2)
        if self._step is None:
            zeta, zeta_hat, coefficients = self.state(kin.lam1.size), None, np.zeros(self.networks)
        else:
            zeta, (h, zeta_hat) = self.internal(kin), self._step
            coefficients = self._coefficients(h)
        total = [0.0 * zero for _ in range(6)]
        for k, c in enumerate(coefficients):
            hat = zeta[k] if zeta_hat is None else zeta_hat[k]
            parts = python_of(_kernel.network_condensed)(eps1, eps2, zeta[k, 0], zeta[k, 1], hat[0], hat[1],
                                                         self.moduli[k], self.jlims[k], c)
            total = [t + x for t, x in zip(total, parts)]
        # the networks summed, then log strains -> stretches
        return Density(*_kernel.log_to_stretch.py_func(kin.lam1, kin.lam2, *total))

    def compiled(self, scene):
        """The networks' declaration for the compiled time step (which reads the open step from the term)."""
        return ViscousDeclaration(self)


def viscous_terms(scene) -> list:
    """The scene's :class:`ViscousNetworks` terms."""
    return [t for t in scene.terms if isinstance(t, ViscousNetworks)]
