"""The viscous networks' formulas (snapmem.model.viscous documents the model), each written once as a
compiled function on arrays: the numpy term calls the Python original (``.py_func``), the compiled
time step (snapmem.dynamics.compiled_assembly) the compiled one.

A network k has the energy W_k(a1, a2) of its elastic stretches a_i = lam_i / xi_ki, neo-Hookean
(``jlim`` = inf) or Gent with the lock ``jlim``, written in the elastic log strains e_i = eps_i -
zeta_i (eps_i = ln lam_i, zeta_i = ln xi_i). In a time step of length h from the anchor zeta_hat
its incremental potential is W_k(e) + (c / 2)(zeta - zeta_hat)^T A (zeta - zeta_hat), c = eta_k / h,
A = [[4, 2], [2, 4]]; :func:`network_internal` minimises it in zeta (the implicit flow rule) and
:func:`network_condensed` gives the condensed density and its derivatives in the log strains.
"""

from __future__ import annotations

import numpy as np
from snapmem._lazy import njit

from snapmem.kernels.assembly import edge_stretches

#: The local Newton's accuracy in the internal log stretches: it ends after a correction below
#: LOCAL_STEP = sqrt(LOCAL_TOL), since it converges quadratically (the remaining error is about the
#: correction squared: another iteration would move zeta by rounding only) ...
LOCAL_TOL = 1e-14
LOCAL_STEP = 1e-7
#: ... or fails after this many iterations.
LOCAL_MAX_ITERATIONS = 50


@njit(cache=True, nogil=True, inline="always")
def network_log_derivatives(e1, e2, mu, jlim):
    """W of a network and its derivatives in the elastic log strains (e1, e2): (W, f1, f2, f11, f12, f22) [Pa].

    Neo-Hookean for ``jlim`` = inf, W = (mu/2)(I1 - 3); Gent otherwise, W = -(mu jlim / 2) ln(1 -
    (I1 - 3) / jlim); I1 = exp(2 e1) + exp(2 e2) + exp(-2 e1 - 2 e2). Arrays or numbers.
    """
    return network_exp_derivatives(np.exp(2.0 * e1), np.exp(2.0 * e2), np.exp(-2.0 * (e1 + e2)), mu, jlim)


@njit(cache=True, nogil=True, inline="always")
def network_exp_derivatives(x1, x2, x3, mu, jlim):
    """:func:`network_log_derivatives` from the squared elastic stretches x1 = exp(2 e1), x2 =
    exp(2 e2), x3 = exp(-2 e1 - 2 e2) (so that a local solve can update them without exponentials)."""
    if jlim == np.inf:
        w = 0.5 * mu * (x1 + x2 + x3 - 3.0)
        f1, f2 = mu * (x1 - x3), mu * (x2 - x3)
        f11, f22, f12 = 2.0 * mu * (x1 + x3), 2.0 * mu * (x2 + x3), 2.0 * mu * x3
        return w, f1, f2, f11, f12, f22
    s = 1.0 - (x1 + x2 + x3 - 3.0) / jlim           # > 0 short of the lock
    W1 = 0.5 * mu / s                                # dW/dI1
    W11 = W1 / (s * jlim)                            # d2W/dI1^2
    i1, i2 = 2.0 * (x1 - x3), 2.0 * (x2 - x3)        # dI1/de
    i11, i22, i12 = 4.0 * (x1 + x3), 4.0 * (x2 + x3), 4.0 * x3
    w = -0.5 * mu * jlim * np.log(s)
    return (w, W1 * i1, W1 * i2, W11 * i1 * i1 + W1 * i11, W11 * i1 * i2 + W1 * i12,
            W11 * i2 * i2 + W1 * i22)


#: Below this |s|, :func:`exp_twice` sums exp(2 s)'s series to its (2 s)^5 term: the rest, below
#: (2e-3)^6 / 720 ~ 1e-19, is under the rounding of the result.
SERIES_BELOW = 1e-3


