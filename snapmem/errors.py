"""Errors raised by snapmem and the checks that produce them.

Every message names the parameter, the value it got and what is allowed, so that a user who
typed it (in Python, on the command line or in a spreadsheet) can fix it without a traceback.
"""

from __future__ import annotations

import math
import os
import re
from numbers import Real
from pathlib import Path


class SnapmemError(ValueError):
    """Bad input to snapmem: the message names the parameter, its value and what is allowed."""


class SolverError(RuntimeError):
    """A solve that could not produce a trustworthy answer (the message says why)."""


def check_real(name: str, value, *, minimum: float | None = None, maximum: float | None = None,
               min_inclusive: bool = True, max_inclusive: bool = True) -> float:
    """Return ``value`` as a finite float, or raise SnapmemError naming ``name``.

    Parameters
    ----------
    name : str
        Parameter name used in the message.
    value : object
        The value to check (bools and strings are rejected).
    minimum, maximum : float, optional
        Allowed range.
    min_inclusive, max_inclusive : bool
        Whether the bounds themselves are allowed.
    """
    if isinstance(value, bool) or not isinstance(value, Real):
        raise SnapmemError(f"{name} = {value!r}: must be a real number")
    value = float(value)
    if not math.isfinite(value):
        raise SnapmemError(f"{name} = {value!r}: must be finite")
    if minimum is not None and (value < minimum or (value == minimum and not min_inclusive)):
        raise SnapmemError(f"{name} = {value!r}: must be {_range_text(minimum, maximum, min_inclusive, max_inclusive)}")
    if maximum is not None and (value > maximum or (value == maximum and not max_inclusive)):
        raise SnapmemError(f"{name} = {value!r}: must be {_range_text(minimum, maximum, min_inclusive, max_inclusive)}")
    return value


def check_int(name: str, value, *, minimum: int | None = None, maximum: int | None = None) -> int:
    """Return ``value`` as an int within [minimum, maximum], or raise SnapmemError."""
    if isinstance(value, bool) or isinstance(value, str):
        raise SnapmemError(f"{name} = {value!r}: must be an integer")
    try:
        as_int = int(value)
    except (TypeError, ValueError, OverflowError):
        raise SnapmemError(f"{name} = {value!r}: must be an integer") from None
    if as_int != value:
        raise SnapmemError(f"{name} = {value!r}: must be an integer")
    if (minimum is not None and as_int < minimum) or (maximum is not None and as_int > maximum):
        raise SnapmemError(f"{name} = {value!r}: must be an integer {_range_text(minimum, maximum, True, True)}")
    return as_int


def check_array(name: str, value, shape: tuple) -> "np.ndarray":
    """Return ``value`` as a finite float array of ``shape``, or raise SnapmemError naming ``name``."""
    import numpy as np
    try:
        array = np.array(value, dtype=float)
    except (TypeError, ValueError):
        raise SnapmemError(f"{name} = {_short(value)}: must be an array of numbers of shape {shape}") from None
    if array.shape != tuple(shape):
        raise SnapmemError(f"{name}: shape {array.shape}; must be {tuple(shape)}")
    if not np.all(np.isfinite(array)):
        bad = int(np.flatnonzero(~np.isfinite(array.ravel()))[0])
        raise SnapmemError(f"{name}[{bad}] = {float(array.ravel()[bad])!r}: must be finite")
    return array


def read_npz(path, what: str, required: tuple = ()) -> dict:
    """The arrays of a .npz file written by snapmem, loaded without pickle.

    A missing, truncated or corrupt file, one with object (pickled) arrays, or one without the
    ``required`` arrays is a SnapmemError naming the file and what is wrong, never a traceback.
    """
    import zipfile
    import zlib

    import numpy as np
    try:
        data = np.load(path, allow_pickle=False)
        if not isinstance(data, np.lib.npyio.NpzFile):
            raise ValueError("a single .npy array, not an .npz archive")
        with data:
            out = {k: data[k] for k in data.files}
    except (OSError, ValueError, EOFError, KeyError, zipfile.BadZipFile, zlib.error) as exc:
        raise SnapmemError(f"{what} {str(path)!r}: cannot be read ({exc})") from None
    for key in required:
        if key not in out:
            raise SnapmemError(f"{what} {str(path)!r}: has no {key!r} array; not a snapmem {what.split()[0]}")
    return out


#: A number as typed: ASCII digits, an optional sign, point and exponent, or inf / nan (so '1_0',
#: full-width digits '１２' and other spellings Python's int() and float() accept are refused).
_NUMBER_TEXT = re.compile(r"[+-]?((\d+\.?\d*|\.\d+)([eE][+-]?\d+)?|inf|infinity|nan)", re.IGNORECASE)
_INT_TEXT = re.compile(r"[+-]?\d+")


def parse_number(name: str, text: str):
    """``text`` as an int (plain digits) or a float, or SnapmemError naming ``name``.

    Only ASCII decimal notation is a number ('12', '-0.5', '1e-3', 'inf', 'nan'); what Python
    would also read ('1_0', '１２', ' 0x1') is refused, so that a typo is not taken for a value.
    """
    text = str(text).strip()
    if not _NUMBER_TEXT.fullmatch(text) or not text.isascii():
        raise SnapmemError(f"{name} = {text!r}: must be a number")
    return int(text) if _INT_TEXT.fullmatch(text) else float(text)


#: File name endings matplotlib can write a figure to.
FIGURE_SUFFIXES = (".png", ".pdf", ".svg", ".svgz", ".jpg", ".jpeg", ".eps", ".ps", ".tif", ".tiff", ".webp")


def check_output(option: str, path, suffixes: tuple = ()) -> Path:
    """``path`` as a Path a file can be written to, checked before any work is done.

    Parameters
    ----------
    option : str
        The option or argument the path came from (named in the message, e.g. '--out').
    path : str or Path
    suffixes : tuple of str, optional
        Allowed endings (lower case, with the dot); empty: any.

    Raises
    ------
    SnapmemError
        The path is empty, is a folder, has another ending, its folder does not exist or is not
        writable, or the file exists and is not writable.
    """
    text = str(path)
    if not text.strip():
        raise SnapmemError(f"{option} = {text!r}: must be a file name")
    out = Path(text)
    if suffixes and out.suffix.lower() not in suffixes:
        raise SnapmemError(f"{option} = {text!r}: must end in {', '.join(suffixes)}")
    if out.is_dir():
        raise SnapmemError(f"{option} = {text!r}: is a folder; give a file name in it")
    folder = out.parent
    if not folder.exists():
        raise SnapmemError(f"{option} = {text!r}: folder {str(folder)!r} does not exist")
    if not folder.is_dir():
        raise SnapmemError(f"{option} = {text!r}: {str(folder)!r} is not a folder")
    if not os.access(folder, os.W_OK | os.X_OK):
        raise SnapmemError(f"{option} = {text!r}: folder {str(folder)!r} is not writable")
    if out.exists() and not os.access(out, os.W_OK):
        raise SnapmemError(f"{option} = {text!r}: the file exists and is not writable")
    return out


def _short(value) -> str:
    text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


def _range_text(minimum, maximum, min_inclusive, max_inclusive) -> str:
    parts = []
    if minimum is not None:
        parts.append(f"{'>=' if min_inclusive else '>'} {minimum:g}")
    if maximum is not None:
        parts.append(f"{'<=' if max_inclusive else '<'} {maximum:g}")
    return " and ".join(parts) if parts else "any finite value"
