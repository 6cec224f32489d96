"""The one exception type for bad input, so callers and the CLI can answer it in one line, the
checks of fields read from files (scenes, JSON) that raise it, naming the field, and
:func:`read_json`, the one reader of every JSON file vrecho reads."""

from __future__ import annotations

import dataclasses
import json
import os
import reprlib
import stat
from pathlib import Path

import numpy as np

MAX_JSON_BYTES = 16 * 2**20
"""The largest JSON file read (16 MiB); a scene of a thousand poses is under 1 MiB."""
MAX_JSON_DEPTH = 32
"""The deepest nesting of lists and objects read; vrecho's own files nest 6 deep at most."""
MAX_JSON_DIGITS = 18
"""The most digits an integer in a JSON file may have (no count or index needs more)."""

_reprlib = reprlib.Repr()
_reprlib.maxstring = _reprlib.maxother = 30
_reprlib.maxlevel = 3


def _show(x) -> str:
    """A value as a message shows it: its start, never megabytes of it (a NumPy scalar as a number)."""
    s = _reprlib.repr(x.item() if isinstance(x, np.generic) else x)
    return s if len(s) <= 80 else s[:77] + "..."


class VrechoError(ValueError):
    """Bad input or an impossible request; the message names the offending field and value.

    A subclass of ``ValueError``: code that catches ``ValueError`` catches it too.

    Parameters
    ----------
    message : str
        The offending field, a colon, then what is wrong with it, e.g. ``"fs: sample rate must
        be a positive whole number of hertz, got 0"``.
    """


def check_field(d: dict, key: str, where: str, default=dataclasses.MISSING):
    """One field of a JSON object read from a file, or its default.

    Parameters
    ----------
    d : dict
        The JSON object that should hold the field.
    key : str
        The field's name.
    where : str
        The object's path in the file (e.g. ``"poses[0]"``), which errors name.
    default : object, optional
        What to return when ``key`` is absent; without it the field is required.

    Returns
    -------
    object
        ``d[key]`` as read, unchecked, or ``default``.

    Raises
    ------
    VrechoError
        If ``d`` is not a dict, or ``key`` is absent and there is no default.

    Examples
    --------
    >>> check_field({"fs": 16000}, "fs", "capture")
    16000
    >>> check_field({}, "gain_db", "sources[0]", 0.0)
    0.0
    """
    if not isinstance(d, dict):
        raise VrechoError(f"{where}: expected an object, got {type(d).__name__}")
    if key not in d:
        if default is dataclasses.MISSING:
            raise VrechoError(f"{where}.{key}: missing")
        return default
    return d[key]


def _range(lo, hi) -> str:
    if lo is not None and lo == hi:
        return f"exactly {lo}"
    if lo is not None and hi is not None:
        return f"from {lo} to {hi}"
    return f"at least {lo}" if lo is not None else f"at most {hi}"


def check_number(x, where: str, *, lo: float | None = None, hi: float | None = None) -> float:
    """``x`` as a float if it is a finite number (not a bool) within ``lo`` to ``hi``.

    Parameters
    ----------
    x : object
        The value read; an int, float or NumPy scalar passes, a bool or a string does not.
    where : str
        The field's path in the file (e.g. ``"room.height_m"``), which errors name.
    lo, hi : float, optional
        Inclusive bounds, in the field's own unit; none by default. Errors give the range.

    Returns
    -------
    float

    Raises
    ------
    VrechoError
        Naming the field ``where``, if ``x`` is not a finite number (an integer too large for a
        float included) or lies outside ``lo`` to ``hi``.

    Examples
    --------
    >>> check_number(3, "room.height_m", lo=0.0)
    3.0
    """
    if isinstance(x, bool) or not isinstance(x, (int, float, np.integer, np.floating)):
        raise VrechoError(f"{where}: expected a finite number, got {_show(x)}")
    try:
        v = float(x)
    except OverflowError:  # a Python int beyond float's range
        v = float("inf")
    if not np.isfinite(v):
        raise VrechoError(f"{where}: expected a finite number, got {_show(x)}")
    if (lo is not None and v < lo) or (hi is not None and v > hi):
        raise VrechoError(f"{where}: must be {_range(lo, hi)}, got {_show(x)}")
    return v