@njit(cache=True, nogil=True, inline="always")
def exp_twice(s):
    """exp(2 s) (a number): its series where |s| < :data:`SERIES_BELOW` (the local Newton's late,
    small corrections), np.exp otherwise."""
    if abs(s) < SERIES_BELOW:
        t = 2.0 * s
        return 1.0 + t * (1.0 + t * (0.5 + t * (1.0 / 6.0 + t * (1.0 / 24.0 + t * (1.0 / 120.0)))))
    return np.exp(2.0 * s)


@njit(cache=True, nogil=True, inline="always")
def flow_newton_step(eps1, eps2, z1, z2, zhat1, zhat2, mu, jlim, c):
    """One Newton correction (dz1, dz2) of the implicit flow rule at the internal log stretches
    (z1, z2): the step's incremental potential's gradient in zeta, -f_e + c A (zeta - zeta_hat),
    solved with its Hessian f_ee + c A (positive definite). Numbers or arrays."""
    _, f1, f2, f11, f12, f22 = network_log_derivatives(eps1 - z1, eps2 - z2, mu, jlim)
    return flow_correction(f1, f2, f11, f12, f22, z1 - zhat1, z2 - zhat2, c)


@njit(cache=True, nogil=True, inline="always")
def flow_correction(f1, f2, f11, f12, f22, d1, d2, c):
    """:func:`flow_newton_step`'s correction from the network's derivatives (f1, f2, f11, f12, f22)
    at zeta and d = zeta - zeta_hat."""
    g1 = -f1 + c * (4.0 * d1 + 2.0 * d2)
    g2 = -f2 + c * (2.0 * d1 + 4.0 * d2)
    k11, k12, k22 = f11 + 4.0 * c, f12 + 2.0 * c, f22 + 4.0 * c
    det = k11 * k22 - k12 * k12
    return (k22 * g1 - k12 * g2) / det, (k11 * g2 - k12 * g1) / det


@njit(cache=True, nogil=True)
def network_internal(eps1, eps2, zeta1, zeta2, zhat1, zhat2, mu, jlim, c):
    """The implicit flow rule of one network on every edge: Newton (:func:`flow_newton_step`) on the
    step's incremental potential in zeta from (zeta1, zeta2), until every correction is below
    :data:`LOCAL_STEP` (then within about :data:`LOCAL_TOL` of the solution; convex: its Hessian f_ee + c A is positive definite).

    eps1, eps2, zeta1, zeta2, zhat1, zhat2 : (E,) the log stretches, the start, the anchor; mu,
    jlim the network's modulus [Pa] and lock; c = eta / h [Pa]. Returns (zeta1, zeta2, converged).
    """
    z1, z2 = zeta1.copy(), zeta2.copy()
    for _ in range(LOCAL_MAX_ITERATIONS):
        step1, step2 = flow_newton_step(eps1, eps2, z1, z2, zhat1, zhat2, mu, jlim, c)
        z1 = z1 - step1
        z2 = z2 - step2
        if max(np.max(np.abs(step1)), np.max(np.abs(step2))) < LOCAL_STEP:
            return z1, z2, True
    return z1, z2, False


@njit(cache=True, nogil=True, inline="always")
def network_condensed(eps1, eps2, zeta1, zeta2, zhat1, zhat2, mu, jlim, c):
    """One network's density in the log strains eps at its internal log stretches zeta: (w, f1, f2,
    f11, f12, f22) [Pa].

    c > 0 (in a step, zeta the minimiser of :func:`network_internal`): the condensed incremental
    potential, w + (c/2) d^T A d with d = zeta - zeta_hat, gradient f_e (envelope theorem) and
    Hessian f_ee - f_ee (f_ee + c A)^-1 f_ee. c = 0: the network with zeta held (no condensation).
    """
    w, f1, f2, f11, f12, f22 = network_log_derivatives(eps1 - zeta1, eps2 - zeta2, mu, jlim)
    if c == 0.0:
        return w, f1, f2, f11, f12, f22
    return condense(w, f1, f2, f11, f12, f22, zeta1 - zhat1, zeta2 - zhat2, c)


