"""localization: the room's sound sources, separated and placed in 3D (issue 5).

- :class:`Capture` (capture.py): a stretch of multichannel recording at one device pose;
  :func:`simulate_walk_capture` records a room's ambient sources (:mod:`localization.sounds`)
  along a walkthrough with the foundation's acoustics; :func:`hear_scene` a scene's own sources
  along its camera path.
- :func:`locate` (locate.py): world positions from all captures at once; :func:`doa`:
  pyroomacoustics' direction finders on one capture.
- :func:`separate` (separate.py): pyroomacoustics' AuxIVA, ILRMA, FastMNMF2, a single-channel
  NMF, and vrecho's separation informed by the positions: masknet.py's network gives each
  time-frequency bin's share of each located source (weights shipped in ``assets/``), a
  multichannel Wiener filter the sources' images.
- :func:`place_sources`: both, giving :class:`PlacedSource` for :mod:`usd_export`.
"""

from __future__ import annotations

import numpy as np

from vrecho.errors import VrechoError

from .capture import Capture, hear_scene, simulate_walk_capture
from .locate import Located, doa, locate
from .separate import separate
from .sources import PlacedSource

__all__ = ["Capture", "Located", "PlacedSource", "doa", "hear_scene", "locate", "place_sources", "separate",
           "simulate_walk_capture"]

CROSSFADE_S = 0.05


def place_sources(captures, n_sources: int | None = None, bounds=None, method: str = "informed",
                  progress: bool = False) -> list[PlacedSource]:
    """The sources heard across ``captures``: where each is and what it plays.

    Positions from :func:`locate` (``n_sources`` None: the count is estimated); each capture is
    separated with ``method`` (``informed``: steered by those positions) and each source's
    stretches are joined in capture order with short crossfades into one signal at the
    captures' rate (stretches that were not recorded are not invented: the track is the
    captures' stretches back to back). ``confidence``: the source's share of the strongest
    source's map peak; ``uncertainty_m``: the position's standard error.
    """
    from .locate import check_captures

    captures = check_captures(captures)
    if method not in ("informed", "auxiva", "ilrma", "fastmnmf"):  # before the work
        raise VrechoError(f"method: place_sources separates with informed, auxiva, ilrma or fastmnmf, got {method!r}")
    located = locate(captures, n_sources, bounds)
    k = len(located.positions)  # separate refuses more sources than a capture has microphones
    fs = captures[0].fs
    fade = int(CROSSFADE_S * fs)
    tracks = [np.zeros(0) for _ in range(k)]
    iterator = captures
    if progress:
        from tqdm import tqdm

        iterator = tqdm(captures, desc="separating", unit="capture")
    for c in iterator:
        y = separate(c, k, method, positions=located.positions)
        if method != "informed":  # blind outputs come in any order: match them to the positions
            y = y[_order_by_direction(c, y, located.positions)]
        for i in range(k):
            tracks[i] = _join(tracks[i], y[i], fade)
    return [PlacedSource(located.positions[i], tracks[i].astype(np.float32), fs, float(np.clip(located.strength[i], 0, 1)),
                         f"source_{i}", None if not np.isfinite(located.uncertainty_m[i]) else float(located.uncertainty_m[i]))
            for i in range(k)]


def _join(a: np.ndarray, b: np.ndarray, fade: int) -> np.ndarray:
    if len(a) < fade or len(b) < fade:
        return np.concatenate([a, b])
    ramp = np.linspace(0.0, 1.0, fade)
    return np.concatenate([a[:-fade], a[-fade:] * (1 - ramp) + b[:fade] * ramp, b[fade:]])


def _order_by_direction(capture: Capture, y: np.ndarray, positions: np.ndarray) -> np.ndarray:
    """Which separated output belongs to which position: the one most coherent, at microphone
    0, with the capture's delay-and-sum beam toward that position."""
    from scipy.optimize import linear_sum_assignment

    from .separate import steering

    n = capture.audio.shape[1]
    spec = np.fft.rfft(capture.audio, axis=1)
    A = steering(capture, positions, np.fft.rfftfreq(n, 1 / capture.fs))  # (F, M, K)
    beams = np.fft.irfft(np.einsum("fmk,mf->kf", np.conj(A / np.abs(A)), spec) / capture.n_mics, n)
    score = np.abs(np.corrcoef(np.vstack([beams, y]))[:len(positions), len(positions):])
    _, cols = linear_sum_assignment(-score)
    return cols
