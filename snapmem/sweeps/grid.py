"""The designs of a sweep: axes and their product grid, design values and keys, and the parsing
of ``NAME=START:STOP:COUNT`` / ``NAME=v1,v2,...`` axes (``snapmem sweep --grid``, ``snapmem fold
--vary``)."""

from __future__ import annotations

import hashlib
import itertools
import json
from numbers import Integral, Real
from typing import Iterable, Mapping, Sequence

import numpy as np

from snapmem.errors import SnapmemError, check_int, check_real

#: Column names a sweep writes itself, so no design parameter may take them.
RESERVED = {"design", "key", "status", "message"}

#: Most designs one sweep may have: each design is a row of the results table and a key in its
#: journal (about 1 kB together), so 1e7 designs are about 10 GB before any is run.
MAX_DESIGNS = 10_000_000


def check_design_count(axes: Mapping[str, Sequence]) -> int:
    """The number of designs of the axes' product, or SnapmemError (before the product is made)
    when it exceeds :data:`MAX_DESIGNS`."""
    count = 1
    for values in axes.values():
        count *= len(values)
    if count > MAX_DESIGNS:
        sizes = " x ".join(f"{len(v)} ({name})" for name, v in axes.items())
        raise SnapmemError(f"grid: {sizes} = {count:.4g} designs; at most {MAX_DESIGNS:g} per sweep "
                           "(split it into several sweeps)")
    return count


def product_grid(axes: Mapping[str, Sequence]) -> list[dict]:
    """Every combination of the axes' values, the last axis varying fastest.

    >>> product_grid({"R": [1, 2], "H": [0.1, 0.2]})[1]
    {'R': 1, 'H': 0.2}
    """
    names = list(axes)
    for name in names:
        values = axes[name]
        if isinstance(values, (str, bytes)) or not isinstance(values, Iterable):
            raise SnapmemError(f"grid axis {name!r} = {values!r}: must be a list of values")
    check_design_count({name: list(axes[name]) for name in names})
    return [dict(zip(names, combo)) for combo in itertools.product(*(list(axes[n]) for n in names))]


def _scalar(name: str, value):
    """A design value as a plain Python bool, int, finite float or one-line str."""
    if isinstance(value, (bool, np.bool_)):
        return bool(value)
    if isinstance(value, (Integral, np.integer)):
        return int(value)
    if isinstance(value, (Real, np.floating)):
        return check_real(name, float(value))
    if isinstance(value, str):
        if "\n" in value or "\r" in value:
            raise SnapmemError(f"{name} = {value!r}: must be one line")
        return value
    raise SnapmemError(f"{name} = {value!r}: must be a number or a string (got {type(value).__name__})")


def designs_of(grid) -> list[dict]:
    """The list of designs of ``grid``: a mapping of axes (their product) or a list of dicts.

    Every design must have the same parameter names; values are plain numbers or strings.
    """
    if isinstance(grid, Mapping):
        designs = product_grid(grid) if grid else []
    elif isinstance(grid, (str, bytes)) or not isinstance(grid, Iterable):
        raise SnapmemError(f"grid = {grid!r}: must be a mapping of axes or a list of designs (dicts)")
    else:
        designs = list(grid)
    if not designs:
        raise SnapmemError("grid: has no designs")
    names = None
    out = []
    for i, design in enumerate(designs):
        if not isinstance(design, Mapping):
            raise SnapmemError(f"grid design {i} = {design!r}: must be a dict of parameters")
        for key in design:
            if not isinstance(key, str) or not key.strip():
                raise SnapmemError(f"grid design {i}: parameter name {key!r} must be a non-empty string")
            if key in RESERVED:
                raise SnapmemError(f"grid parameter {key!r}: reserved for the sweep's own columns "
                                   f"({', '.join(sorted(RESERVED))})")
        if names is None:
            names = list(design)
        elif set(design) != set(names):
            raise SnapmemError(f"grid design {i}: parameters {sorted(design)}; design 0 has {sorted(names)}: "
                               "every design needs the same names")
        out.append({name: _scalar(name, design[name]) for name in names})
    return out


def design_key(design: Mapping) -> str:
    """A stable 16-hex-digit key of a design's parameters (order of the names does not matter)."""
    text = json.dumps(design, sort_keys=True, separators=(",", ":"))
    return hashlib.sha1(text.encode()).hexdigest()[:16]


def parse_axis(text: str, option: str = "--grid", number: bool = False):
    """``NAME=START:STOP:COUNT`` (evenly spaced) or ``NAME=v1,v2,...`` -> (name, list of values).

    Parameters
    ----------
    text : str
        The axis as typed.
    option : str
        The command-line option it came from, named in error messages.
    number : bool
        Every value must be a number (else a list value that is not one stays a string).

    Returns
    -------
    name : str
    values : list
        Floats for a range; ints, floats (or strings) for a list.
    """
    name, sep, spec = str(text).partition("=")
    name, spec = name.strip(), spec.strip()
    usage = "must be NAME=START:STOP:COUNT or NAME=v1,v2,..."
    if not sep or not name or not spec:
        raise SnapmemError(f"{option} {text!r}: {usage}")
    if ":" in spec:
        parts = spec.split(":")
        if len(parts) != 3:
            raise SnapmemError(f"{option} {text!r}: {usage}")
        start, stop = (check_real(f"{name} {what}", parse_value(f"{name} {what}", p, number=True))
                       for what, p in zip(("START", "STOP"), parts[:2]))
        count = check_int(f"{name} COUNT", parse_value(f"{name} COUNT", parts[2], number=True), minimum=1,
                          maximum=MAX_DESIGNS)
        return name, [float(v) for v in np.linspace(start, stop, count)]
    values = [v.strip() for v in spec.split(",")]
    if any(not v for v in values):
        raise SnapmemError(f"{option} {text!r}: empty value in the list; {usage}")
    return name, [parse_value(name, v, number=number) for v in values]


def parse_value(name: str, text: str, number: bool = False):
    """Text as an int, else a float, else (unless ``number``) the string itself."""
    text = str(text).strip()
    for kind in (int, float):
        try:
            return kind(text)
        except ValueError:
            pass
    if number:
        raise SnapmemError(f"{name} = {text!r}: must be a number")
    return text