@njit(cache=True, nogil=True, inline="always")
def condense(w, f1, f2, f11, f12, f22, d1, d2, c):
    """The condensed incremental potential of :func:`network_condensed` from the network's density
    (w, f1, f2, f11, f12, f22) at zeta* and d = zeta* - zeta_hat, c = eta / h > 0."""
    w = w + 0.5 * c * (4.0 * d1 * d1 + 4.0 * d1 * d2 + 4.0 * d2 * d2)
    k11, k12, k22 = f11 + 4.0 * c, f12 + 2.0 * c, f22 + 4.0 * c
    det = k11 * k22 - k12 * k12
    i11, i12, i22 = k22 / det, -k12 / det, k11 / det
    # F K^-1 F with F = [[f11, f12], [f12, f22]] symmetric
    a11, a12 = f11 * i11 + f12 * i12, f11 * i12 + f12 * i22
    a21, a22 = f12 * i11 + f22 * i12, f12 * i12 + f22 * i22
    s11 = a11 * f11 + a12 * f12
    s12 = a11 * f12 + a12 * f22
    s22 = a21 * f12 + a22 * f22
    return w, f1, f2, f11 - s11, f12 - s12, f22 - s22


@njit(cache=True, nogil=True, inline="always")
def edge_condensed(lam1, lam2, z1, z2, u1, u2, zhat1, zhat2, mu, jlim, c):
    """One network on one edge at the stretches (lam1, lam2) (numbers), the compiled step's: the implicit flow rule
    (:func:`network_internal`'s Newton and stopping rule, from (z1, z2)) and then the condensed
    density there (:func:`network_condensed`), fused. The squared elastic stretches x_i =
    exp(2 e_i) are computed once and then follow each correction s (e = eps - zeta grows by s):
    x_i exp(2 s_i) by :func:`exp_twice`, x3 = 1 / (x1 x2), so that the late iterations and the
    final evaluation need no exponential (the numbers are :func:`network_condensed`'s at the
    solution to rounding). They start from the stretches (lam1, lam2) and the start's u_i =
    exp(-2 zeta_i) (kept with zeta from the last solve, which updates it likewise), x_i = lam_i^2
    u_i: neither a log strain (a logarithm) nor an exponential is needed but for large corrections.
    c = 0: zeta held at zeta_hat, no solve (u_i ignored).

    Returns (zeta1, zeta2, u1, u2, converged, w, f1, f2, f11, f12, f22)."""
    if c == 0.0:
        x1, x2 = lam1 * lam1 * np.exp(-2.0 * zhat1), lam2 * lam2 * np.exp(-2.0 * zhat2)
        w, f1, f2, f11, f12, f22 = network_exp_derivatives(x1, x2, 1.0 / (x1 * x2), mu, jlim)
        return zhat1, zhat2, u1, u2, True, w, f1, f2, f11, f12, f22
    x1, x2 = lam1 * lam1 * u1, lam2 * lam2 * u2
    x3 = 1.0 / (x1 * x2)
    done = False
    for _ in range(LOCAL_MAX_ITERATIONS):
        _, f1, f2, f11, f12, f22 = network_exp_derivatives(x1, x2, x3, mu, jlim)
        step1, step2 = flow_correction(f1, f2, f11, f12, f22, z1 - zhat1, z2 - zhat2, c)
        z1 -= step1
        z2 -= step2
        grow1, grow2 = exp_twice(step1), exp_twice(step2)
        u1 *= grow1
        u2 *= grow2
        x1 *= grow1
        x2 *= grow2
        x3 = 1.0 / (x1 * x2)
        if max(abs(step1), abs(step2)) < LOCAL_STEP:
            done = True
            break
    w, f1, f2, f11, f12, f22 = network_exp_derivatives(x1, x2, x3, mu, jlim)
    w, f1, f2, f11, f12, f22 = condense(w, f1, f2, f11, f12, f22, z1 - zhat1, z2 - zhat2, c)
    return z1, z2, u1, u2, done, w, f1, f2, f11, f12, f22


