"""Chambers: the fluid regions that membranes bound, and their energies.

A chamber is bounded by one or more membranes of a :class:`~snapmem.model.multi.MultiScene`.
Its volume is

    V_c(q) = V_dead + sum_i s_i V_i(q_i)

with V_i the volume a membrane's meridian sweeps (MODEL.md section 2) and s_i = +1 or -1 its
orientation towards the chamber (a membrane whose swept volume grows as the chamber shrinks has
s_i = -1). V_dead is the tubing's and the reservoir's volume. One sign convention everywhere:
a membrane's pressure work is -p V (its energy falls as the pressure inflates it), and a
chamber's energy E_c(V_c) makes the chamber's pressure on its membranes p_c = -dE_c/dV_c.

- ``pressure``: p_c prescribed, E_c = -p_c V_c (today's pressure work).
- ``volume``: an incompressible fluid of prescribed volume, V_c = V_fluid; p_c is its Lagrange
  multiplier (as volume control is today).
- ``gas``: an isothermal ideal gas of fixed amount, (p_c + p_atm) V_c = n R T. Its energy (with
  the atmosphere's work on the membranes' outside) is

      E_c(V_c) = -n R T ln(V_c) + p_atm V_c,      p_c = -dE_c/dV_c = n R T / V_c - p_atm,

  convex in V_c (d2E_c/dV_c^2 = n R T / V_c^2 > 0): the gas stiffens the chamber.
- ``adiabatic``: an ideal gas compressed without heat exchange, (p_c + p_atm) V_c^gamma = C
  (gamma = c_p / c_v > 1, 1.4 for air). Its energy (the gas' internal energy P V / (gamma - 1)
  with the atmosphere's work) is

      E_c(V_c) = C V_c^(1 - gamma) / (gamma - 1) + p_atm V_c,   p_c = C / V_c^gamma - p_atm,

  convex (d2E_c/dV_c^2 = gamma C / V_c^(gamma + 1) > 0) and stiffer than the isothermal gas at
  the same state by gamma. The chamber's ``amount`` is C = P V^gamma [Pa m^(3 gamma)], which is
  n R T at gamma = 1: every formula below takes ``gamma`` (1: isothermal), and tends to the
  isothermal one as gamma -> 1.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import Enum

from snapmem.errors import SnapmemError, check_real


class ChamberKind(str, Enum):
    """What holds a chamber's state; the values are the words of the ``chamber`` parameter."""

    PRESSURE = "pressure"     #: prescribed pressure
    VOLUME = "volume"         #: prescribed incompressible fluid volume (pressure: a multiplier)
    GAS = "gas"               #: isothermal ideal gas of fixed amount n R T
    ADIABATIC = "adiabatic"   #: ideal gas compressed adiabatically, P V^gamma = C


