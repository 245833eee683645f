"""A declared parameter: name, default, unit, doc and allowed range, with its check.

Laws (snapmem.model.materials) declare theirs with it, and the scene catalog
(snapmem.catalog) declares the parameters of each scene with the same type, so that a law's
parameters become scene and command-line parameters without being written twice.
"""

from __future__ import annotations

from dataclasses import dataclass

from snapmem.errors import SnapmemError, check_int, check_real


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
            value = _parse_number(self.name, value)
        if self.kind is int:
            return check_int(self.name, value, minimum=self.minimum, maximum=self.maximum)
        return check_real(self.name, value, minimum=self.minimum, maximum=self.maximum,
                          min_inclusive=not self.open_min, max_inclusive=not self.open_max)

    def with_default(self, default) -> "Parameter":
        """The same parameter with another default."""
        return Parameter(**{**self.__dict__, "default": default})


def _parse_number(name, text):
    try:
        return int(text)
    except ValueError:
        pass
    try:
        return float(text)
    except ValueError:
        raise SnapmemError(f"{name} = {text!r}: must be a number") from None
