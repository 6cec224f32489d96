"""Features of 1 s frames: the paper's log-mel spectrogram, and echo features that use the
emitted sound where it is known.

The log-mel spectrogram follows the paper: 2048-sample Hann window, hop 512, mel power in dB,
62 mel bands, 25 time bins (means over groups of STFT frames), each spectrogram normalised to zero
mean and unit variance. At 25 time bins per second one bin spans 40 ms, far coarser than the
1.5 to 17.5 ms echo delays of surfaces 0.25 to 3 m away; hence the echo features: with the emitted
sound known, circular Wiener deconvolution of the frame recovers the room's impulse response
(the frame is the steady state of a pulse train, a circular convolution), from which echo delays
can be read to a fraction of a sample and band energies to a few milliseconds.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import librosa
import numpy as np
import scipy.fft
import scipy.signal

from .device import MIC_ABOVE_EMITTER_M
from .errors import VrechoError
from .signals import FS, SPEED_OF_SOUND, check_fs, parabolic_peaks

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
CLIP_LEVEL = 0.999
CLIP_SHARE = 1e-3
"""A frame with at least this share of samples at full scale (|x| >= 0.999, or 0.999 of its own
peak above 1) is clipped."""


def clipped(audio) -> np.ndarray:
    """Which frames are clipped, tested on the samples as recorded: resampling or a fractional
    shift rings past the rail (Gibbs), and the flat tops no longer sit at the peak.

    Parameters
    ----------
    audio : numpy.ndarray [shape=(n,) or (B, n)], numbers
        Frames at their own rate, finite (as :func:`check_frames` takes them).

    Returns
    -------
    numpy.ndarray [shape=() or (B,)], bool
        True where at least :data:`CLIP_SHARE` of a frame's samples reach :data:`CLIP_LEVEL`
        of full scale (of the frame's peak, where that exceeds 1).
    """
    mag = np.abs(np.asarray(audio, np.float64))
    peak = mag.max(axis=-1, keepdims=True) if mag.shape[-1] else np.ones(mag.shape[:-1] + (1,))
    return np.mean(mag >= CLIP_LEVEL * np.maximum(peak, 1.0), axis=-1) >= CLIP_SHARE


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
    x = x.astype(np.float32)
    if not np.all(np.isfinite(x)):
        raise VrechoError("audio: contains NaN or infinite samples")
    if fs != FS:
        x = librosa.resample(x, orig_sr=fs, target_sr=FS, res_type="soxr_hq", axis=-1).astype(np.float32)
        x = x[..., :FS] if x.shape[-1] >= FS else np.pad(x, [(0, 0)] * (x.ndim - 1) + [(0, FS - x.shape[-1])])
    return x


@functools.lru_cache(maxsize=1)
def _window() -> np.ndarray:
    return scipy.signal.get_window("hann", N_FFT, fftbins=True).astype(np.float32)


@functools.lru_cache(maxsize=1)
def _mel_basis() -> np.ndarray:
    return librosa.filters.mel(sr=FS, n_fft=N_FFT, n_mels=N_MELS, fmax=FS / 2)  # built once: 2 ms a call


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
        If ``fs`` is not a valid sample rate, ``emitted`` has another shape or is not numbers,
        has NaN or infinite samples, is longer than a 1 s frame, or a sound is silent (all
        zero).
    """
    fs = check_fs(fs)
    try:
        s = np.asarray(emitted)
    except (ValueError, TypeError):
        raise VrechoError("emitted: expected a sound or sounds of one length (an array), got ragged sequences") from None
    if s.size == 0:
        raise VrechoError("emitted: expected at least one sample, got none")
    if s.dtype.kind not in "fiu" or s.ndim not in (1, 2) or (s.ndim == 2 and len(s) != n_frames):
        per_frame = "" if n_frames is None else f" or one per frame ({n_frames}, k)"
        raise VrechoError(f"emitted: expected one sound (k,){per_frame}, got shape {s.shape}")
    s = s.astype(np.float32)
    if not np.all(np.isfinite(s)):
        raise VrechoError("emitted: contains NaN or infinite samples")
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
    # librosa's centred STFT (zero padding by N_FFT / 2, periodic Hann), framed by hand: the same
    # numbers in a third of the time, which is most of a prediction's budget
    padded = np.pad(x, [(0, 0)] * (x.ndim - 1) + [(N_FFT // 2, N_FFT // 2)])
    frames = np.lib.stride_tricks.sliding_window_view(padded, N_FFT, axis=-1)[..., ::HOP, :]
    power = np.abs(scipy.fft.rfft(frames * _window(), axis=-1)) ** 2
    mel = np.einsum("...tf,mf->...mt", power, _mel_basis(), optimize=True)  # librosa's melspectrogram
    db = librosa.power_to_db(mel, ref=1.0, amin=1e-10, top_db=None)
    starts = np.array([g[0] for g in np.array_split(np.arange(db.shape[-1]), N_TIME)])
    pooled = np.add.reduceat(db, starts, axis=-1) / np.diff(np.append(starts, db.shape[-1]))
    mean = pooled.mean(axis=(-2, -1), keepdims=True)
    std = pooled.std(axis=(-2, -1), keepdims=True)
    return ((pooled - mean) / np.maximum(std, 1e-6)).astype(np.float32)


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
    s = check_emitted(emitted, fs, None if x.ndim == 1 else len(x))
    n = x.shape[-1]
    X = scipy.fft.rfft(x, n)
    if s.ndim == 1:  # one sound for every frame: its inverse filter, cached (a device repeats its probe)
        G = _cached_inverse_filter(s.tobytes(), n, regularization)
    else:
        G = _inverse_filter(s, n, regularization)
    h = scipy.fft.irfft(X * G, n)
    if length_s is not None:
        h = h[..., :int(round(length_s * FS))]
    return h.astype(np.float32)


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
    h = echo_response(audio, emitted, fs, length_s=None)
    early = h[..., :int(round(ECHO_WINDOW_S * FS))]
    env = np.abs(scipy.signal.hilbert(early, axis=-1))
    peak = env[..., :int(0.002 * FS)].max(axis=-1, keepdims=True)  # direct sound: first 2 ms
    envelope = env / np.maximum(peak, 1e-12)
    # Band energies of 25 ms segments from their spectra (a Hann-windowed FFT per segment, 40 Hz
    # bins: the 125 Hz octave gets two), four times faster than octave filter banks per frame.
    bin_len = int(0.025 * FS)
    seg = h[..., :20 * bin_len].reshape(*h.shape[:-1], 20, bin_len) * np.hanning(bin_len)
    power = np.abs(scipy.fft.rfft(seg, axis=-1)) ** 2
    f = np.fft.rfftfreq(bin_len, 1 / FS)
    energies = [power[..., (f >= fc / np.sqrt(2)) & (f < fc * np.sqrt(2))].sum(axis=-1) for fc in DECAY_BANDS_HZ]
    e = np.stack(energies, axis=-2)
    db = 10 * np.log10(np.maximum(e, 1e-20))
    db -= db.max(axis=(-2, -1), keepdims=True)
    return EchoFeatures(envelope.astype(np.float32), np.maximum(db, -120).astype(np.float32))


def echo_at(audio, emitted, depth_m: float, fs: int = FS, *, window_m: float = 0.03) -> tuple[float, float]:
    """The echo of a plane expected ``depth_m`` in front of the emitter (say, a wall seen by the
    camera): its level and its measured depth.

    The impulse response (:func:`echo_response`) is searched within ``window_m`` of that depth
    (the path emitter, plane, microphone 7 cm above the emitter); the strongest peak there gives
    the depth (parabolic refinement) and the level in dB relative to the direct sound, corrected
    for spherical spreading (so 0 dB is a perfect reflector facing a loudspeaker that radiates
    as strongly forward as toward its microphone). An opening leaves 10 dB or more less there.

    Parameters
    ----------
    audio : array_like, shape (n,), float
        One 1 s frame starting at the pulse onset, n = round(``fs``) samples.
    emitted : array_like, shape (k,), float
        The emitted sound at the same rate.
    depth_m : float
        Expected distance from the emitter to the plane, in metres.
    fs : int
        Sample rate of both, in Hz (resampled to 44.1 kHz).
    window_m : float
        Half-width of the depth range searched, in metres; 3 cm by default. The range starts
        no nearer than 5 cm.

    Returns
    -------
    level_db : float
        Level of the echo in dB relative to the direct sound, corrected for spreading.
    depth_m : float
        Measured distance from the emitter to the plane, in metres.

    Raises
    ------
    VrechoError
        If the searched range lies outside the first 30 ms of the response, or for input
        :func:`echo_response` refuses.

    Examples
    --------
    A frame holding the probe and one echo 300 samples later (a plane 1.166 m away):

    >>> from vrecho.signals import probe
    >>> s = probe()
    >>> x = np.zeros(44_100, np.float32)
    >>> x[:4410] += s
    >>> x[300:4710] += 0.5 * s
    >>> level_db, depth_m = echo_at(x, s, 1.2)
    >>> round(depth_m, 3)
    1.166
    """
    c = SPEED_OF_SOUND
    h = np.abs(echo_response(audio, emitted, fs, length_s=0.03)).astype(np.float64)
    direct = int(np.argmax(h[:int(0.002 * FS)]))

    def index(d):
        return np.sqrt((2 * d) ** 2 + MIC_ABOVE_EMITTER_M ** 2) / c * FS

    lo = int(np.floor(index(max(depth_m - window_m, 0.05))))
    hi = min(int(np.ceil(index(depth_m + window_m))) + 1, len(h) - 1)
    if lo >= hi:
        raise VrechoError(f"depth_m: {depth_m} m lies outside the 30 ms analysed")
    p = lo + int(np.argmax(h[lo:hi]))
    path = c * float(parabolic_peaks(h, (p,))[0]) / FS
    level = 20 * np.log10(max(h[p], 1e-12) / max(h[direct], 1e-12)) + 20 * np.log10(path / MIC_ABOVE_EMITTER_M)
    return float(level), float(np.sqrt(max(path ** 2 - MIC_ABOVE_EMITTER_M ** 2, 0.0)) / 2)
