"""Hyperelastic laws: a strain energy density W(lam1, lam2) and its derivatives.

A law is a small object with ``density(lam1, lam2)`` returning a :class:`Density`: W per unit
reference volume and its first and second derivatives in the two in-plane principal stretches
(thickness stretch eliminated by incompressibility, lam3 = 1 / (lam1 lam2)). Arrays of shape (E,).

Laws written in the invariants I1, I2 subclass :class:`InvariantLaw` and give only dW/dI and
d2W/dI2; the chain rule to (lam1, lam2) is written once, here.

Every law declares its parameters (:class:`~snapmem.model.parameters.Parameter`: name, default,
unit, doc, allowed range) and an example instance; :func:`register_law` makes it known by name,
so that scenes, the command line (``--set material=NAME`` and its parameters) and the tests that
check every law take it from there. A law defined outside the package works the same way::

    @register_law
    @dataclass(frozen=True)
    class Ogden1(Law):
        mu: float
        alpha: float
        parameters = (Parameter("mu", 1.0, "Pa", "shear modulus", minimum=0.0, open_min=True),
                      Parameter("alpha", 2.0, "", "exponent", minimum=0.0, open_min=True))
        def density(self, lam1, lam2): ...
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from snapmem.errors import SnapmemError
from snapmem.kernels.assembly import invariant_chain, linear_law_density
from snapmem.kernels.laws import first_invariant, gent_invariants
from snapmem.kernels.switch import compiled
from snapmem.model.parameters import Parameter


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
    """Base of all strain energy densities W(lam1, lam2) [Pa].

    A subclass implements ``density`` (and ``admissible`` if W is not finite for every positive
    stretch), has an initial shear modulus ``mu`` [Pa], declares ``parameters`` in the order its
    constructor takes them as keywords, and may override ``example`` and ``with_modulus``. Frozen
    dataclass laws get their declared parameters checked on construction (``__post_init__``).
    """

    #: initial shear modulus [Pa], used to normalise loads (E_hat, p_hat)
    mu: float

    #: the law's parameters (name, default, unit, doc, allowed range), each a constructor keyword
    parameters: tuple = ()

    def __post_init__(self):
        """SnapmemError naming the first declared parameter that is not set or out of its range."""
        for p in self.parameters:
            value = getattr(self, p.name)
            if value is None:
                raise SnapmemError(f"{p.name} = None: must be a real number")
            p.check(value, parse_text=False)

    @classmethod
    def from_parameters(cls, **values) -> "Law":
        """An instance from parameter values by name (in their declared units).

        Missing parameters take their declared defaults; numbers may come as text (as from the
        command line); each value is checked against its declared range.
        """
        known = {p.name: p for p in cls.parameters}
        for key in values:
            if key not in known:
                raise SnapmemError(f"parameter {key!r}: law {cls.__name__} has no such parameter; "
                                   f"it has {', '.join(known) or 'none'}")
        return cls(**{name: p.check(values.get(name, p.default)) for name, p in known.items()})

    @classmethod
    def example(cls) -> "Law":
        """A typical instance, for the tests that check every registered law (here: the defaults)."""
        return cls.from_parameters()

    @classmethod
    def with_modulus(cls, values: dict, mu: float) -> dict:
        """Parameter values changed so that the law they make has initial shear modulus ``mu`` [Pa].

        Scenes use it for their parameter ``mu``. Here: a parameter named ``mu`` is set; a law
        without one has its parameters in Pa scaled by mu / (its modulus), which scales W and so
        its modulus (values already at modulus ``mu`` come back unchanged).
        """
        full = {p.name: values.get(p.name, p.default) for p in cls.parameters}
        if "mu" in full:
            return {**full, "mu": mu}
        current = cls.from_parameters(**full).mu
        stresses = [p.name for p in cls.parameters if p.unit == "Pa"]
        if current == mu:
            return full
        if not stresses:
            raise SnapmemError(f"law {cls.__name__}: no parameter in Pa to give it shear modulus mu = {mu:g}; "
                               "define its with_modulus")
        return {**full, **{name: full[name] * (mu / current) for name in stresses}}

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
    parameters = (Parameter("mu", 1.0, "Pa", "shear modulus", minimum=0.0, open_min=True),)

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
    parameters = (Parameter("c1", 0.4375, "Pa", "constant of I1 - 3", minimum=0.0, open_min=True),
                  Parameter("c2", 0.0625, "Pa", "constant of I2 - 3", minimum=0.0))

    @property
    def mu(self) -> float:
        return 2.0 * (self.c1 + self.c2)

    @classmethod
    def with_modulus(cls, values, mu):
        """c1 and c2 scaled to 2 (c1 + c2) = mu, keeping c1/c2 (unchanged if that holds already)."""
        c1, c2 = (values.get(p.name, p.default) for p in cls.parameters)
        if mu == 2.0 * (c1 + c2):
            return {**values, "c1": c1, "c2": c2}
        return {**values, "c1": mu * c1 / (2 * (c1 + c2)), "c2": mu * c2 / (2 * (c1 + c2))}

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
    parameters = (Parameter("mu", 1.0, "Pa", "shear modulus", minimum=0.0, open_min=True),
                  Parameter("Jlim", 270.0, "", "limit of I1 - 3", minimum=0.0, open_min=True))

    @classmethod
    def example(cls):
        return cls(mu=1.0, Jlim=20.0)        # a lock within reach of the tests' stretches

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
    parameters = (Parameter("c1", 0.5, "Pa", "constant of I1 - 3", minimum=0.0, open_min=True),
                  Parameter("c2", 0.0, "Pa", "constant of (I1 - 3)^2"),
                  Parameter("c3", 0.0, "Pa", "constant of (I1 - 3)^3"))

    @property
    def mu(self) -> float:
        return 2.0 * self.c1

    @classmethod
    def with_modulus(cls, values, mu):
        """c1 = mu / 2; c2 and c3 unchanged."""
        return {**values, "c1": 0.5 * mu}

    @classmethod
    def example(cls):
        return cls(c1=0.5, c2=-0.01, c3=0.002)

    def invariant_derivatives(self, I1, I2):
        x = I1 - 3.0
        zero = np.zeros_like(I1)
        W = x * (self.c1 + x * (self.c2 + x * self.c3))
        W1 = self.c1 + x * (2.0 * self.c2 + 3.0 * x * self.c3)
        W11 = 2.0 * self.c2 + 6.0 * self.c3 * x
        return W, W1, zero, W11, zero, zero


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
        return Density(d.w, lp1 * d.w1, lp2 * d.w2, lp1 * lp1 * d.w11, lp1 * lp2 * d.w12, lp2 * lp2 * d.w22)

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


#: Registered laws by name, for scenes, the command line and the tests that check every law:
#: name -> (class, its parameter names). Filled by :func:`register_law`.
LAWS: dict[str, tuple[type, tuple[str, ...]]] = {}


def _snake_case(name: str) -> str:
    return "".join("_" + c.lower() if c.isupper() and i else c.lower() for i, c in enumerate(name))


def register_law(cls: type, name: str | None = None) -> type:
    """Make a law class known by name (``build_scene(..., material=name)``, ``--set material=NAME``).

    Parameters
    ----------
    cls : type
        A subclass of :class:`Law` declaring its ``parameters`` (its constructor takes them as
        keywords).
    name : str, optional
        Default: the class name in snake case (``MooneyRivlin`` -> ``mooney_rivlin``).

    Returns
    -------
    type
        ``cls``, so that ``@register_law`` works as a class decorator.
    """
    if not (isinstance(cls, type) and issubclass(cls, Law)):
        raise SnapmemError(f"register_law({cls!r}): must be a subclass of snapmem.Law")
    if not all(isinstance(p, Parameter) for p in cls.parameters):
        raise SnapmemError(f"register_law({cls.__name__}): parameters must be a tuple of snapmem.Parameter")
    name = _snake_case(cls.__name__) if name is None else name
    if not name.isidentifier():
        raise SnapmemError(f"register_law({cls.__name__}): name {name!r} must be a word (letters, digits, _)")
    if name in LAWS and LAWS[name][0] is not cls:
        raise SnapmemError(f"register_law({cls.__name__}): the name {name!r} is taken by {LAWS[name][0].__name__}")
    LAWS[name] = (cls, tuple(p.name for p in cls.parameters))
    return cls


def law_class(name: str) -> type:
    """The law class registered as ``name``, or SnapmemError listing the registered ones."""
    if not isinstance(name, str) or name not in LAWS:
        raise SnapmemError(f"material = {name!r}: unknown law; must be one of {', '.join(LAWS)}")
    return LAWS[name][0]


def law_name(law: Law) -> str:
    """The name a law instance's class is registered under (its class name if it is not registered)."""
    return next((name for name, (cls, _) in LAWS.items() if cls is type(law)), type(law).__name__)


def make_law(name: str, **params) -> Law:
    """Build a law by its name in ``LAWS`` from keyword parameters (extra ones are ignored; missing
    ones take their declared defaults)."""
    cls = law_class(name)
    return cls.from_parameters(**{k: v for k, v in params.items() if k in LAWS[name][1]})


register_law(NeoHookean)
register_law(MooneyRivlin)
register_law(Gent)
register_law(Yeoh)
