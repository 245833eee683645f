"""The strain-energy formulas the compiled kernels evaluate, each written once as a scalar
compiled function: the numpy laws and terms of snapmem.model call the same function's Python
original (``.py_func``, which takes arrays), the compiled assembly calls it per edge.

A law the compiled time step covers is a *kind* here (:data:`LAW_LINEAR`, :data:`LAW_GENT`) with
its parameters; :func:`law_density` and :func:`law_admissible` branch on it. Adding a kind is its
scalar formula, one branch in each of those two functions and the law's declaration
(:meth:`snapmem.model.terms.Stretching.compiled`).
"""

from __future__ import annotations

import numpy as np
from snapmem._lazy import njit

from snapmem.kernels.assembly import invariant_chain, linear_law_density

#: Law kinds of the compiled density: any law linear in I1 and I2 (parameters: its constant
#: dW/dI1, dW/dI2), and Gent (parameters: mu, Jlim).
LAW_LINEAR, LAW_GENT = 0, 1


@njit(cache=True, nogil=True, inline="always")
def first_invariant(l1, l2):
    """I1 = lam1^2 + lam2^2 + 1 / (lam1 lam2)^2 of the incompressible membrane."""
    a2, b2 = l1 * l1, l2 * l2
    return a2 + b2 + 1.0 / (a2 * b2)


@njit(cache=True, nogil=True, inline="always")
def gent_invariants(I1, mu, jlim):
    """Gent's W = -(mu Jlim / 2) ln(1 - (I1 - 3) / Jlim) with dW/dI1 and d2W/dI1^2: (W, W1, W11) [Pa]
    (its I2 derivatives are zero). Finite while I1 - 3 < Jlim."""
    s = 1.0 - (I1 - 3.0) / jlim           # > 0 inside the domain
    W1 = 0.5 * mu / s
    return -0.5 * mu * jlim * np.log(s), W1, W1 / (s * jlim)


@njit(cache=True, nogil=True, inline="always")
def electric_density(l1, l2, a):
    """The electric term's density -a lam1^2 lam2^2 (a = eps phi^2 / (2 H^2) [Pa]) and its
    derivatives in (lam1, lam2): (w, w1, w2, w11, w12, w22)."""
    p = l1 * l2
    return (-a * (p * p), -2.0 * a * l1 * l2 * l2, -2.0 * a * l1 * l1 * l2,
            -2.0 * a * l2 * l2, -4.0 * a * l1 * l2, -2.0 * a * l1 * l1)


@njit(cache=True, nogil=True)
def prestretch_chain(w, w1, w2, w11, w12, w22, lp1, lp2):
    """A density of the total stretches Lam_i = lp_i lam_i as one of the mounted stretches lam_i
    (snapmem.model.prestretch): the first derivatives times lp_i, the second times lp_i lp_j."""
    return w, lp1 * w1, lp2 * w2, lp1 * lp1 * w11, lp1 * lp2 * w12, lp2 * lp2 * w22


@njit(cache=True, nogil=True)
def law_density(lam1, lam2, kind, params):
    """The law's (w, w1, w2, w11, w12, w22), each (E,), for a law of ``kind`` with ``params``."""
    if kind == LAW_LINEAR:
        return linear_law_density(lam1, lam2, params[0], params[1])
    n = lam1.size                                       # LAW_GENT
    w, W1, W11, zero = np.empty(n), np.empty(n), np.empty(n), np.zeros(n)
    for e in range(n):
        w[e], W1[e], W11[e] = gent_invariants(first_invariant(lam1[e], lam2[e]), params[0], params[1])
    w1, w2, w11, w12, w22 = invariant_chain(lam1, lam2, W1, zero, W11, zero, zero)
    return w, w1, w2, w11, w12, w22


@njit(cache=True, nogil=True)
def law_admissible(lam1, lam2, kind, params):
    """Whether every edge's stretches are inside the law's domain (positive; Gent: short of its lock)."""
    if kind != LAW_GENT:
        return True
    for e in range(lam1.size):
        if not (lam1[e] > 0.0 and lam2[e] > 0.0 and first_invariant(lam1[e], lam2[e]) - 3.0 < params[1]):
            return False
    return True
