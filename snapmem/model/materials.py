"""Hyperelastic laws: a strain energy density W(lam1, lam2) and its derivatives.

A law is a small object with ``density(lam1, lam2)`` returning a :class:`Density`: W per unit
reference volume and its first and second derivatives in the two in-plane principal stretches
(thickness stretch eliminated by incompressibility, lam3 = 1 / (lam1 lam2)). Arrays of shape (E,).

Laws written in the invariants I1, I2 subclass :class:`InvariantLaw` and give only dW/dI and
d2W/dI2; the chain rule to (lam1, lam2) is written once, here. Adding a law is one small class
plus one line in ``LAWS``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from snapmem.errors import SnapmemError, check_real
from snapmem.kernels.assembly import invariant_chain, linear_law_density
from snapmem.kernels.laws import first_invariant, gent_invariants
from snapmem.kernels.switch import compiled


def _compilable(lam1, lam2) -> bool:
    """Whether the compiled chain rule (snapmem.kernels.assembly.invariant_chain) applies: two 1D
    float64 arrays of one shape, off the reference path (else numpy, which takes scalars and any
    shape: the reference the tests compare with)."""
    return (compiled() and isinstance(lam1, np.ndarray) and isinstance(lam2, np.ndarray) and lam1.ndim == 1
            and lam1.dtype == np.float64 and lam2.dtype == np.float64 and lam1.shape == lam2.shape)


@dataclass
class Density:
    """Energy per unit reference volume and its derivatives, each of shape (E,).

    ``w1 = dW/dlam1``, ``w12 = d2W/dlam1 dlam2``, and so on.
    """

    w: np.ndarray
    w1: np.ndarray
    w2: np.ndarray
    w11: np.ndarray
    w12: np.ndarray
    w22: np.ndarray

    def __add__(self, other: "Density") -> "Density":
        return Density(self.w + other.w, self.w1 + other.w1, self.w2 + other.w2,
                       self.w11 + other.w11, self.w12 + other.w12, self.w22 + other.w22)


class Law:
    """Base of all strain energy densities W(lam1, lam2) [Pa]."""

    #: initial shear modulus [Pa], used to normalise loads (E_hat, p_hat)
    mu: float

    def density(self, lam1: np.ndarray, lam2: np.ndarray) -> Density:
        raise NotImplementedError

    def admissible(self, lam1: np.ndarray, lam2: np.ndarray) -> np.ndarray:
        """Boolean mask (E,) of stretches where W is finite. Default: all positive stretches."""
        return (lam1 > 0) & (lam2 > 0)


def _full(x, like: np.ndarray) -> np.ndarray:
    """x as a float array of the shape of ``like`` (a law's constant derivative is a scalar)."""
    if type(x) is np.ndarray and x.shape == like.shape and x.dtype == np.float64:
        return x
    return np.broadcast_to(np.asarray(x, dtype=float), like.shape)


class InvariantLaw(Law):
    """A law W(I1, I2) of the first two invariants of the (incompressible) right Cauchy-Green tensor.

    Subclasses implement ``invariant_derivatives(I1, I2)`` returning
    (W, W_1, W_2, W_11, W_12, W_22), derivatives taken with respect to I1 and I2.
    """

    #: True for laws linear in I1 and I2 (neo-Hookean, Mooney-Rivlin): their second derivatives
    #: in the invariants vanish and the chain rule skips them
    linear = False

    def invariant_derivatives(self, I1, I2):
        raise NotImplementedError

    def density(self, lam1, lam2) -> Density:
        if self.linear and _compilable(lam1, lam2):
            _, W1, W2, _, _, _ = self.invariant_derivatives(3.0, 3.0)
            return Density(*linear_law_density(lam1, lam2, float(W1), float(W2)))
        a2, b2 = lam1 * lam1, lam2 * lam2
        inv = 1.0 / (a2 * b2)                      # lam3^2
        I1 = a2 + b2 + inv
        I2 = 1.0 / a2 + 1.0 / b2 + a2 * b2
        W, W1, W2, W11, W12, W22 = self.invariant_derivatives(I1, I2)
        if _compilable(lam1, lam2):
            w1, w2, w11, w12, w22 = invariant_chain(lam1, lam2, *(_full(x, lam1) for x in (W1, W2, W11, W12, W22)))
            return Density(W, w1, w2, w11, w12, w22)
        # first and second derivatives of the invariants in (lam1, lam2)
        i1_1 = 2.0 * lam1 - 2.0 * inv / lam1
        i1_2 = 2.0 * lam2 - 2.0 * inv / lam2
        i1_11 = 2.0 + 6.0 * inv / a2
        i1_12 = 4.0 * inv / (lam1 * lam2)
        i1_22 = 2.0 + 6.0 * inv / b2
        i2_1 = -2.0 / (a2 * lam1) + 2.0 * lam1 * b2
        i2_2 = -2.0 / (b2 * lam2) + 2.0 * a2 * lam2
        i2_11 = 6.0 / (a2 * a2) + 2.0 * b2
        i2_12 = 4.0 * lam1 * lam2
        i2_22 = 6.0 / (b2 * b2) + 2.0 * a2
        if self.linear:
            return Density(w=W, w1=W1 * i1_1 + W2 * i2_1, w2=W1 * i1_2 + W2 * i2_2,
                           w11=W1 * i1_11 + W2 * i2_11, w12=W1 * i1_12 + W2 * i2_12, w22=W1 * i1_22 + W2 * i2_22)
        return Density(
            w=W,
            w1=W1 * i1_1 + W2 * i2_1,
            w2=W1 * i1_2 + W2 * i2_2,
            w11=W1 * i1_11 + W2 * i2_11 + W11 * i1_1 * i1_1 + 2.0 * W12 * i1_1 * i2_1 + W22 * i2_1 * i2_1,
            w12=(W1 * i1_12 + W2 * i2_12 + W11 * i1_1 * i1_2
                 + W12 * (i1_1 * i2_2 + i2_1 * i1_2) + W22 * i2_1 * i2_2),
            w22=W1 * i1_22 + W2 * i2_22 + W11 * i1_2 * i1_2 + 2.0 * W12 * i1_2 * i2_2 + W22 * i2_2 * i2_2,
        )


@dataclass(frozen=True)
class NeoHookean(InvariantLaw):
    """Neo-Hookean law W = (mu/2)(I1 - 3).

    Attributes
    ----------
    mu : float
        Shear modulus [Pa], > 0.
    """

    mu: float
    linear = True

    def __post_init__(self):
        check_real("mu", self.mu, minimum=0.0, min_inclusive=False)

    def invariant_derivatives(self, I1, I2):
        zero = np.zeros_like(I1)
        return 0.5 * self.mu * (I1 - 3.0), 0.5 * self.mu, 0.0, zero, zero, zero


@dataclass(frozen=True)
class MooneyRivlin(InvariantLaw):
    """Mooney-Rivlin law W = c1 (I1 - 3) + c2 (I2 - 3), shear modulus mu = 2 (c1 + c2).

    Attributes
    ----------
    c1, c2 : float
        Material constants [Pa]; c1 > 0, c2 >= 0.
    """

    c1: float
    c2: float
    linear = True

    def __post_init__(self):
        check_real("c1", self.c1, minimum=0.0, min_inclusive=False)
        check_real("c2", self.c2, minimum=0.0)

    @property
    def mu(self) -> float:
        return 2.0 * (self.c1 + self.c2)

    def invariant_derivatives(self, I1, I2):
        zero = np.zeros_like(I1)
        return self.c1 * (I1 - 3.0) + self.c2 * (I2 - 3.0), self.c1, self.c2, zero, zero, zero


@dataclass(frozen=True)
class Gent(InvariantLaw):
    """Gent law W = -(mu Jlim / 2) ln(1 - (I1 - 3)/Jlim), finite only while I1 - 3 < Jlim.

    Attributes
    ----------
    mu : float
        Shear modulus [Pa], > 0.
    Jlim : float
        Limit of I1 - 3 (chain extensibility), > 0.
    """

    mu: float
    Jlim: float

    def __post_init__(self):
        check_real("mu", self.mu, minimum=0.0, min_inclusive=False)
        check_real("Jlim", self.Jlim, minimum=0.0, min_inclusive=False)

    def invariant_derivatives(self, I1, I2):
        W, W1, W11 = gent_invariants.py_func(I1, self.mu, self.Jlim)     # the compiled kernels' formula
        zero = np.zeros_like(I1)
        return W, W1, zero, W11, zero, zero

    def admissible(self, lam1, lam2):
        with np.errstate(divide="ignore", invalid="ignore"):
            I1 = first_invariant.py_func(lam1, lam2)
        return (lam1 > 0) & (lam2 > 0) & (I1 - 3.0 < self.Jlim)


@dataclass(frozen=True)
class Yeoh(InvariantLaw):
    """Yeoh law W = c1 (I1 - 3) + c2 (I1 - 3)^2 + c3 (I1 - 3)^3, shear modulus mu = 2 c1.

    Attributes
    ----------
    c1, c2, c3 : float
        Material constants [Pa]; c1 > 0.
    """

    c1: float
    c2: float = 0.0
    c3: float = 0.0

    def __post_init__(self):
        check_real("c1", self.c1, minimum=0.0, min_inclusive=False)
        check_real("c2", self.c2)
        check_real("c3", self.c3)

    @property
    def mu(self) -> float:
        return 2.0 * self.c1

    def invariant_derivatives(self, I1, I2):
        x = I1 - 3.0
        zero = np.zeros_like(I1)
        W = x * (self.c1 + x * (self.c2 + x * self.c3))
        W1 = self.c1 + x * (2.0 * self.c2 + 3.0 * x * self.c3)
        W11 = 2.0 * self.c2 + 6.0 * self.c3 * x
        return W, W1, zero, W11, zero, zero


#: Laws by name, for scenes and the command line: name -> (class, parameter names).
LAWS = {
    "neo_hookean": (NeoHookean, ("mu",)),
    "mooney_rivlin": (MooneyRivlin, ("c1", "c2")),
    "gent": (Gent, ("mu", "Jlim")),
    "yeoh": (Yeoh, ("c1", "c2", "c3")),
}


#: Parameters of one instance of every law, for tests that check every registered law.
EXAMPLES = {
    "neo_hookean": {"mu": 1.0},
    "mooney_rivlin": {"c1": 0.4375, "c2": 0.0625},
    "gent": {"mu": 1.0, "Jlim": 20.0},
    "yeoh": {"c1": 0.5, "c2": -0.01, "c3": 0.002},
}


def make_law(name: str, **params) -> Law:
    """Build a law by its name in ``LAWS`` from keyword parameters (extra ones are ignored)."""
    if name not in LAWS:
        raise SnapmemError(f"material = {name!r}: unknown law; allowed: {', '.join(LAWS)}")
    cls, names = LAWS[name]
    return cls(**{k: params[k] for k in names if k in params})
