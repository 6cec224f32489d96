"""Separation of the sources one capture hears, as each sounds at the reference microphone 0.

Methods:

- ``auxiva``, ``ilrma``, ``fastmnmf``: pyroomacoustics' blind multichannel separation (AuxIVA,
  OverIVA when there are more microphones than sources; ILRMA, determined, on microphone 0 and
  the ``k - 1`` farthest from it; FastMNMF2), scaled back to microphone 0 by projection.
- ``nmf``: the single-channel fallback: KL-NMF of microphone 0's magnitude spectrogram, its
  components grouped into sources by the similarity of their activations, Wiener masks.
- ``informed`` (vrecho's, needs ``positions``): what vrecho knows goes in. The sources'
  positions (from :func:`localization.locate`) give each frequency's near-field steering
  vectors; :mod:`localization.masknet`, a small network trained on simulated walks, turns them
  and microphone 0's spectrogram into each time-frequency bin's share of each source (so
  source k is the same source at every frequency: no permutation problem). Each source's
  spatial covariance is estimated from its shares, the multichannel Wiener filter R_k R_x^-1
  gives its image at microphone 0 (the filter keeps what the steering model misses:
  reverberation), and the share's square root, bin by bin, takes out what a time-invariant
  filter cannot. Runs at 16 kHz (a capture at another rate is resampled to it and back).

Every method returns an array (k, samples), the capture's length, in the order of
``positions`` for ``informed``.
"""

from __future__ import annotations

import numpy as np

from vrecho.acoustics import SPEED_OF_SOUND
from vrecho.errors import VrechoError

from .capture import Capture

METHODS: tuple[str, ...] = ("auxiva", "ilrma", "fastmnmf", "nmf", "informed")
BLIND_FRAME_S = 0.016
"""STFT frame of blind separation: 16 ms (256 points at 16 kHz). A capture of 1.5 s then gives
the blind methods some 370 frames to learn their demixing from; 128 ms frames (as long as the
rooms' reverberation) left them 47 and lost 2 to 4 dB SDR on the tuning rooms (seed 7700)."""


def _blind_nfft(fs: int) -> int:
    return int(2 ** round(np.log2(BLIND_FRAME_S * fs)))


