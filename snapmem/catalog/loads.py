"""Which loads a scene must be built with, for what will be varied.

A scene includes the electric term only when its voltage is nonzero, unless it is built with
``with_loads=('voltage',)``: a continuation or a fold curve that starts at zero voltage and
varies the voltage (directly, or through the dimensionless field E_hat) needs the term from
the start.
"""

from __future__ import annotations

#: Controls and parameters that change the voltage load.
VOLTAGE_NAMES = ("voltage", "E_hat")


def loads_needed(control: str, *names: str) -> tuple:
    """The ``with_loads`` of a scene traced in ``control`` while the parameters ``names`` vary.

    >>> loads_needed("pressure", "E_hat")
    ('voltage',)
    >>> loads_needed("volume")
    ()
    """
    return ("voltage",) if any(name in VOLTAGE_NAMES for name in (control, *names)) else ()


def same_load(control: str, name: str) -> bool:
    """Whether the parameter ``name`` is the load that ``control`` sweeps (itself, or the voltage
    in the other unit: 'voltage' and the dimensionless field 'E_hat'): varying it beside that
    control changes nothing, since the control sets it at every point.

    >>> same_load("voltage", "E_hat"), same_load("pressure", "E_hat")
    (True, False)
    """
    return name == control or (name in VOLTAGE_NAMES and control in VOLTAGE_NAMES)
