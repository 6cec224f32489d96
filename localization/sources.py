"""What localization hands on: a sound source placed in the room."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np


@dataclass
class PlacedSource:
    """A separated sound source at a world position.

    ``position`` (3,) in metres, vrecho's world frame (Z up); ``signal`` the separated mono
    signal (1-D float array at ``fs`` Hz) or the path of a WAV file holding it; ``confidence``
    in [0, 1]; ``uncertainty_m`` the position's standard error where one is known; ``name`` a
    label for people and for file names.
    """

    position: np.ndarray
    signal: np.ndarray | str | Path
    fs: int
    confidence: float = 1.0
    name: str = "source"
    uncertainty_m: float | None = None