@njit(cache=True, nogil=True, inline="always")
def log_to_stretch(lam1, lam2, w, f1, f2, f11, f12, f22):
    """A density's derivatives in the log strains as derivatives in the stretches: w_i = f_i / lam_i,
    w_ij = (f_ij - delta_ij f_i) / (lam_i lam_j). Returns (w, w1, w2, w11, w12, w22)."""
    return (w, f1 / lam1, f2 / lam2, (f11 - f1) / (lam1 * lam1), f12 / (lam1 * lam2),
            (f22 - f2) / (lam2 * lam2))


@njit(cache=True, nogil=True)
def step_dissipation(zeta_star, zeta_hat, h, dt, viscosities, weight):
    """Energy the dashpots dissipate over a step of length dt [s] [J]: dt eta_k r^T A r summed over
    networks k and edges (weighted by the edges' reference volumes ``weight`` (E,) [m^3]), with
    r = (zeta* - zeta_hat) / h the step's flow rate; zeta_star, zeta_hat (K, 2, E)."""
    total = 0.0
    for k in range(zeta_star.shape[0]):
        for e in range(zeta_star.shape[2]):
            r1 = (zeta_star[k, 0, e] - zeta_hat[k, 0, e]) / h
            r2 = (zeta_star[k, 1, e] - zeta_hat[k, 1, e]) / h
            total += viscosities[k] * (4.0 * r1 * r1 + 4.0 * r1 * r2 + 4.0 * r2 * r2) * weight[e]
    return dt * total


@njit(cache=True, nogil=True)
def stored_energy(lam1, lam2, zeta, moduli, jlims, weight):
    """The networks' elastic energy [J] at the stretches (lam1, lam2) (E,) with their internal log
    stretches ``zeta`` (K, 2, E) held, weighted by the edges' reference volumes ``weight`` (E,) [m^3]."""
    total = 0.0
    for e in range(lam1.size):
        eps1, eps2 = np.log(lam1[e]), np.log(lam2[e])
        for k in range(zeta.shape[0]):
            total += weight[e] * network_log_derivatives(eps1 - zeta[k, 0, e], eps2 - zeta[k, 1, e], moduli[k],
                                                         jlims[k])[0]
    return total


@njit(cache=True, nogil=True)
def stored_energy_frames(Q, edges, inv_length, inv_mid_radius, zetas, moduli, jlims, weight):
    """:func:`stored_energy` of every frame (T,) [J]: the states Q (T, n) (their stretches by
    snapmem.kernels.assembly.edge_stretches) with the frames' internal log stretches ``zetas``
    (T, K, 2, E), in one call."""
    energy = np.empty(Q.shape[0])
    for t in range(Q.shape[0]):
        lam1, lam2 = edge_stretches(Q[t], edges, inv_length, inv_mid_radius)
        energy[t] = stored_energy(lam1, lam2, zetas[t], moduli, jlims, weight)
    return energy


@njit(cache=True, nogil=True)
def anchor_internal(zeta, previous, c_now, c_previous, out):
    """A time step's anchor of the internal log stretches, zeta_hat = c_now zeta_n + c_previous
    zeta_{n-1} (every array (K, 2, E); the scheme's coefficients), written into ``out``."""
    for k in range(zeta.shape[0]):
        for i in range(2):
            for e in range(zeta.shape[2]):
                out[k, i, e] = c_now * zeta[k, i, e] + c_previous * previous[k, i, e]


@njit(cache=True, nogil=True)
def update_internal(star, zeta, previous, n_star, n_now, n_previous, zeta_hat, h, dt, viscosities, weight, out):
    """A solved step's new internal log stretches, zeta_{n+1} = n_star zeta* + n_now zeta_n +
    n_previous zeta_{n-1} (the scheme's coefficients; every array (K, 2, E)), written into
    ``out``; returns the energy the dashpots dissipated over the step [J] (:func:`step_dissipation`
    of zeta* from the anchor ``zeta_hat`` with the step h [s], over dt [s])."""
    for k in range(zeta.shape[0]):
        for i in range(2):
            for e in range(zeta.shape[2]):
                out[k, i, e] = n_star * star[k, i, e] + n_now * zeta[k, i, e] + n_previous * previous[k, i, e]
    return step_dissipation(star, zeta_hat, h, dt, viscosities, weight)
