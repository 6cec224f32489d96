"""localization: the room's sound sources, separated and placed in 3D (issue 5).

- :class:`Capture` (capture.py): a stretch of multichannel recording at one device pose (the
  simulator makes them in :mod:`vrecho.sim.ambient`).
- :func:`locate` (locate.py): world positions from all captures at once; :func:`doa` (doa.py):
  pyroomacoustics' direction finders on one capture.
- :func:`separate` (separate.py): pyroomacoustics' AuxIVA, ILRMA, FastMNMF2, a single-channel
  NMF, and vrecho's separation informed by the positions: masknet.py's network gives each
  time-frequency bin's share of each located source (weights shipped in ``assets/``), a
  multichannel Wiener filter the sources' images; :func:`informed` says which tracks its guard
  kept (a track that could come out worse than the microphone is the microphone, flagged).
- :func:`place_sources`: both, giving :class:`PlacedSource` for :mod:`usd_export`.
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import linear_sum_assignment
from tqdm import tqdm

from vrecho.errors import VrechoError, check_count

from .capture import Capture
from .doa import doa
from .locate import MAX_SOURCES, Located, check_captures, locate
from .separate import SEPARATORS, informed, separate, steering
from .sources import PlacedSource

__all__ = ["Capture", "Located", "PlacedSource", "doa", "informed", "locate", "place_sources", "separate"]

CROSSFADE_S = 0.05
AGREEMENT_SURE = 1.3
"""The agreement (:func:`locate`) from which a source's confidence is its strength alone: the
benchmark's clear rooms reach 1.3 to 1.5, a source 0 dB over a diffuse field 1.4 (4 captures)."""


def place_sources(captures, n_sources: int | None = None, *, bounds=None, method: str = "informed",
                  progress: bool = False) -> list[PlacedSource]:
    """The sources heard across ``captures``: where each is and what it plays.

    Positions from :func:`locate`; each capture is separated with ``method`` (``informed``: steered by
    the positions, its guard reading their uncertainty) and each source's
    stretches are joined in capture order with short crossfades (``CROSSFADE_S``, 50 ms) into
    one signal at the captures' rate (stretches that were not recorded are not invented: the
    track is the captures' stretches back to back). Blind methods' outputs are matched to the
    positions by their coherence with a delay-and-sum beam toward each.

    Parameters
    ----------
    captures : Capture or iterable of Capture
        The walk's captures, at one sample rate, each with at least 2 microphones.
    n_sources : int, optional
        The most sources: 1 to the fewest microphones a capture has (what a multichannel
        method separates), and no more than :data:`localization.locate.MAX_SOURCES` (None: the
        count is estimated, up to the same and 4). Fewer come back where fewer stand clear of
        incoherent noise (:func:`locate`).
    bounds : tuple of two array_like [shape=(3,)], optional
        The search box's (low corner, high corner) in metres (:func:`locate`).
    method : str
        A multichannel method of :func:`separate`: "informed" (the default: steered by the
        positions), "auxiva", "ilrma" or "fastmnmf".
    progress : bool
        Show a progress bar over the captures (default False).

    Returns
    -------
    list of PlacedSource
        One per located source, named ``source_<i>``, its signal float32 at the captures' rate;
        ``confidence``: the source's share of the strongest source's map peak times how far
        the captures agree on it in the world rather than in their own frame (``agreement``
        of :func:`locate`: 0 at an agreement of 1 or less, as diffuse noise and crosstalk get,
        1 from :data:`AGREEMENT_SURE`; one half for a single capture, which cannot tell), in
        [0, 1];
        ``uncertainty_m``: the position's standard error in metres (None where unknown);
        ``flags``: ``"not separated in N of M captures"`` where informed separation's guard gave
        microphone 0 instead of a track that could have come out worse. Empty where no coherent
        source is heard (independent noise on each microphone).

    Raises
    ------
    VrechoError
        Before any work: for bad captures, a method that is not multichannel, an ``n_sources``
        out of its range, or bad ``bounds``; after it, as :func:`separate` does.
    """
    captures = check_captures(captures)
    multichannel = [name for name, sep in SEPARATORS.items() if sep.multichannel]
    if not isinstance(method, str) or method not in multichannel:
        raise VrechoError(f"method: place_sources separates with {', '.join(multichannel)}, got {method!r}")
    most = min(MAX_SOURCES, min(c.n_mics for c in captures))  # what every capture's separation takes
    if n_sources is not None:
        check_count(n_sources, "n_sources", most)
    located = locate(captures, n_sources, bounds=bounds, max_sources=min(4, most))
    k = len(located.positions)
    if k == 0:  # nothing stands clear of the microphones' own noise
        return []
    fs = captures[0].fs
    fade = int(CROSSFADE_S * fs)
    tracks = [np.zeros(0) for _ in range(k)]
    kept = np.zeros(k, int)
    for c in tqdm(captures, desc="separating", unit="capture", disable=not progress):
        if method == "informed":
            sep = informed(c, located.positions, uncertainty_m=located.uncertainty_m)
            y, kept = sep.signals, kept + sep.separated
        else:  # blind outputs come in any order: match them to the positions
            y = separate(c, k, method=method)
            y = y[_order_by_direction(c, y, located.positions)]
            kept += 1
        for i in range(k):
            tracks[i] = _join(tracks[i], y[i], fade)
    sure = 0.5 if len(captures) == 1 else float(np.clip((located.agreement - 1) / (AGREEMENT_SURE - 1), 0, 1))
    return [PlacedSource(located.positions[i], tracks[i].astype(np.float32), fs,
                         float(np.clip(located.strength[i], 0, 1)) * sure,
                         f"source_{i}", None if not np.isfinite(located.uncertainty_m[i]) else float(located.uncertainty_m[i]),
                         () if kept[i] == len(captures) else (f"not separated in {len(captures) - kept[i]} of {len(captures)} captures",))
            for i in range(k)]


def _join(a: np.ndarray, b: np.ndarray, fade: int) -> np.ndarray:
    if len(a) < fade or len(b) < fade:
        return np.concatenate([a, b])
    ramp = np.linspace(0.0, 1.0, fade)
    return np.concatenate([a[:-fade], a[-fade:] * (1 - ramp) + b[:fade] * ramp, b[fade:]])


def _order_by_direction(capture: Capture, y: np.ndarray, positions: np.ndarray) -> np.ndarray:
    """Which separated output belongs to which position: the one most coherent, at microphone
    0, with the capture's delay-and-sum beam toward that position."""
    n = capture.audio.shape[1]
    spec = np.fft.rfft(capture.audio, axis=1)
    A = steering(capture, positions, np.fft.rfftfreq(n, 1 / capture.fs))  # (F, M, K)
    beams = np.fft.irfft(np.einsum("fmk,mf->kf", np.conj(A / np.abs(A)), spec) / capture.n_mics, n)
    with np.errstate(invalid="ignore", divide="ignore"):  # a silent output correlates with nothing
        score = np.nan_to_num(np.abs(np.corrcoef(np.vstack([beams, y]))[:len(positions), len(positions):]))
    _, cols = linear_sum_assignment(-score)
    return cols
