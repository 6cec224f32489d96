"""The time-frequency bins that vote in :func:`localization.locate`: the onsets, where a
source's direct sound dominates the room's reverberation (its energy rises over the frames just
before it)."""

from __future__ import annotations

import numpy as np

ONSET_FRAMES = 3
"""How many frames before a bin its energy is averaged over."""
ONSET_RATIO = 2.0
"""How many times that average a bin's energy must reach to vote."""


def onset_bins(energy: np.ndarray) -> np.ndarray:
    """The bins that vote: above :data:`ONSET_RATIO` times the mean of their frequency's
    :data:`ONSET_FRAMES` frames before them, and above their frequency's 30th percentile.

    Parameters
    ----------
    energy : numpy.ndarray [shape=(F, T)]
        Each bin's energy summed over the microphones.

    Returns
    -------
    numpy.ndarray [shape=(F, T)], bool
    """
    before = np.full_like(energy, np.inf)
    before[:, ONSET_FRAMES:] = np.stack([energy[:, ONSET_FRAMES - i:energy.shape[1] - i]
                                         for i in range(1, ONSET_FRAMES + 1)]).mean(axis=0)
    return (energy > ONSET_RATIO * before) & (energy > np.quantile(energy, 0.3, axis=1, keepdims=True))
