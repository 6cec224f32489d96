"""What localization hands on: a sound source placed in the room."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np


@dataclass
class PlacedSource:
    """A separated sound source at a world position.

    Parameters
    ----------
    position : numpy.ndarray [shape=(3,)]
        In metres, vrecho's world frame (Z up).
    signal : numpy.ndarray [shape=(n,)], str or pathlib.Path
        The separated mono signal (1-D float array at ``fs`` Hz) or the path of a WAV file
        holding it.
    fs : int
        The signal's sample rate in Hz (a WAV file's own rate is read from it).
    confidence : float
        In [0, 1] (default 1).
    name : str
        A label for people and for file names.
    uncertainty_m : float or None
        The position's standard error in metres where one is known.
    flags : tuple of str
        What the listener should know about the track (``"not separated in N of M captures"``:
        microphone 0 there, as separation could have made it worse).
    """

    position: np.ndarray
    signal: np.ndarray | str | Path
    fs: int
    confidence: float = 1.0
    name: str = "source"
    uncertainty_m: float | None = None
    flags: tuple = ()
