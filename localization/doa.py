"""Directions of arrival on one capture by pyroomacoustics' grid-based methods (:func:`doa`),
the per-capture baseline :func:`localization.locate` is compared with in
``benchmarks/bench_localization.py``."""

from __future__ import annotations

import numpy as np

from vrecho.errors import VrechoError, check_count
from vrecho.signals import SPEED_OF_SOUND

from .capture import Capture
from .locate import BAND_HZ, MAX_SOURCES, NFFT, band_bins, check_captures, stft

PRA_METHODS: tuple[str, ...] = ("MUSIC", "NormMUSIC", "SRP", "CSSM", "WAVES", "TOPS")
"""pyroomacoustics' grid-based DOA methods (FRIDA works in the plane only)."""
MAX_DOA_GRID = 100_000
"""The most points of :func:`doa`'s sphere grid (0.7 degrees apart)."""


def doa(capture: Capture, n_sources: int, *, method: str = "NormMUSIC", n_grid: int = 6000,
        n_freq: int | None = None) -> np.ndarray:
    """Directions of the sources one capture hears, by a pyroomacoustics method.

    Parameters
    ----------
    capture : Capture
        The capture, with at least 2 microphones.
    n_sources : int
        How many directions to give, 1 to :data:`MAX_SOURCES`; MUSIC, NormMUSIC, CSSM, WAVES
        and TOPS find fewer sources than microphones.
    method : str
        One of :data:`PRA_METHODS` (default "NormMUSIC").
    n_grid : int
        The number of points of the sphere grid searched, 100 to :data:`MAX_DOA_GRID` (default
        6000).
    n_freq : int, optional
        Use only that many frequency bins (2 to the band's), evenly spread over the band
        :data:`BAND_HZ` (CSSM, WAVES and TOPS take about 20 s per capture on all of them);
        None: the whole band.

    Returns
    -------
    numpy.ndarray [shape=(n_sources, 3)]
        Unit vectors from the array centre (world frame); where the method finds fewer peaks
        than asked, the strongest is repeated.

    Raises
    ------
    VrechoError
        For a bad capture, an unknown method, an ``n_sources``, ``n_grid`` or ``n_freq`` out of
        its range, or too many sources for the method.
    """
    import pyroomacoustics as pra  # heavy (1.4 s to import): only where it simulates or analyses

    if not isinstance(capture, Capture):
        raise VrechoError(f"capture: expected a localization.Capture, got {type(capture).__name__}")
    (capture,) = check_captures([capture])
    if method not in PRA_METHODS:
        raise VrechoError(f"method: expected one of {PRA_METHODS}, got {method!r}")
    check_count(n_sources, "n_sources", MAX_SOURCES)
    if method in ("MUSIC", "NormMUSIC", "CSSM", "WAVES", "TOPS") and n_sources >= capture.n_mics:
        raise VrechoError(f"{method} finds fewer sources than microphones: {n_sources} sources with "
                          f"{capture.n_mics} microphones")
    check_count(n_grid, "n_grid", MAX_DOA_GRID, 100)
    if n_freq is not None:  # TOPS, CSSM and WAVES fail on a single frequency
        check_count(n_freq, "n_freq", int(np.sum(band_bins(capture.fs))), 2)
    L = (capture.mics - capture.center).T
    X = stft(capture.audio)
    d = pra.doa.algorithms[method](L, capture.fs, NFFT, c=SPEED_OF_SOUND, num_src=n_sources, dim=3, n_grid=n_grid)
    if n_freq is None:
        d.locate_sources(X, freq_range=list(BAND_HZ))
    else:
        bins = np.flatnonzero(band_bins(capture.fs))
        d.locate_sources(X, freq_bins=bins[np.linspace(0, len(bins) - 1, n_freq).round().astype(int)])
    az, col = np.asarray(d.azimuth_recon), np.asarray(d.colatitude_recon)
    out = np.stack([np.cos(az) * np.sin(col), np.sin(az) * np.sin(col), np.cos(col)], -1)
    if len(out) < n_sources:  # fewer peaks than asked: repeat the strongest
        out = np.vstack([out, np.repeat(out[:1], n_sources - len(out), axis=0)])
    return out
