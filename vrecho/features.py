"""Features of 1 s frames: the paper's log-mel spectrogram, and echo features that use the
emitted sound where it is known.

The log-mel spectrogram follows the paper: 2048-sample Hann window, hop 512, mel power in dB,
62 mel bands, 25 time bins (means over groups of STFT frames), each spectrogram normalised to zero
mean and unit variance. At 25 time bins per second one bin spans 40 ms, far coarser than the
1.5 to 17.5 ms echo delays of surfaces 0.25 to 3 m away; hence the echo features: with the emitted
sound known, circular Wiener deconvolution of the frame recovers the room's impulse response
(the frame is the steady state of a pulse train, a circular convolution), from which echo delays
can be read to a fraction of a sample and band energies to a few milliseconds. With a surface's
distance known as well (a scan's plane), :mod:`vrecho.planes` reads what the response holds
where that plane must echo. With the emitted sound unknown (the paper's protocol), :func:`self_features`
reads the same delays off the recording's own whitened autocorrelation: the direct sound is the
reference.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import librosa
import numpy as np
import scipy.fft
import scipy.ndimage
import scipy.signal

from .device import MIC_ABOVE_EMITTER_M
from .errors import VrechoError, check_float32
from .signals import FS, SPEED_OF_SOUND, check_fs, hilbert_envelope

N_FFT = 2048
HOP = 512
N_MELS = 62
N_TIME = 25
FRAME_S = 1.0
ECHO_WINDOW_S = 0.03
"""Length of the early impulse response kept as an echo feature: round trips up to 5 m."""
DECAY_BANDS_HZ = (125, 250, 500, 1000, 2000, 4000, 8000)
BAND_FS = 40_000
"""The lowest sample rate, in Hz, that holds the probe's band (200 Hz to 18 kHz, up to 0.45 of
the rate): EchoCNN learned from 44.1 kHz frames, so a frame recorded at a lower rate, resampled,
lacks what it reads depth and material from (an 8 kHz frame said 3.43 m where 44.1 kHz said
1.20 m)."""
def check_frames(audio, fs) -> np.ndarray:
    """Validate 1 s frames, shape (n,) or (B, n) at ``fs`` Hz, and return them at 44.1 kHz (float32).

    Another sample rate is resampled (never silently assumed); a frame of the wrong length,
    or with NaN or infinite samples, is a :class:`VrechoError`.

    Parameters
    ----------
    audio : array_like, shape (n,) or (B, n), numbers
        One frame or a batch of frames, n = round(``fs``) samples each.
    fs : int
        Sample rate in Hz.

    Returns
    -------
    numpy.ndarray, shape (44100,) or (B, 44100), float32
        The frames at 44.1 kHz (a copy); resampled frames are cut or zero-padded to exactly
        44100 samples.

    Raises
    ------
    VrechoError
        If ``fs`` is not a valid sample rate, ``audio`` is not a 1-D or 2-D array of numbers,
        a frame is not 1 s long, or a sample is NaN or infinite.
    """
    fs = check_fs(fs)
    try:
        x = np.asarray(audio)
    except (ValueError, TypeError):  # ragged lists: frames of different lengths
        raise VrechoError("audio: expected a frame or frames of one length (an array), got ragged sequences") from None
    if x.dtype.kind not in "fiu" or x.ndim not in (1, 2):
        raise VrechoError(f"audio: expected a 1-D frame or a 2-D batch of frames of numbers, got shape {x.shape} ({x.dtype})")
    n = int(round(FRAME_S * fs))
    if x.shape[-1] != n:
        raise VrechoError(f"audio: a frame is {FRAME_S:g} s, {n} samples at {fs} Hz; got {x.shape[-1]}")
    x = check_float32(x, "audio")
    if fs != FS:
        x = librosa.resample(x, orig_sr=fs, target_sr=FS, res_type="soxr_hq", axis=-1).astype(np.float32)
        x = x[..., :FS] if x.shape[-1] >= FS else np.pad(x, [(0, 0)] * (x.ndim - 1) + [(0, FS - x.shape[-1])])
    return x


@functools.lru_cache(maxsize=1)
def _window() -> np.ndarray:
    return scipy.signal.get_window("hann", N_FFT, fftbins=True).astype(np.float32)


@functools.lru_cache(maxsize=1)
def _mel_blocks() -> tuple[tuple[int, int, int, int, np.ndarray], ...]:
    """librosa's mel filters (STFT bins by mel bands, float32, built once: 2 ms a call) as
    :data:`_MEL_BLOCKS` blocks of bins, each with only the bands it feeds: (first and last bin
    times two, first and last band, the block's weights with each row twice, one for a bin's
    real part squared and one for its imaginary part's). A band's triangle spans a few bins
    low and some hundred high: 3 % of the dense matrix's weights are not zero, and the blocks
    hold 15 % of it (one thread, this 2-core machine: the power and the product 0.19 -> 0.07 ms
    a frame, the same sums in another order, 2e-7 of the largest apart)."""
    basis = librosa.filters.mel(sr=FS, n_fft=N_FFT, n_mels=N_MELS, fmax=FS / 2).T.astype(np.float32)
    used = basis > 0
    count = np.cumsum(used.sum(axis=1))  # blocks of equal weights
    edges = [0, *np.searchsorted(count, np.linspace(0, count[-1], _MEL_BLOCKS + 1)[1:-1]), len(basis)]
    blocks = []
    for a, b in zip(edges[:-1], edges[1:]):
        bands = np.flatnonzero(used[a:b].any(axis=0))
        if b > a and len(bands):
            c, d = int(bands[0]), int(bands[-1]) + 1
            blocks.append((2 * a, 2 * b, c, d, np.ascontiguousarray(np.repeat(basis[a:b, c:d], 2, axis=0))))
    return tuple(blocks)


_MEL_BLOCKS = 8


SILENCE_RMS = 1e-6
"""Frames quieter than this (RMS) are silent (:func:`check_sounding`)."""


def check_sounding(x: np.ndarray) -> None:
    """Refuse checked frames of which one is silent (RMS below :data:`SILENCE_RMS`).

    Parameters
    ----------
    x : numpy.ndarray, shape (B, n) or (n,)
        Frames :func:`check_frames` took.

    Raises
    ------
    VrechoError
        Naming the first silent frame.
    """
    with np.errstate(over="ignore"):  # (single precision, summed pairwise; a square beyond its range: loud, not silent)
        rms = np.sqrt(np.mean(np.square(x, dtype=np.float32), axis=-1)).reshape(-1)
    if np.any(rms < SILENCE_RMS):
        raise VrechoError(f"audio: frame {int(np.argmax(rms < SILENCE_RMS))} is silent "
                          f"(RMS below {SILENCE_RMS:g}): is the microphone on?")


def check_emitted(emitted, fs, n_frames: int | None = None) -> np.ndarray:
    """Validate the emitted sound(s) and return them at 44.1 kHz (float32).

    One sound (k,) for every frame, or, with ``n_frames``, one per frame (n_frames, k). Each
    must be finite, not silent and at most one frame long; another sample rate is resampled.

    Parameters
    ----------
    emitted : array_like, shape (k,) or (n_frames, k), numbers
        The emitted sound(s), at most round(``fs``) samples long.
    fs : int
        Sample rate in Hz.
    n_frames : int, optional
        Number of frames; only with it is one sound per frame accepted.

    Returns
    -------
    numpy.ndarray, shape (k',) or (n_frames, k'), float32
        The sound(s) at 44.1 kHz (a copy); k' = k unless resampled.

    Raises
    ------
    VrechoError
        If ``fs`` is not a valid sample rate, ``emitted`` is None, has another shape or is not numbers,
        has NaN or infinite samples, is longer than a 1 s frame, or a sound is silent (all
        zero).
    """
    fs = check_fs(fs)
    if emitted is None:
        raise VrechoError("emitted: required here: the sound the device played, at the frames' rate")
    try:
        s = np.asarray(emitted)
    except (ValueError, TypeError):
        raise VrechoError("emitted: expected a sound or sounds of one length (an array), got ragged sequences") from None
    if s.size == 0:
        raise VrechoError("emitted: expected at least one sample, got none")
    if s.dtype.kind not in "fiu" or s.ndim not in (1, 2) or (s.ndim == 2 and len(s) != n_frames):
        per_frame = "" if n_frames is None else f" or one per frame ({n_frames}, k)"
        raise VrechoError(f"emitted: expected one sound (k,){per_frame}, got shape {s.shape}")
    s = check_float32(s, "emitted")
    if s.shape[-1] > round(FRAME_S * fs):
        raise VrechoError(f"emitted: longer than a 1 s frame ({s.shape[-1]} samples at {fs} Hz)")
    if np.any(np.abs(s).max(axis=-1) == 0):
        raise VrechoError("emitted: the emitted sound is silent")
    if fs != FS:
        s = librosa.resample(s, orig_sr=fs, target_sr=FS, res_type="soxr_hq", axis=-1).astype(np.float32)
    return s


def logmel(audio, fs: int = FS) -> np.ndarray:
    """The paper's normalised log-mel spectrogram.

    Parameters
    ----------
    audio : array_like, shape (n,) or (B, n), float
        One or more 1 s frames, n = round(``fs``) samples.
    fs : int
        Sample rate in Hz (resampled to 44.1 kHz); :data:`~vrecho.signals.FS` by default.

    Returns
    -------
    numpy.ndarray, shape (62, 25) or (B, 62, 25), float32
        Mel bands (low to high) by time bins; each spectrogram has zero mean and unit variance.

    Raises
    ------
    VrechoError
        For frames :func:`check_frames` refuses.

    Examples
    --------
    >>> frame = np.random.default_rng(0).standard_normal(44_100)
    >>> logmel(frame).shape
    (62, 25)
    """
    x = check_frames(audio, fs)
    batch = x.reshape(-1, x.shape[-1])
    out = np.empty((len(batch), N_MELS, N_TIME), np.float32)
    for i in range(0, len(batch), _LOGMEL_CHUNK):  # a few frames at a time: their STFT stays in cache
        out[i:i + _LOGMEL_CHUNK] = _pooled_db(batch[i:i + _LOGMEL_CHUNK])
    mean = out.mean(axis=(-2, -1), keepdims=True)
    std = out.std(axis=(-2, -1), keepdims=True)
    return ((out - mean) / np.maximum(std, 1e-6)).reshape(*x.shape[:-1], N_MELS, N_TIME)


_LOGMEL_CHUNK = 4


def _pooled_db(x: np.ndarray) -> np.ndarray:
    """Mel power in dB of frames (B, n), pooled into :data:`N_TIME` bins: (B, 62, 25) float32.

    librosa's centred STFT (zero padding by N_FFT / 2, periodic Hann), framed by hand, its
    melspectrogram and ``power_to_db(ref=1, amin=1e-10)``: the same numbers (within float32's
    rounding) in two thirds of the time, which is most of a prediction's budget."""
    padded = np.pad(x, [(0, 0), (N_FFT // 2, N_FFT // 2)])
    frames = np.lib.stride_tricks.sliding_window_view(padded, N_FFT, axis=-1)[..., ::HOP, :]
    squares = np.square(scipy.fft.rfft(frames * _window(), axis=-1).view(np.float32))  # real, imaginary, ...
    mel = np.zeros((*squares.shape[:-1], N_MELS), np.float32)
    for a, b, c, d, weights in _mel_blocks():  # the power of each bin (its two squares) into its bands
        mel[..., c:d] += squares[..., a:b] @ weights
    db = 10 * np.log10(np.maximum(mel, 1e-10))  # (B, STFT frames, mel bands)
    starts, counts = _time_bins(db.shape[-2])
    return (np.add.reduceat(db, starts, axis=-2) / counts[:, None]).transpose(0, 2, 1)


@functools.lru_cache(maxsize=4)
def _time_bins(n: int) -> tuple[np.ndarray, np.ndarray]:
    """The first STFT frame of each of :data:`N_TIME` near-equal groups of ``n``, and their sizes."""
    starts = np.array([g[0] for g in np.array_split(np.arange(n), N_TIME)])
    return starts, np.diff(np.append(starts, n)).astype(np.float32)


def echo_response(audio, emitted, fs: int = FS, *, length_s: float | None = ECHO_WINDOW_S,
                  regularization: float = 1e-3) -> np.ndarray:
    """The room's impulse response estimated from a frame and the known emitted sound.

    Circular Wiener deconvolution over the whole frame: ``H = X S* / (|S|^2 + r max|S|^2)``. Sample
    0 is the emission instant; where the sound has no energy (a pure tone's other frequencies)
    the estimate has none either.

    Parameters
    ----------
    audio : array_like, shape (n,) or (B, n), float
        1 s frames starting at the pulse onset, n = round(``fs``) samples.
    emitted : array_like, shape (k,) or (B, k), float
        The emitted sound at the same rate: one for every frame, or one per frame.
    fs : int
        Sample rate of both, in Hz (resampled to 44.1 kHz).
    length_s : float or None
        Keep the first ``length_s`` seconds (all of it with None); 30 ms
        (:data:`ECHO_WINDOW_S`) by default.
    regularization : float
        Noise floor relative to the sound's strongest bin (power); 1e-3 by default.

    Returns
    -------
    numpy.ndarray, shape (..., round(length_s * 44100)), float32
        The impulse response at 44.1 kHz, sample 0 at emission; (..., 44100) with
        ``length_s=None``.

    Raises
    ------
    VrechoError
        For frames :func:`check_frames` refuses or sounds :func:`check_emitted` refuses.

    Examples
    --------
    A frame holding the probe and one echo of half its amplitude, 300 samples later:

    >>> from vrecho.signals import probe
    >>> s = probe()
    >>> x = np.zeros(44_100, np.float32)
    >>> x[:4410] += s
    >>> x[300:4710] += 0.5 * s
    >>> h = echo_response(x, s)
    >>> h.shape
    (1323,)
    >>> int(np.argmax(h[100:])) + 100
    300
    """
    x = check_frames(audio, fs)
    h = deconvolve(x, check_emitted(emitted, fs, None if x.ndim == 1 else len(x)), regularization)
    return h if length_s is None else h[..., :int(round(length_s * FS))]


def deconvolve(x: np.ndarray, s: np.ndarray, regularization: float = 1e-3) -> np.ndarray:
    """:func:`echo_response` of checked frames, whole: their spectra times the sounds' Wiener
    inverse filter, back in time, float32. One deconvolution for every reader of it
    (:func:`response_features`, :func:`vrecho.planes.plane_echo_from_responses`).

    Parameters
    ----------
    x : numpy.ndarray, shape (..., n)
        Frames :func:`check_frames` took.
    s : numpy.ndarray, shape (k,) or (..., k)
        Sounds :func:`check_emitted` took: one for every frame (its filter cached), or one each.
    regularization : float
        The inverse filter's floor, as a share of the sound's strongest bin's power.

    Returns
    -------
    numpy.ndarray, shape (..., n), float32
    """
    n = x.shape[-1]
    if s.ndim == 1:  # one sound for every frame: its inverse filter, cached (a device repeats its probe)
        G = _cached_inverse_filter(s.tobytes(), n, regularization)
    else:
        G = _inverse_filter(s, n, regularization)
    X = scipy.fft.rfft(x, n)
    np.multiply(X, G, out=X)
    return scipy.fft.irfft(X, n, overwrite_x=True).astype(np.float32, copy=False)


def _inverse_filter(s: np.ndarray, n: int, regularization: float) -> np.ndarray:
    """Wiener inverse filter ``S* / (|S|^2 + r max|S|^2)`` of sounds (..., k), n-point."""
    S = scipy.fft.rfft(s, n)
    power = np.abs(S) ** 2
    return np.conj(S) / (power + regularization * power.max(axis=-1, keepdims=True))


@functools.lru_cache(maxsize=8)
def _cached_inverse_filter(sound: bytes, n: int, regularization: float) -> np.ndarray:
    return _inverse_filter(np.frombuffer(sound, np.float32), n, regularization)


@dataclass
class EchoFeatures:
    """Echo features of one or more frames.

    Attributes
    ----------
    envelope : numpy.ndarray, shape (..., 1323), float32
        Hilbert envelope of the first 30 ms of the estimated impulse response, divided by its
        direct-sound peak (the largest value in the first 2 ms).
    bands : numpy.ndarray, shape (..., 7, 20), float32
        Log energy of the estimated response in the octave bands of :data:`DECAY_BANDS_HZ` over
        20 bins of 25 ms (0 to 0.5 s), in dB relative to the strongest cell, floored at -120 dB.
    """

    envelope: np.ndarray
    bands: np.ndarray


def echo_features(audio, emitted, fs: int = FS) -> EchoFeatures:
    """:class:`EchoFeatures` of frames whose emitted sound is known.

    Both come from the impulse response of :func:`echo_response` over the whole frame; the
    band energies from a Hann-windowed FFT of each 25 ms segment.

    Parameters
    ----------
    audio : array_like, shape (n,) or (B, n), float
        1 s frames starting at the pulse onset, n = round(``fs``) samples.
    emitted : array_like, shape (k,) or (B, k), float
        The emitted sound at the same rate: one for every frame, or one per frame.
    fs : int
        Sample rate of both, in Hz (resampled to 44.1 kHz).

    Returns
    -------
    EchoFeatures
        ``envelope`` (..., 1323) and ``bands`` (..., 7, 20), float32.

    Raises
    ------
    VrechoError
        For frames :func:`check_frames` refuses or sounds :func:`check_emitted` refuses.
    """
    x = check_frames(audio, fs)
    return response_features(deconvolve(x, check_emitted(emitted, fs, None if x.ndim == 1 else len(x))))


def response_features(h: np.ndarray) -> EchoFeatures:
    """:func:`echo_features` of impulse responses, :func:`deconvolve`'s: for a caller that reads
    more of one deconvolution (:func:`vrecho.planes.plane_echo_from_responses`).

    Parameters
    ----------
    h : numpy.ndarray, shape (..., n), float32
        The frames' whole responses (n >= 0.5 s at 44.1 kHz).

    Returns
    -------
    EchoFeatures
    """
    return EchoFeatures(_direct_one(h[..., :int(round(ECHO_WINDOW_S * FS))]), _decay_bands(h))


def _direct_one(early: np.ndarray) -> np.ndarray:
    """Hilbert envelope of the first 30 ms of responses (..., 1323), divided by its direct-sound
    peak (the largest value in the first 2 ms), float32."""
    env = hilbert_envelope(early)
    peak = env[..., :int(0.002 * FS)].max(axis=-1, keepdims=True)
    return (env / np.maximum(peak, 1e-12)).astype(np.float32)


def _decay_bands(h: np.ndarray) -> np.ndarray:
    """:attr:`EchoFeatures.bands` of signals (..., n >= 0.5 s) at 44.1 kHz.

    Band energies of 25 ms segments from their spectra (a Hann-windowed FFT per segment, 40 Hz
    bins: the 125 Hz octave gets two), four times faster than octave filter banks per frame."""
    bin_len = int(0.025 * FS)
    window, bands = _band_sums(bin_len)
    spec = scipy.fft.rfft(h[..., :20 * bin_len].reshape(*h.shape[:-1], 20, bin_len) * window, axis=-1)
    e = np.swapaxes((spec.real ** 2 + spec.imag ** 2) @ bands, -1, -2)  # (..., 7, 20)
    db = 10 * np.log10(np.maximum(e, 1e-20))
    db -= db.max(axis=(-2, -1), keepdims=True)
    return np.maximum(db, -120).astype(np.float32)


SELF_BAND_HZ = (300.0, 15000.0)
"""The band :func:`self_features` whitens and reads: what every broadband sound holds, above the
room's modes."""
SELF_SMOOTH_HZ = 1000.0
"""How far :func:`self_features` smooths the frame's power spectrum to whiten it: the sound's
own colour (slower than this across frequency) goes, an echo's ripple (every 1 / delay Hz, 57
to 670 Hz for delays of 1.5 to 17.5 ms) stays."""


def self_features(audio, fs: int = FS) -> EchoFeatures:
    """:class:`EchoFeatures` of frames whose emitted sound is unknown: the recording is its own
    reference.

    A frame is the emitted sound s convolved with the room's response h, whose first arrival,
    the direct sound, outweighs every echo. The frame's autocorrelation is s's convolved with
    h's, and h's holds, at each echo's delay after the direct sound, the echo's strength times
    the direct sound's. Whitened (the frame's power spectrum divided by itself smoothed over
    :data:`SELF_SMOOTH_HZ`, within :data:`SELF_BAND_HZ`), s's autocorrelation narrows to a
    spike for any broadband sound, and what is left is h's, read like :func:`echo_features`'
    response: its envelope over the first 30 ms, lag 0 placed at the direct sound's delay for a
    microphone :data:`~vrecho.device.MIC_ABOVE_EMITTER_M` from the loudspeaker (the reference
    device's, as :class:`~vrecho.models.EchoBranch` maps delays to depth) and divided by its
    peak. A periodic sound (a voice's pitch, a tone) correlates with itself at its period as an
    echo would: physics, not the method, bounds those. ``bands`` is the frame's own band energy decay.

    Parameters
    ----------
    audio : array_like, shape (n,) or (B, n), float
        1 s frames starting at the sound's onset, n = round(``fs``) samples.
    fs : int
        Sample rate in Hz (resampled to 44.1 kHz).

    Returns
    -------
    EchoFeatures
        ``envelope`` (..., 1323) and ``bands`` (..., 7, 20), float32; ``plane`` None.

    Raises
    ------
    VrechoError
        For frames :func:`check_frames` refuses.

    Examples
    --------
    White noise and its echo at half the amplitude, 300 samples later:

    >>> rng = np.random.default_rng(0)
    >>> s = rng.standard_normal(44_100).astype(np.float32)
    >>> x = 0.1 * (s + 0.5 * np.roll(s, 300))
    >>> e = self_features(x).envelope
    >>> lag0 = int(round(MIC_ABOVE_EMITTER_M / SPEED_OF_SOUND * FS))
    >>> int(np.argmax(e[lag0 + 50:])) + 50, round(float(e[lag0 + 300]), 1)
    (300, 0.4)
    """
    x = check_frames(audio, fs)
    length = int(round(ECHO_WINDOW_S * FS))
    lag0 = int(round(MIC_ABOVE_EMITTER_M / SPEED_OF_SOUND * FS))
    n = scipy.fft.next_fast_len(x.shape[-1] + length, real=True)  # no lag wraps onto another
    spec = scipy.fft.rfft(x, n, axis=-1)
    power = (spec.real ** 2 + spec.imag ** 2).astype(np.float32)
    f = np.fft.rfftfreq(n, 1 / FS)
    width = max(int(round(SELF_SMOOTH_HZ / (f[1] - f[0]))), 1)
    smooth = scipy.ndimage.uniform_filter1d(power, width, axis=-1, mode="nearest")
    band = band_weights(f, *SELF_BAND_HZ).astype(np.float32)
    white = band * power / (smooth + 1e-6 * smooth.max(axis=-1, keepdims=True) + 1e-30)  # -60 dB: not lifted
    r = scipy.fft.irfft(white, n, axis=-1)[..., :length - lag0 + 1]
    early = np.concatenate([r[..., lag0:0:-1], r[..., :length - lag0]], axis=-1)  # lag 0 at the direct sound's delay
    return EchoFeatures(_direct_one(early), _decay_bands(x))


@functools.lru_cache(maxsize=2)
def _band_sums(bin_len: int) -> tuple[np.ndarray, np.ndarray]:
    """The Hann window of a segment of ``bin_len`` samples and the 0/1 matrix (bins, 7) that sums
    its spectrum's power into the octaves of :data:`DECAY_BANDS_HZ`, single precision."""
    f = np.fft.rfftfreq(bin_len, 1 / FS)
    bands = np.stack([(f >= fc / np.sqrt(2)) & (f < fc * np.sqrt(2)) for fc in DECAY_BANDS_HZ], axis=1)
    return np.hanning(bin_len).astype(np.float32), bands.astype(np.float32)


PLANE_TAPER_HZ = 1000.0
"""The raised-cosine edges of :data:`PLANE_BANDS_HZ`: a sharp band edge rings, and the direct
sound's ringing (50 dB over a far echo where the microphone sits a centimetre from the
loudspeaker) would cover the echo."""


def band_weights(f: np.ndarray, lo_hz: float, hi_hz: float) -> np.ndarray:
    """Weights of the band ``lo_hz`` to ``hi_hz`` over frequencies ``f``, with raised-cosine
    edges :data:`PLANE_TAPER_HZ` wide inside it.

    Parameters
    ----------
    f : numpy.ndarray
        Frequencies in Hz.
    lo_hz, hi_hz : float
        The band's edges in Hz.

    Returns
    -------
    numpy.ndarray
        0 to 1, the shape of ``f``.
    """
    up = np.clip((f - lo_hz) / PLANE_TAPER_HZ, 0, 1)
    down = np.clip((hi_hz - f) / PLANE_TAPER_HZ, 0, 1)
    return (0.5 - 0.5 * np.cos(np.pi * up)) * (0.5 - 0.5 * np.cos(np.pi * down))