def check_count(n, where: str, hi: int, lo: int = 1) -> int:
    """``n`` as an int if it is a whole number from ``lo`` to ``hi`` (not a bool): a count, a seed,
    an argument of a public call.

    Parameters
    ----------
    n : object
        The value given.
    where : str
        The argument's name, which errors name.
    hi, lo : int
        The largest and the smallest allowed (``lo`` 1 by default).

    Returns
    -------
    int

    Raises
    ------
    VrechoError
        Naming ``where`` and the allowed range, for anything else.
    """
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or not lo <= n <= hi:
        raise VrechoError(f"{where}: expected a whole number from {lo} to {hi}, got {n!r}")
    return int(n)


def check_vector(x, where: str, n: int = 3, *, lo: float | None = None, hi: float | None = None) -> np.ndarray:
    """``x`` as a float vector of ``n`` finite numbers, each within ``lo`` to ``hi``.

    Parameters
    ----------
    x : array_like
        The value read, e.g. a JSON list ``[x, y, z]``: a list or tuple of numbers (as
        :func:`check_number` takes them, so not strings) or a numeric NumPy array.
    where : str
        The field's path in the file (e.g. ``"poses[0].emitter"``), which errors name.
    n : int
        The number of values expected; 3 (a point or direction in metres) by default.
    lo, hi : float, optional
        Inclusive bounds of every value; none by default.

    Returns
    -------
    numpy.ndarray [shape=(n,)], float64
        Not a copy where ``x`` is already such an array.

    Raises
    ------
    VrechoError
        Naming the field ``where`` (and the value's index), if ``x`` is not ``n`` finite numbers
        within the bounds.

    Examples
    --------
    >>> check_vector([1, 2, 0.5], "sources[0].position")
    array([1. , 2. , 0.5])
    """
    if isinstance(x, np.ndarray) and x.dtype.kind in "iuf" and x.shape == (n,):
        v = x.astype(float, copy=False)
        values = v.tolist()
    elif isinstance(x, (list, tuple)) and len(x) == n:
        v, values = None, x
    else:
        raise VrechoError(f"{where}: expected {n} numbers, got {_show(x)}")
    checked = [check_number(a, f"{where}[{i}]", lo=lo, hi=hi) for i, a in enumerate(values)]
    return v if v is not None else np.array(checked)


def check_float32(x: np.ndarray, name: str) -> np.ndarray:
    """``x`` (numbers) as float32, or one :class:`VrechoError` naming ``name`` for NaN or
    infinite samples, or samples beyond float32's range (about 3.4e38: no audio is that loud,
    and the cast would make them infinite with only a warning).

    Parameters
    ----------
    x : numpy.ndarray
        Samples, floats or integers.
    name : str
        The argument's name, for the error.

    Returns
    -------
    numpy.ndarray [dtype=float32]
        A copy.

    Raises
    ------
    VrechoError
        As above.
    """
    with np.errstate(over="ignore"):
        out = x.astype(np.float32)
    if not np.all(np.isfinite(out)):  # (one pass over the samples that pass: the cause only on failure)
        if not np.all(np.isfinite(x)):
            raise VrechoError(f"{name}: contains NaN or infinite samples")
        raise VrechoError(f"{name}: samples beyond float32's range (|x| > {np.finfo(np.float32).max:.1e})")
    return out


def check_per_frame(value, n: int, where: str, noun: str) -> np.ndarray:
    """``value``, metres, one for every frame or one per frame of ``n``, as an array (n,);
    whether each is finite and in range is the caller's to check.

    Parameters
    ----------
    value : float or array_like, shape (n,)
        What the caller was given.
    n : int
        How many frames it is for.
    where, noun : str
        The parameter's name and what one value is ("distance"), for the error.

    Returns
    -------
    numpy.ndarray [shape=(n,)], float64
        A copy.

    Raises
    ------
    VrechoError
        Naming ``where``, for a value that is not numbers, or not one or ``n`` of them.

    Examples
    --------
    >>> check_per_frame(1.5, 2, "surface_m", "distance")
    array([1.5, 1.5])
    """
    try:
        a = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise VrechoError(f"{where}: expected metres (a number, or one per frame), got {type(value).__name__}") from None
    if a.ndim > 1 or (a.ndim == 1 and len(a) != n):
        raise VrechoError(f"{where}: expected one {noun}, or one per frame ({n}), got shape {a.shape}")
    return np.broadcast_to(a, (n,)).copy()


