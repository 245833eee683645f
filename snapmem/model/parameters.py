"""A declared parameter: name, default, unit, doc and allowed range, with its check.

Laws (snapmem.model.materials) declare theirs with it, and the scene catalog
(snapmem.catalog) declares the parameters of each scene with the same type, so that a law's
parameters become scene and command-line parameters without being written twice.
"""

from __future__ import annotations

import os
from dataclasses import dataclass

from snapmem.errors import SnapmemError, check_int, check_real, parse_number


#: Magnitudes a real parameter may take besides 0. A product of ten such values stays finite and
#: normal in double precision (1e30^10 = 1e300), so no formula of the model (energies, forces,
#: their derivatives, the voltage from E_hat) overflows to inf or underflows to subnormals.
MAGNITUDE = (1e-30, 1e30)

#: Largest number of meridian nodes: the stiffness' condition number grows as N^2, so the
#: round-off of a state, about 2.2e-16 N^2, reaches 2e-4 at 1e6 nodes (the discretisation error,
#: about 0.45 / N^2, is far below it there).
MAX_NODES = 1_000_000

#: Memory one Newton solve takes per meridian node [bytes]: measured 1.16 kB per node at
#: 1e6 nodes (banded Hessian, its LDL^T factor, residual pieces and work arrays), rounded up.
SOLVE_BYTES_PER_NODE = 1200

#: Memory one stored state takes per node [bytes]: 2 degrees of freedom, state and tangent, 8 bytes each.
STATE_BYTES_PER_NODE = 32


def memory_estimate(nodes: int, stored_states: int = 0) -> float:
    """Estimated peak memory [bytes] of a solve on ``nodes`` nodes that keeps ``stored_states``
    states (continuation points, saved frames)."""
    return float(nodes) * (SOLVE_BYTES_PER_NODE + STATE_BYTES_PER_NODE * max(0, stored_states))


def available_memory() -> float | None:
    """Memory the system can give this process now [bytes] (MemAvailable), or None if unknown."""
    try:
        with open("/proc/meminfo") as meminfo:
            for line in meminfo:
                if line.startswith("MemAvailable:"):
                    return float(line.split()[1]) * 1024.0
    except OSError:
        pass
    try:
        return float(os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE"))
    except (ValueError, OSError, AttributeError):
        return None


def check_memory(what: str, nodes: int, stored_states: int = 0) -> float:
    """The memory estimate of ``what`` [bytes], or SnapmemError (before anything is allocated)
    when it exceeds the memory available."""
    need, have = memory_estimate(nodes, stored_states), available_memory()
    if have is not None and need > have:
        raise SnapmemError(f"{what}: needs about {_gb(need)} of memory ({nodes} nodes"
                           f"{f', {stored_states} stored states' if stored_states else ''}); "
                           f"{_gb(have)} is available")
    return need


def _gb(nbytes: float) -> str:
    return f"{nbytes / 1e9:.3g} GB"


def nodes_note(value) -> str:
    """Why a number of nodes beyond MAX_NODES is refused: its memory and round-off."""
    try:
        n = float(value)
    except (TypeError, ValueError, OverflowError):
        return ""
    if not n > MAX_NODES or n != n:
        return ""
    if n > 1e15:
        return " (more memory than any machine has)"
    return (f" (one solve would need about {_gb(memory_estimate(n))} of memory, and its round-off "
            f"2.2e-16 N^2 = {2.2e-16 * n * n:.2g} exceeds any tolerance)")


@dataclass(frozen=True)
class Parameter:
    """One parameter of a law or a scene.

    Attributes
    ----------
    name, unit, doc : str
    default : float, int, str or None
        None means "not set" (derived from other parameters).
    kind : type
        float, int or str.
    minimum, maximum : float, optional
        Allowed range (``open_min``/``open_max`` exclude the bound itself).
    choices : tuple of str, optional
        Allowed values of a string parameter.
    note : callable (value) -> str, optional
        Says why a value out of range is refused (appended to the message).
    excludes : tuple of str, optional
        Parameters that may not be set together with this one (they give the same thing another
        way, e.g. aspect_ratio and Rs); setting both is refused, not resolved by order.

    Every real value must also have a magnitude at most ``MAGNITUDE[1]``, and a strictly positive
    scale (``minimum=0, open_min=True``: a length, a modulus, a permittivity, which the model
    divides by) at least ``MAGNITUDE[0]``.
    """

    name: str
    default: object
    unit: str
    doc: str
    kind: type = float
    minimum: float | None = None
    maximum: float | None = None
    open_min: bool = False
    open_max: bool = False
    choices: tuple = ()
    note: object = None
    excludes: tuple = ()

    def check(self, value, parse_text: bool = True):
        """The value converted to ``kind``, or SnapmemError naming this parameter, the value and
        the allowed range.

        Parameters
        ----------
        value : object
            None (not set) passes unchanged.
        parse_text : bool
            Whether a number may come as text (as from ``--set NAME=VALUE``).
        """
        if value is None:
            return None
        if self.kind is str:
            if not isinstance(value, str) or (self.choices and value not in self.choices):
                raise SnapmemError(f"{self.name} = {value!r}: must be one of {', '.join(self.choices)}")
            return value
        if isinstance(value, str) and parse_text:
            value = parse_number(self.name, value)
        try:
            if self.kind is int:
                return check_int(self.name, value, minimum=self.minimum, maximum=self.maximum)
            value = check_real(self.name, value, minimum=self.minimum, maximum=self.maximum,
                               min_inclusive=not self.open_min, max_inclusive=not self.open_max)
        except SnapmemError as exc:
            raise SnapmemError(f"{exc}{self.note(value) if self.note else ''}") from None
        low, high = MAGNITUDE
        scale = self.minimum == 0.0 and self.open_min          # a length, modulus, ...: the model divides by it
        if abs(value) > high or (scale and value < low):
            raise SnapmemError(f"{self.name} = {value!r}: its magnitude must lie between {low:g} and {high:g} "
                               f"{'' if scale else '(or below, down to 0) '}for the model's formulas to stay finite")
        return value

    def with_default(self, default) -> "Parameter":
        """The same parameter with another default."""
        return Parameter(**{**self.__dict__, "default": default})


