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

A law defined outside the package has its derivatives checked on first use (per instance):
W's first and second derivatives against central differences of W and of the first derivatives
at a few stretches (:data:`CHECK_STRETCHES`, five density calls). Wrong ones raise SnapmemError
naming the derivative, since a solve would otherwise report "converged" at a state that is not an
equilibrium. To opt out (a law checked some other way, or too costly to call), set the class
attribute ``check_derivatives = False``.
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

    #: check a law defined outside snapmem against finite differences on first use (see the module
    #: docstring); set False on a subclass to opt out
    check_derivatives: bool = True

    def __init_subclass__(cls, **kwargs):
        super().__init_subclass__(**kwargs)
        density = getattr(cls, "density", None)
        if cls.__module__.split(".")[0] != "snapmem" and density is not None and not getattr(density, "checks_first_use", False):
            cls.density = _checked_on_first_use(density)

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


#: (lam1, lam2) pairs where a user's law is checked on first use (those outside its domain are skipped).
CHECK_STRETCHES = ((1.0, 1.0), (1.3, 0.9), (0.85, 1.15), (1.6, 1.6), (2.2, 1.4))


def check_derivatives(law: Law, density=None, rtol: float = 1e-5, step: float = 1e-4) -> None:
    """SnapmemError if ``law``'s derivatives disagree with central differences at :data:`CHECK_STRETCHES`.

    Parameters
    ----------
    law : Law
    density : callable (law, lam1, lam2) -> Density, optional
        The function to check (default ``type(law).density``).
    rtol : float
        Allowed difference, relative to the largest derivative at that stretch pair.
    step : float
        Central-difference step, relative to the stretch.
    """
    density = type(law).density if density is None else density
    lam = np.array(CHECK_STRETCHES, dtype=float)
    a, b = lam[:, 0], lam[:, 1]
    h = step * lam
    inside = np.ones(len(lam), dtype=bool)
    for da, db in ((0, 0), (1, 0), (-1, 0), (0, 1), (0, -1)):
        inside &= np.asarray(law.admissible(a + da * h[:, 0], b + db * h[:, 1]), dtype=bool)
    if not inside.any():
        return
    a, b, h1, h2 = a[inside], b[inside], h[inside, 0], h[inside, 1]
    d = density(law, a.copy(), b.copy())
    p1, m1 = density(law, a + h1, b.copy()), density(law, a - h1, b.copy())
    p2, m2 = density(law, a.copy(), b + h2), density(law, a.copy(), b - h2)
    checks = (("dW/dlam1", d.w1, (p1.w - m1.w) / (2 * h1), "W"),
              ("dW/dlam2", d.w2, (p2.w - m2.w) / (2 * h2), "W"),
              ("d2W/dlam1^2", d.w11, (p1.w1 - m1.w1) / (2 * h1), "dW/dlam1"),
              ("d2W/dlam1 dlam2", d.w12, (p2.w1 - m2.w1) / (2 * h2), "dW/dlam1"),
              ("d2W/dlam1 dlam2", d.w12, (p1.w2 - m1.w2) / (2 * h1), "dW/dlam2"),
              ("d2W/dlam2^2", d.w22, (p2.w2 - m2.w2) / (2 * h2), "dW/dlam2"))
    given = [np.broadcast_to(np.asarray(c[1], dtype=float), a.shape) for c in checks]
    scale = np.max(np.abs(np.array(given)), axis=0) + np.finfo(float).tiny
    for (name, _, fd, of), value in zip(checks, given):
        err = np.abs(value - fd) / scale
        if not np.all(err <= rtol):                  # NaN fails too
            i = int(np.argmax(np.where(np.isfinite(err), err, np.inf)))
            raise SnapmemError(
                f"law {type(law).__name__}: {name} = {value[i]:.6g} at (lam1, lam2) = ({a[i]:g}, {b[i]:g}), but finite "
                f"differences of {of} give {fd[i]:.6g} (difference {err[i]:.2g} of its largest derivative there): "
                "its density returns wrong derivatives, and a solve would report converged at a state that is not "
                "an equilibrium; fix them, or set check_derivatives = False on the class to skip this check")


def _checked_on_first_use(density):
    """``density`` that checks the law's derivatives the first time an instance is used."""
    def checked(self, lam1, lam2):
        if type(self).check_derivatives and not getattr(self, "_derivatives_checked", False):
            check_derivatives(self, density)
            try:
                object.__setattr__(self, "_derivatives_checked", True)     # frozen dataclasses too
            except AttributeError:                                     # __slots__: checked at every call
                pass
        return density(self, lam1, lam2)
    checked.checks_first_use = True
    checked.__doc__, checked.__name__, checked.__qualname__ = density.__doc__, density.__name__, density.__qualname__
    return checked


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