def check_text(x, where: str, *, choices=None, max_len: int = 100) -> str:
    """``x`` if it is a string of printable text, and one of ``choices`` where they are given.

    Parameters
    ----------
    x : object
        The value read.
    where : str
        The field's path in the file (e.g. ``"sources[0].sound"``), which errors name.
    choices : collection of str, optional
        The allowed values; errors list them.
    max_len : int
        The most characters allowed (default 100).

    Returns
    -------
    str

    Raises
    ------
    VrechoError
        Naming the field ``where``, if ``x`` is not a string, is empty or longer than
        ``max_len``, holds control characters or unpaired surrogates (it could not be written as
        UTF-8), or is not one of ``choices``.

    Examples
    --------
    >>> check_text("voice", "sources[0].sound", choices=("voice", "whistle"))
    'voice'
    """
    if not isinstance(x, str):
        raise VrechoError(f"{where}: expected a string, got {_show(x)}")
    if choices is not None:
        if x not in choices:
            raise VrechoError(f"{where}: expected one of {tuple(choices)}, got {_show(x)}")
        return x
    if not 0 < len(x) <= max_len or not x.isprintable():  # unpaired surrogates are not printable
        raise VrechoError(f"{where}: expected 1 to {max_len} printable characters, got {_show(x)}")
    return x


def check_list(x, where: str, *, lo: int = 0, hi: int) -> list:
    """``x`` if it is a list (or tuple) of ``lo`` to ``hi`` items, checked before any is read.

    Parameters
    ----------
    x : object
        The value read.
    where : str
        The field's path in the file (e.g. ``"poses"``), which errors name.
    lo, hi : int
        The fewest and most items allowed.

    Returns
    -------
    list or tuple
        ``x`` itself.

    Raises
    ------
    VrechoError
        Naming the field ``where`` and the allowed count, if ``x`` is not a list or has too few
        or too many items.

    Examples
    --------
    >>> check_list([[0, 0], [1, 0], [0, 1]], "room.footprint", lo=3, hi=32)
    [[0, 0], [1, 0], [0, 1]]
    """
    if not isinstance(x, (list, tuple)):
        raise VrechoError(f"{where}: expected a list, got {_show(x)}")
    if not lo <= len(x) <= hi:
        count = f"at most {hi}" if lo == 0 else _range(lo, hi).replace("from ", "")
        raise VrechoError(f"{where}: expected {count} items, got {len(x)}")
    return x


def check_keys(d: dict, known, where: str) -> None:
    """Refuse fields of a JSON object that are not ``known`` (a misspelt optional field would
    otherwise silently take its default).

    Parameters
    ----------
    d : dict
        The JSON object.
    known : collection of str
        Its fields.
    where : str
        The object's path in the file, which errors name.

    Raises
    ------
    VrechoError
        If ``d`` is not a dict or has a field not in ``known``; the message lists them.
    """
    if not isinstance(d, dict):
        raise VrechoError(f"{where}: expected an object, got {type(d).__name__}")
    for key in d:
        if key not in known:
            raise VrechoError(f"{where}: unknown field {_show(key)}; expected some of {', '.join(known)}")