def _stft(audio: np.ndarray, nfft: int) -> np.ndarray:
    """(frames, freq, channels), as pyroomacoustics' separation expects."""
    import pyroomacoustics as pra

    win = pra.hann(nfft)
    return np.stack([pra.transform.stft.analysis(ch, nfft, nfft // 4, win=win) for ch in audio], axis=-1)


def _istft(Y: np.ndarray, n: int, nfft: int) -> np.ndarray:
    """(k, n) signals from (frames, freq, k) spectra."""
    import pyroomacoustics as pra

    out = np.zeros((Y.shape[-1], n))
    win = pra.transform.stft.compute_synthesis_window(pra.hann(nfft), nfft // 4)
    for k in range(Y.shape[-1]):
        y = pra.transform.stft.synthesis(Y[:, :, k], nfft, nfft // 4, win=win)[nfft - nfft // 4:]  # its delay
        out[k, :min(n, len(y))] = y[:n]
    return out


def separate(capture: Capture, n_sources: int, method: str = "informed", positions=None,
             n_iter: int | None = None) -> np.ndarray:
    """Separate ``n_sources`` sources from ``capture`` (see the module's docstring); ``n_iter``:
    the iterations of the blind methods and NMF (informed separation has none)."""
    if not isinstance(capture, Capture):
        raise VrechoError(f"capture: expected a localization.Capture, got {type(capture).__name__}")
    if method not in METHODS:
        raise VrechoError(f"method: expected one of {METHODS}, got {method!r}")
    if isinstance(n_sources, bool) or not isinstance(n_sources, (int, np.integer)) or n_sources < 1:
        raise VrechoError(f"n_sources: expected a positive whole number, got {n_sources!r}")
    m = capture.n_mics
    if method in ("auxiva", "ilrma", "fastmnmf", "informed") and n_sources > m:
        raise VrechoError(f"{method} separates at most as many sources as microphones: {n_sources} sources, "
                          f"{m} microphone{'s' if m > 1 else ''} (use method='nmf' for one channel)")
    if method == "informed":
        if positions is None:
            raise VrechoError("informed separation needs the sources' positions (localization.locate)")
        positions = np.asarray(positions, dtype=float)
        if positions.shape != (n_sources, 3) or not np.all(np.isfinite(positions)):
            raise VrechoError(f"positions: expected ({n_sources}, 3) finite positions, got shape {positions.shape}")
    n = capture.audio.shape[1]
    if method == "nmf":
        return _nmf(capture.audio[0], n_sources, n_iter or 200)
    if method == "informed":
        return _informed(capture, positions)
    import pyroomacoustics as pra

    nfft = _blind_nfft(capture.fs)
    X = _stft(capture.audio, nfft)
    if method == "auxiva":
        Y = pra.bss.auxiva(X, n_src=n_sources, n_iter=n_iter or 50, proj_back=True)
    elif method == "ilrma":  # determined: microphone 0 and the n_sources - 1 farthest from it
        far = np.argsort(np.linalg.norm(capture.mics - capture.mics[0], axis=1))[::-1][:n_sources - 1]
        try:
            Y = pra.bss.ilrma(X[:, :, np.r_[0, np.sort(far)]], n_src=n_sources, n_iter=n_iter or 50, proj_back=True)
        except np.linalg.LinAlgError:
            raise VrechoError("ilrma: the demixing matrix became singular (try auxiva or informed)") from None
    else:
        Y = pra.bss.fastmnmf2(X, n_src=n_sources, n_iter=n_iter or 50, mic_index=0)
    return _istft(Y, n, nfft)


def steering(capture: Capture, positions: np.ndarray, freqs: np.ndarray) -> np.ndarray:
    """Near-field steering vectors (freq, mics, sources), relative to microphone 0."""
    dist = np.linalg.norm(capture.mics[None] - positions[:, None], axis=-1).T  # (M, K)
    rel = dist - dist[:1]
    return (dist[:1] / dist)[None] * np.exp(-2j * np.pi * freqs[:, None, None] * rel[None] / SPEED_OF_SOUND)


def _informed(capture: Capture, positions: np.ndarray) -> np.ndarray:
    """(k, samples) at the capture's rate: the mask network's shares (at 16 kHz) weight each
    source's spatial covariance; the multichannel Wiener filter R_k R_x^-1 (R_x the measured
    covariance, so the microphones' noise is in it) gives its image at microphone 0, and the
    square root of its share, bin by bin, takes out what the time-invariant filter let through."""
    from scipy.signal import resample_poly

    from . import masknet

    fs, nfft = masknet.FS, masknet.NFFT
    n = capture.audio.shape[1]
    g = np.gcd(capture.fs, fs)
    audio = capture.audio if capture.fs == fs else resample_poly(capture.audio, fs // g, capture.fs // g, axis=1)
    X = _stft(audio, nfft)
    share = masknet.source_masks(X, steering(capture, positions, np.fft.rfftfreq(nfft, 1 / fs)))
    n_frames, _, m = X.shape
    Rx = np.einsum("tfm,tfn->fmn", X, np.conj(X)) / n_frames
    iRx = np.linalg.inv(Rx + 1e-9 * np.trace(Rx, axis1=-2, axis2=-1).real.mean() * np.eye(m))
    out = np.zeros(share.shape, dtype=complex)
    for k in range(share.shape[-1]):
        Rk = np.einsum("tf,tfm,tfn->fmn", share[..., k] ** 2, X, np.conj(X)) / n_frames
        out[..., k] = np.einsum("fn,tfn->tf", (Rk @ iRx)[:, 0], X) * np.sqrt(share[..., k])
    if capture.fs == fs:
        return _istft(out, n, nfft)
    y = resample_poly(_istft(out, audio.shape[1], nfft), capture.fs // g, fs // g, axis=1)  # back to the capture's rate
    return np.pad(y[:, :n], ((0, 0), (0, max(0, n - y.shape[1]))))


def _nmf(x: np.ndarray, k: int, n_iter: int, per_source: int = 8, nfft: int = 1024) -> np.ndarray:
    """Single-channel separation by KL-NMF (see the module's docstring)."""
    import scipy.cluster.hierarchy as hc

    S = _stft(x[None], nfft)[:, :, 0]  # (T, F)
    V = np.abs(S).T + 1e-9  # (F, T)
    rng = np.random.default_rng(0)
    r = k * per_source
    W = rng.uniform(0.1, 1.0, (V.shape[0], r))
    H = rng.uniform(0.1, 1.0, (r, V.shape[1]))
    for _ in range(n_iter):
        H *= (W.T @ (V / (W @ H))) / W.sum(axis=0)[:, None]
        W *= ((V / (W @ H)) @ H.T) / H.sum(axis=1)[None]
    act = np.log(H + 1e-9)
    groups = hc.fcluster(hc.linkage(act, "average", metric="correlation"), k, "maxclust") - 1
    parts = np.stack([W[:, groups == g] @ H[groups == g] if np.any(groups == g) else np.zeros_like(V)
                      for g in range(k)])
    masks = parts / (parts.sum(axis=0) + 1e-12)
    Y = (masks * S.T[None]).transpose(2, 1, 0)  # (T, F, k)
    return _istft(Y, len(x), nfft)
