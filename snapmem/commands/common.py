"""What every ``snapmem`` command shares: number and ``NAME=VALUE`` parsing, and the check of its
outputs before any work (a bad one is one line and exit 2)."""

from __future__ import annotations

import numpy as np

from snapmem.continuation import CONTROLS
from snapmem.errors import FIGURE_SUFFIXES, SnapmemError, check_output, parse_number


#: The controls that move a load (fold curves and hysteresis loops; not a volume or a gas amount).
LOAD_CONTROLS = tuple(control for control in CONTROLS if control not in ("volume", "gas_amount"))


def real(text: str) -> float:
    """An option's value as a number, typed in ASCII decimal notation (argparse type; see
    :func:`snapmem.errors.parse_number`)."""
    return float(parse_number("value", text))


def integer(text: str) -> int:
    """An option's value as an integer in ASCII digits (argparse type)."""
    value = parse_number("value", text)
    if not isinstance(value, int):
        raise ValueError(text)
    return value


def parse_sets(pairs: list[str]) -> dict:
    """``["R=10", "nodes=51"]`` -> ``{"R": "10", "nodes": "51"}`` (values checked by the scene)."""
    out = {}
    for pair in pairs or []:
        name, sep, value = pair.partition("=")
        if not sep or not name.strip() or not value.strip():
            raise SnapmemError(f"--set {pair!r}: must be NAME=VALUE, e.g. --set nodes=201")
        if name.strip() in out:
            raise SnapmemError(f"--set {name.strip()!r}: given twice ({out[name.strip()]!r} and {value.strip()!r}); "
                               "give each parameter once")
        out[name.strip()] = value.strip()
    return out


def merge_option(params: dict, name: str, value, option: str) -> dict:
    """``params`` with ``name`` = ``value`` from its own ``option`` (if given); a ``--set`` of the
    same parameter as well is a conflict, refused rather than resolved by order."""
    if value is None:
        return params
    if name in params:
        raise SnapmemError(f"--set {name}={params[name]} and {option} {value}: set {name} one way, not both")
    return {**params, name: value}


#: Output options of each command and the file endings they take (empty: any).
OUTPUTS = {"trace": {"out": (), "points": (), "plot": FIGURE_SUFFIXES},
           "fold": {"out": (), "plot": FIGURE_SUFFIXES},
           "hysteresis": {"out": (), "plot": FIGURE_SUFFIXES},
           "simulate": {"out": (".npz",)},
           "replay": {"out": (".gif", ".mp4")},
           "bench": {"out": ()},
           "sweep": {"out": ()}}


def check_outputs(args) -> None:
    """Every output path of the command checked before any work (folder exists and is writable,
    not a folder itself, the right ending), so that a run never fails only at its end."""
    for option, suffixes in OUTPUTS.get(args.command, {}).items():
        value = getattr(args, option, None)
        if value is not None:
            check_output(f"--{option}", value, suffixes)



def parse_until(pairs: list[str]) -> dict:
    """``["stretch=4"]`` -> ``{"stretch": 4.0}``."""
    out = {}
    for name, value in parse_sets(pairs).items():
        try:
            out[name] = float(value)
        except ValueError:
            raise SnapmemError(f"--until {name}={value!r}: the value must be a number") from None
        if not np.isfinite(out[name]):
            raise SnapmemError(f"--until {name}={value!r}: the value must be a finite number (a target the "
                               "branch can reach)")
    return out