def read_json(path: str | Path, what: str, *, expect: type | None = None, max_bytes: int = MAX_JSON_BYTES):
    """A JSON file's value, read strictly: one :class:`VrechoError` for anything else.

    Refused: a path that is not a regular file (a FIFO would hang), more than ``max_bytes``,
    bytes that are not UTF-8 (a leading BOM is allowed), JSON syntax errors (with line and
    column), ``NaN``/``Infinity`` and numbers that overflow a float, integers of more than
    :data:`MAX_JSON_DIGITS` digits, and nesting deeper than :data:`MAX_JSON_DEPTH`.

    Parameters
    ----------
    path : str or pathlib.Path
        The file.
    what : str
        What the file is, for messages (e.g. ``"scene file"``).
    expect : type, optional
        What the top level must be (``dict`` or ``list``); anything by default.
    max_bytes : int
        The largest file read; :data:`MAX_JSON_BYTES` (16 MiB) by default.

    Returns
    -------
    object
        Dicts, lists, strings, finite floats, ints, bools and None.

    Raises
    ------
    VrechoError
        Naming ``what`` and ``path``, and what is wrong.
    """
    path = Path(path)
    where = f"{what} {path}"
    try:
        regular = stat.S_ISREG(os.stat(path).st_mode)
        if regular:
            with open(path, "rb") as f:
                data = f.read(max_bytes + 1)
    except (OSError, ValueError) as e:  # ValueError: a path with a NUL byte
        raise VrechoError(f"{where}: cannot read ({getattr(e, 'strerror', None) or e})") from None
    if not regular:
        raise VrechoError(f"{where}: not a regular file")
    if len(data) > max_bytes:
        raise VrechoError(f"{where}: larger than the {max_bytes} bytes allowed")
    try:
        text = data.decode("utf-8-sig")
    except UnicodeDecodeError as e:
        raise VrechoError(f"{where}: not UTF-8 text (byte {e.start} is {data[e.start]:#04x})") from None
    try:
        value = json.loads(text, parse_constant=_refuse_constant, parse_int=_int, parse_float=_float)
    except json.JSONDecodeError as e:
        raise VrechoError(f"{where}: not valid JSON (line {e.lineno}, column {e.colno}: {e.msg})") from None
    except RecursionError:
        raise VrechoError(f"{where}: nested deeper than {MAX_JSON_DEPTH} levels") from None
    except VrechoError as e:
        raise VrechoError(f"{where}: {e}") from None
    if _depth_exceeds(value, MAX_JSON_DEPTH):
        raise VrechoError(f"{where}: nested deeper than {MAX_JSON_DEPTH} levels")
    if expect is not None and not isinstance(value, expect):
        raise VrechoError(f"{where}: expected a JSON {'object' if expect is dict else 'array'} at the top, "
                          f"got {type(value).__name__}")
    return value


def _refuse_constant(name: str):
    raise VrechoError(f"{name} is not a number JSON allows")


def _int(s: str) -> int:
    if len(s.lstrip("-")) > MAX_JSON_DIGITS:
        raise VrechoError(f"an integer of {len(s.lstrip('-'))} digits (at most {MAX_JSON_DIGITS} allowed)")
    return int(s)


def _float(s: str) -> float:
    v = float(s)
    if not np.isfinite(v):
        raise VrechoError(f"the number {s[:40]} is too large for a float")
    return v


def _depth_exceeds(value, limit: int) -> bool:
    """Whether lists and dicts nest deeper than ``limit`` (walked without recursion)."""
    stack = [(value, 1)]
    while stack:
        v, depth = stack.pop()
        if isinstance(v, (list, dict)):
            if depth > limit:
                return True
            stack.extend((c, depth + 1) for c in (v.values() if isinstance(v, dict) else v))
    return False


def check_unit(x, where: str) -> np.ndarray:
    """``x`` as a unit 3-vector: a direction, scaled to length 1.

    A vector already within 1e-12 of unit length is returned as it is, so that a direction read
    back from the JSON a scene wrote is exactly the one written.

    Parameters
    ----------
    x : array_like
        The value read: three finite numbers, not all zero.
    where : str
        The field's path in the file (e.g. ``"poses[0].forward"``), which errors name.

    Returns
    -------
    numpy.ndarray [shape=(3,)], float64
        Unit length.

    Raises
    ------
    VrechoError
        Naming the field ``where``, if ``x`` is not three finite numbers or is the zero vector
        (length under 1e-9).

    Examples
    --------
    >>> check_unit([0, 3, 4], "poses[0].forward")
    array([0. , 0.6, 0.8])
    """
    v = check_vector(x, where)
    big = np.abs(v).max()
    norm = big * np.linalg.norm(v / big) if big > 0 else 0.0  # scaled first: 1e200 squared overflows
    if norm < 1e-9:
        raise VrechoError(f"{where}: must not be the zero vector")
    return v if abs(norm - 1.0) < 1e-12 else (v / big) / (norm / big)  # idempotent: JSON round trips are exact
