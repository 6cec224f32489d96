"""The one exception type for bad input, so callers and the CLI can answer it in one line, and the
checks of fields read from files (scenes, JSON) that raise it, naming the field."""

from __future__ import annotations

import dataclasses

import numpy as np


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


def check_number(x, where: str, *, lo: float | None = None, hi: float | None = None) -> float:
    """``x`` as a float if it is a finite number (not a bool) within ``lo`` to ``hi``.

    Parameters
    ----------
    x : object
        The value read; an int, float or NumPy scalar passes, a bool or a string does not.
    where : str
        The field's path in the file (e.g. ``"room.height_m"``), which errors name.
    lo, hi : float, optional
        Inclusive bounds, in the field's own unit; none by default.

    Returns
    -------
    float

    Raises
    ------
    VrechoError
        Naming the field ``where``, if ``x`` is not a finite number or lies outside ``lo`` to
        ``hi``.

    Examples
    --------
    >>> check_number(3, "room.height_m", lo=0.0)
    3.0
    """
    if isinstance(x, bool) or not isinstance(x, (int, float, np.integer, np.floating)) or not np.isfinite(x):
        raise VrechoError(f"{where}: expected a finite number, got {x!r}")
    if lo is not None and x < lo:
        raise VrechoError(f"{where}: must be at least {lo}, got {x}")
    if hi is not None and x > hi:
        raise VrechoError(f"{where}: must be at most {hi}, got {x}")
    return float(x)


def check_vector(x, where: str, n: int = 3) -> np.ndarray:
    """``x`` as a float vector of ``n`` finite numbers.

    Parameters
    ----------
    x : array_like
        The value read, e.g. a JSON list ``[x, y, z]``.
    where : str
        The field's path in the file (e.g. ``"poses[0].emitter"``), which errors name.
    n : int
        The number of values expected; 3 (a point or direction in metres) by default.

    Returns
    -------
    numpy.ndarray [shape=(n,)], float64
        Not a copy where ``x`` is already such an array.

    Raises
    ------
    VrechoError
        Naming the field ``where``, if ``x`` is not ``n`` finite numbers.

    Examples
    --------
    >>> check_vector([1, 2, 0.5], "sources[0].position")
    array([1. , 2. , 0.5])
    """
    try:
        v = np.asarray(x, dtype=float)
    except (TypeError, ValueError):
        raise VrechoError(f"{where}: expected {n} numbers, got {x!r}") from None
    if v.shape != (n,) or not np.all(np.isfinite(v)):
        raise VrechoError(f"{where}: expected {n} finite numbers, got {x!r}")
    return v


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
    norm = np.linalg.norm(v)
    if norm < 1e-9:
        raise VrechoError(f"{where}: must not be the zero vector")
    return v if abs(norm - 1.0) < 1e-12 else v / norm  # idempotent, so JSON round trips are exact