@dataclass(frozen=True)
class Chamber:
    """A chamber: which membranes bound it, and what fills it.

    Attributes
    ----------
    kind : ChamberKind
    membranes : tuple of int
        Indices (from 0) of the membranes of the scene that bound it.
    signs : tuple of float, optional
        s_i = +1 or -1 per membrane (default all +1: each membrane's swept volume is the chamber's).
    pressure : float
        Prescribed pressure p_c [Pa] (``pressure``), the start of the others.
    volume : float or None
        Fluid volume V_fluid [m^3] (``volume``) when not the continuation parameter; None: as at
        the start.
    amount : float or None
        n R T [J] of the gas (``gas``), or the adiabat's C = P V^gamma [Pa m^(3 gamma)]
        (``adiabatic``), when not the continuation parameter; None: what the reference state holds
        at gauge pressure 0, p_atm (V_reference + V_dead)^gamma.
    dead_volume : float
        V_dead [m^3] >= 0, the tubing's and reservoir's volume.
    p_atm : float
        Ambient (absolute) pressure [Pa] > 0 (``gas`` and ``adiabatic``).
    gamma : float
        The adiabatic exponent c_p / c_v >= 1 (``adiabatic`` only; default 1.4, air).
    """

    kind: ChamberKind
    membranes: tuple
    signs: tuple = ()
    pressure: float = 0.0
    volume: float | None = None
    amount: float | None = None
    dead_volume: float = 0.0
    p_atm: float = 1.0
    gamma: float = 1.4

    def __post_init__(self):
        try:
            kind = ChamberKind(self.kind)
        except ValueError:
            raise SnapmemError(f"chamber = {self.kind!r}: must be one of "
                               f"{', '.join(k.value for k in ChamberKind)}") from None
        object.__setattr__(self, "kind", kind)
        members = tuple(int(i) for i in self.membranes)
        if not members or len(set(members)) != len(members) or min(members) < 0:
            raise SnapmemError(f"chamber membranes = {self.membranes!r}: must be distinct membrane indices >= 0")
        object.__setattr__(self, "membranes", members)
        signs = tuple(float(s) for s in self.signs) or (1.0,) * len(members)
        if len(signs) != len(members) or any(s not in (1.0, -1.0) for s in signs):
            raise SnapmemError(f"chamber signs = {self.signs!r}: one +1 or -1 per membrane ({len(members)})")
        object.__setattr__(self, "signs", signs)
        check_real("pressure", self.pressure)
        check_real("dead_volume", self.dead_volume, minimum=0.0)
        check_real("p_atm", self.p_atm, minimum=0.0, min_inclusive=False)
        check_real("gamma", self.gamma, minimum=1.0)
        if self.volume is not None:
            check_real("volume", self.volume, minimum=0.0, min_inclusive=False)
        if self.amount is not None:
            check_real("amount", self.amount, minimum=0.0, min_inclusive=False)

    @property
    def has_multiplier(self) -> bool:
        """Whether the chamber's pressure is an unknown (fluid and gas chambers)."""
        return self.kind is not ChamberKind.PRESSURE

    @property
    def is_gas(self) -> bool:
        """Whether a gas fills the chamber (isothermal or adiabatic)."""
        return self.kind in (ChamberKind.GAS, ChamberKind.ADIABATIC)

    @property
    def exponent(self) -> float:
        """The gas law's exponent: P V^exponent = amount (1 isothermal, gamma adiabatic)."""
        return self.gamma if self.kind is ChamberKind.ADIABATIC else 1.0


def gas_energy(volume: float, amount: float, p_atm: float, gamma: float = 1.0) -> float:
    """E [J] of a gas chamber of volume V [m^3] holding ``amount`` (P V^gamma = amount: n R T [J]
    at gamma = 1): -amount ln(V) + p_atm V (isothermal, gamma = 1), amount V^(1 - gamma) /
    (gamma - 1) + p_atm V (adiabatic)."""
    if volume <= 0:
        raise SnapmemError(f"gas chamber volume = {volume:g}: must be > 0")
    if gamma == 1.0:
        return -amount * math.log(volume) + p_atm * volume
    return amount * volume ** (1.0 - gamma) / (gamma - 1.0) + p_atm * volume


def gas_pressure(volume, amount: float, p_atm: float, gamma: float = 1.0):
    """Gauge pressure p = amount / V^gamma - p_atm [Pa] of the gas at chamber volume V [m^3]."""
    return amount / volume ** gamma - p_atm


def gas_volume(pressure, amount: float, p_atm: float, gamma: float = 1.0):
    """Chamber volume V = (amount / (p + p_atm))^(1 / gamma) [m^3] of the gas at gauge pressure p [Pa]."""
    ratio = amount / (pressure + p_atm)
    return ratio if gamma == 1.0 else ratio ** (1.0 / gamma)


def gas_compliance(pressure, amount: float, p_atm: float, gamma: float = 1.0):
    """-dV/dp = V / (gamma (p + p_atm)) [m^3/Pa] of the gas at gauge pressure p."""
    if gamma == 1.0:
        return amount / (pressure + p_atm) ** 2
    return gas_volume(pressure, amount, p_atm, gamma) / (gamma * (pressure + p_atm))


def gas_stiffness(volume, amount: float, p_atm: float, gamma: float = 1.0):
    """d2E/dV^2 = gamma amount / V^(gamma + 1) [Pa/m^3] of the gas at chamber volume V [m^3]."""
    return gamma * amount / volume ** (gamma + 1.0)
