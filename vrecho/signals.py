"""The 16 emitted sounds of PROTOCOL.md, vrecho's ranging probe and the pulse train.

Every sound is 100 ms long, peaks at 0.8 and has short raised-cosine fades. Sounds with a random
part (noises, clap, voice, whistle) take a ``numpy.random.Generator`` so that each recording can
hear a different instance of the same kind of sound; the same generator state gives the same
samples.
"""

from __future__ import annotations

import numpy as np
import scipy.signal
from scipy import fft

from .errors import VrechoError

FS = 44_100
"""The protocol's sample rate in Hz."""
PULSE_S = 0.1
"""Length of every emitted sound in seconds."""
PERIOD_S = 1.0
"""Pulse-train period in seconds (100 ms of sound, 900 ms of silence)."""
PEAK = 0.8
FADE_S = 0.005

TONES_HZ = (63, 125, 250, 500, 1000, 2000, 4000, 8000, 16000)
SOUNDS: tuple[str, ...] = tuple(f"tone_{f}" for f in TONES_HZ) + (
    "clap", "chirp", "white_noise", "pink_noise", "brown_noise", "voice", "whistle")
"""Names of the 16 emitted sounds."""
TRAIN_SOUNDS: tuple[str, ...] = tuple(f"tone_{f}" for f in TONES_HZ) + (
    "clap", "pink_noise", "brown_noise")
"""The paper's training sounds: nine tones, clap, pink and brown noise."""
HELD_OUT_SOUNDS: tuple[str, ...] = ("voice", "whistle", "chirp", "white_noise")
"""The paper's "unheard" test sounds."""
MAX_FS = 384_000
"""The highest sample rate taken, in Hz (audio interfaces' highest): a rate of 1e9 would ask for
gigabytes a second."""
MIN_COHERENCE = 0.3
"""How much of a window a pulse must explain (:func:`coherence`) for the sound there to be taken
for that pulse. vrecho's probe heard 7 cm from the loudspeaker gives 0.95 (0.6 under pink noise
as loud as it, 0.9 clipped on 7 % of the samples); speech, claps, doors, noise bursts 0.2 or
less."""
SPEED_OF_SOUND = 343.0
"""m/s; pyroomacoustics' default, used by the simulator and by every echo-delay computation."""


def check_fs(fs) -> int:
    """Validate a sample rate in Hz and return it as an int.

    Parameters
    ----------
    fs : int or float
        Sample rate in Hz: a positive whole number (``44100.0`` is accepted), not a bool.

    Returns
    -------
    int
        The sample rate in Hz.

    Raises
    ------
    VrechoError
        If ``fs`` is not a finite positive whole number, or lies outside 8000 to
        :data:`MAX_FS` Hz.
    """
    if isinstance(fs, bool) or not isinstance(fs, (int, np.integer, float)) or not np.isfinite(fs) \
            or fs <= 0 or float(fs) != int(fs):
        raise VrechoError(f"fs: sample rate must be a positive whole number of hertz, got {fs!r}")
    fs = int(fs)
    if not 8000 <= fs <= MAX_FS:
        raise VrechoError(f"fs: sample rate {fs} Hz is outside 8000 to {MAX_FS} Hz")
    return fs


def _shape(x: np.ndarray, fs: int) -> np.ndarray:
    """Apply the fades and scale to the protocol's peak amplitude."""
    n_fade = int(round(FADE_S * fs))
    ramp = 0.5 - 0.5 * np.cos(np.pi * np.arange(n_fade) / n_fade)
    x = np.asarray(x, dtype=np.float64).copy()
    x[:n_fade] *= ramp
    x[-n_fade:] *= ramp[::-1]
    return (PEAK * x / np.max(np.abs(x))).astype(np.float32)


def _colored_noise(n: int, exponent: float, rng: np.random.Generator) -> np.ndarray:
    """Noise whose power spectral density falls as 1/f**exponent (0 white, 1 pink, 2 brown)."""
    spec = np.fft.rfft(rng.standard_normal(n))
    f = np.fft.rfftfreq(n)
    f[0] = f[1]
    spec *= f ** (-exponent / 2.0)
    spec[0] = 0.0
    return np.fft.irfft(spec, n)


def colored_noise(n: int, exponent: float, rng: np.random.Generator) -> np.ndarray:
    """Unit-RMS noise of ``n`` samples with a 1/f**exponent power spectrum (float64).

    Shaped in the frequency domain, with the DC bin set to zero.

    Parameters
    ----------
    n : int
        Number of samples.
    exponent : float
        Slope of the power spectral density: 0 white, 1 pink, 2 brown.
    rng : numpy.random.Generator
        Source of the noise.

    Returns
    -------
    numpy.ndarray, shape (n,), float64
        Noise with an RMS of 1.
    """
    x = _colored_noise(n, exponent, rng)
    return x / np.sqrt(np.mean(x ** 2))


def _clap(t: np.ndarray, fs: int, rng: np.random.Generator) -> np.ndarray:
    # A few overlapping micro-bursts (palms meeting in more than one place), band-limited to the
    # 0.5-6 kHz region where hand claps carry their energy, each decaying in a few milliseconds.
    x = np.zeros_like(t)
    for _ in range(rng.integers(1, 4)):
        t0 = rng.uniform(0.004, 0.012)
        tau = rng.uniform(0.004, 0.012)
        burst = rng.standard_normal(t.size) * np.exp(-np.clip(t - t0, 0, None) / tau) * (t >= t0)
        x += rng.uniform(0.5, 1.0) * burst
    sos = scipy.signal.butter(2, [500, min(6000, 0.45 * fs)], btype="band", fs=fs, output="sos")
    return scipy.signal.sosfilt(sos, x)


def _voice(t: np.ndarray, fs: int, rng: np.random.Generator) -> np.ndarray:
    # Source-filter model: a glottal pulse train (85-255 Hz fundamental with slight drift)
    # through the formant resonances of a random vowel.
    f0 = rng.uniform(85, 255) * (1 + 0.05 * np.sin(2 * np.pi * rng.uniform(3, 6) * t))
    phase = np.cumsum(f0) / fs
    glottal = np.diff(np.floor(phase), prepend=0.0)  # one impulse per period
    glottal = scipy.signal.lfilter([1.0], [1.0, -0.95], glottal)  # spectral tilt
    vowels = ((730, 1090, 2440), (270, 2290, 3010), (300, 870, 2240), (530, 1840, 2480),
              (570, 840, 2410), (640, 1190, 2390))
    formants = np.array(vowels[rng.integers(len(vowels))]) * rng.uniform(0.9, 1.15)
    x = np.zeros_like(t)
    for i, fc in enumerate(formants):
        bw = 60 + 40 * i
        r = np.exp(-np.pi * bw / fs)
        a = [1.0, -2 * r * np.cos(2 * np.pi * fc / fs), r * r]
        x += scipy.signal.lfilter([1 - r], a, glottal) / (i + 1)
    return x + 0.01 * rng.standard_normal(t.size) * np.std(x)


def _whistle(t: np.ndarray, fs: int, rng: np.random.Generator) -> np.ndarray:
    f_c = np.exp(rng.uniform(np.log(700), np.log(3500)))
    depth = rng.uniform(0.01, 0.04) * f_c
    f = f_c + depth * np.sin(2 * np.pi * rng.uniform(4, 8) * t) + rng.uniform(-0.1, 0.1) * f_c * t / t[-1]
    f = np.clip(f, 500, 5000)
    x = np.sin(2 * np.pi * np.cumsum(f) / fs)
    return x + 0.05 * rng.standard_normal(t.size)  # breath noise


def emitted_sound(name: str, fs: int = FS, rng: np.random.Generator | None = None) -> np.ndarray:
    """One 100 ms emitted sound of PROTOCOL.md.

    Tones start at a random phase; the chirp sweeps linearly from 440 to 1320 Hz.

    Parameters
    ----------
    name : str
        One of :data:`SOUNDS`.
    fs : int
        Sample rate in Hz; :data:`FS` (44.1 kHz) by default.
    rng : numpy.random.Generator, optional
        Source of the random parts (noises, clap, voice, whistle, a tone's phase); a fixed
        default (seed 0) when omitted.

    Returns
    -------
    numpy.ndarray, shape (round(0.1 * fs),), float32
        Peak amplitude 0.8, with 5 ms fades.

    Raises
    ------
    VrechoError
        If ``name`` is not one of :data:`SOUNDS`, ``fs`` is not a valid sample rate, or a tone
        lies at or above half of ``fs``.

    Examples
    --------
    >>> x = emitted_sound("tone_1000", rng=np.random.default_rng(1))
    >>> x.shape, x.dtype
    ((4410,), dtype('float32'))
    >>> round(float(np.abs(x).max()), 3)
    0.8
    """
    fs = check_fs(fs)
    if name not in SOUNDS:
        raise VrechoError(f"sound: unknown emitted sound {name!r}; expected one of {', '.join(SOUNDS)}")
    rng = np.random.default_rng(0) if rng is None else rng
    n = int(round(PULSE_S * fs))
    t = np.arange(n) / fs
    if name.startswith("tone_"):
        f = float(name[5:])
        if f >= fs / 2:
            raise VrechoError(f"sound: {name} needs fs above {2 * f:.0f} Hz, got {fs}")
        x = np.sin(2 * np.pi * f * t + rng.uniform(0, 2 * np.pi))
    elif name == "chirp":
        x = scipy.signal.chirp(t, f0=440.0, t1=PULSE_S, f1=1320.0, method="linear")
    elif name.endswith("_noise"):
        exponent = {"white_noise": 0.0, "pink_noise": 1.0, "brown_noise": 2.0}[name]
        x = _colored_noise(n, exponent, rng)
    elif name == "clap":
        x = _clap(t, fs, rng)
    elif name == "voice":
        x = _voice(t, fs, rng)
    else:
        x = _whistle(t, fs, rng)
    return _shape(x, fs)


def probe(fs: int = FS, *, f_lo: float = 200.0, f_hi: float = 18_000.0) -> np.ndarray:
    """vrecho's documented ranging probe: a 100 ms logarithmic sweep from 200 Hz to 18 kHz.

    Broadband, so echo delays can be read to a fraction of a sample by deconvolution, and
    logarithmic, so the low bands where glass and mirror differ get as much energy as the highs.

    Parameters
    ----------
    fs : int
        Sample rate in Hz; :data:`FS` (44.1 kHz) by default.
    f_lo : float
        Start frequency of the sweep in Hz; 200 Hz by default.
    f_hi : float
        End frequency of the sweep in Hz; 18 kHz by default, and at most 0.45 * ``fs``.

    Returns
    -------
    numpy.ndarray, shape (round(0.1 * fs),), float32
        Peak amplitude 0.8, with 5 ms fades.

    Raises
    ------
    VrechoError
        If ``fs`` is not a valid sample rate.

    Examples
    --------
    >>> probe().shape
    (4410,)
    """
    fs = check_fs(fs)
    f_hi = min(f_hi, 0.45 * fs)
    t = np.arange(int(round(PULSE_S * fs))) / fs
    return _shape(scipy.signal.chirp(t, f0=f_lo, t1=PULSE_S, f1=f_hi, method="logarithmic"), fs)


def random_probe(rng: np.random.Generator, fs: int = FS) -> np.ndarray:
    """A random broadband probe of the kind PROTOCOL.md's product protocol must accept.

    100 ms spanning at least 200 Hz to 16 kHz, peak 0.8 with fades. A linear or logarithmic
    sweep (either direction) or a band-limited noise burst, with random band edges: the lower
    drawn from 60 to 200 Hz, the upper from 16 kHz to min(20 kHz, 0.45 * ``fs``).

    Parameters
    ----------
    rng : numpy.random.Generator
        Source of the kind, the band edges, the direction and the noise.
    fs : int
        Sample rate in Hz; :data:`FS` (44.1 kHz) by default. The band reaches 16 kHz only
        where 0.45 * ``fs`` does (``fs`` of about 35.6 kHz or more).

    Returns
    -------
    numpy.ndarray, shape (round(0.1 * fs),), float32
        Peak amplitude 0.8, with 5 ms fades.

    Raises
    ------
    VrechoError
        If ``fs`` is not a valid sample rate.
    """
    fs = check_fs(fs)
    n = int(round(PULSE_S * fs))
    t = np.arange(n) / fs
    f_lo, f_hi = rng.uniform(60, 200), rng.uniform(16_000, min(20_000, 0.45 * fs))
    kind = rng.integers(3)
    if kind < 2:
        f0, f1 = (f_lo, f_hi) if rng.random() < 0.5 else (f_hi, f_lo)
        x = scipy.signal.chirp(t, f0=f0, t1=PULSE_S, f1=f1, method="logarithmic" if kind == 0 else "linear")
    else:
        sos = scipy.signal.butter(4, [f_lo, f_hi], btype="band", fs=fs, output="sos")
        x = scipy.signal.sosfilt(sos, rng.standard_normal(n + 2000))[2000:]
    return _shape(x, fs)


def pulse_train(sound: np.ndarray, n_periods: int, fs: int = FS) -> np.ndarray:
    """The emitter's signal: ``sound`` at the start of each 1 s period, silence in between.

    Parameters
    ----------
    sound : array_like, shape (k,), float
        The emitted sound, at most one period (``round(fs)`` samples) long.
    n_periods : int
        Number of 1 s periods, at least 1.
    fs : int
        Sample rate in Hz; :data:`FS` (44.1 kHz) by default.

    Returns
    -------
    numpy.ndarray, shape (n_periods * round(fs),), float32
        The pulse train.

    Raises
    ------
    VrechoError
        If ``fs`` is not a valid sample rate, ``sound`` is not 1-D or is longer than a period,
        or ``n_periods`` is below 1.

    Examples
    --------
    >>> pulse_train(probe(), 3).shape
    (132300,)
    """
    fs = check_fs(fs)
    sound = np.asarray(sound, dtype=np.float32)
    period = int(round(PERIOD_S * fs))
    if sound.ndim != 1 or sound.size > period:
        raise VrechoError(f"sound: must be 1-D and at most one period ({period} samples), got shape {sound.shape}")
    if n_periods < 1:
        raise VrechoError(f"n_periods: must be at least 1, got {n_periods}")
    out = np.zeros(n_periods * period, dtype=np.float32)
    for k in range(n_periods):
        out[k * period:k * period + sound.size] = sound
    return out


def hilbert_envelope(y: np.ndarray) -> np.ndarray:
    """The envelope of real signals, ``abs(scipy.signal.hilbert(y, axis=-1))`` within float
    rounding (2.4e-7 of the largest in single precision), from one real FFT pair, not a
    complex one: 1.7 times faster (one thread, 2 760 samples, single or double precision).

    Parameters
    ----------
    y : numpy.ndarray, shape (..., n), float
        Signals along the last axis.

    Returns
    -------
    numpy.ndarray, shape (..., n)
        sqrt(y^2 + H(y)^2), H the Hilbert transform (the spectrum times -i sign(f), nothing at
        0 Hz or, for even n, at Nyquist); ``y``'s precision.

    Examples
    --------
    >>> t = np.arange(64)
    >>> bool(np.allclose(hilbert_envelope(np.cos(2 * np.pi * 4 * t / 64)), 1.0))
    True
    """
    n = y.shape[-1]
    spectrum = fft.rfft(y, axis=-1)
    spectrum *= -1j
    spectrum[..., 0] = 0
    if n % 2 == 0:
        spectrum[..., -1] = 0
    pair = fft.irfft(spectrum, n, axis=-1, overwrite_x=True)
    return np.sqrt(y * y + pair * pair)


def analytic_filter(sound: np.ndarray, n: int) -> np.ndarray:
    """The matched filter of ``sound`` for an FFT of ``n``, made analytic.

    Its conjugate spectrum (n // 2 + 1 bins) doubled on the positive frequencies, so that one
    inverse FFT of a recording's spectrum times it (:func:`analytic_envelope`) gives the
    correlation and its Hilbert pair at once.

    Parameters
    ----------
    sound : numpy.ndarray, shape (k,), float
        The emitted sound; k <= ``n``.
    n : int
        FFT length in samples.

    Returns
    -------
    numpy.ndarray, shape (n // 2 + 1,), complex
        The kernel; single precision for a single-precision ``sound``.
    """
    half = np.conj(fft.rfft(sound, n))
    half[1:(n + 1) // 2] *= 2.0
    return half


def analytic_envelope(x: np.ndarray, kernel: np.ndarray, n: int) -> np.ndarray:
    """Envelope of ``x`` correlated with the sound behind ``kernel``.

    At lag ``l``, how much of the sound starts at sample ``l``. Single-precision inputs give a
    single-precision answer.

    Parameters
    ----------
    x : numpy.ndarray, shape (..., m), float
        The recording, or several.
    kernel : numpy.ndarray, shape (..., n // 2 + 1), complex
        :func:`analytic_filter` of the sound for the same ``n`` (one for all, or one each).
    n : int
        FFT length in samples, at least m + the sound's length.

    Returns
    -------
    numpy.ndarray, shape (..., n), float
        The envelope by lag in samples.
    """
    half = fft.rfft(x, n, axis=-1) * kernel
    spec = np.zeros(half.shape[:-1] + (n,), half.dtype)
    spec[..., :half.shape[-1]] = half
    return np.abs(fft.ifft(spec, axis=-1, overwrite_x=True))


def coherence(x: np.ndarray, env: np.ndarray, k: int) -> np.ndarray:
    """How much of each window of ``k`` samples a pulse explains: the envelope of the window
    correlated with the pulse over the window's energy (Cauchy-Schwarz: 0 to 1, 1 where the
    window is the pulse scaled). Speech or noise gathers 0.2 or less.

    Parameters
    ----------
    x : numpy.ndarray [shape=(..., n)], float64
        The recording, or several (each read on its own).
    env : numpy.ndarray [shape=(..., n - k + 1)]
        Its envelope correlated with the pulse (:func:`analytic_envelope`), divided by the
        pulse's norm: entry ``l`` for the window from sample ``l``.
    k : int
        The pulse's length in samples.

    Returns
    -------
    numpy.ndarray [shape=(..., n - k + 1)], float64
        0 where the window is silent, and for a recording with samples that are not finite.
    """
    x = np.asarray(x, np.float64)
    m = env.shape[-1]
    peak = np.max(np.abs(x), axis=-1, keepdims=True, initial=0.0)
    finite = np.isfinite(peak)
    scale = 1.0 / np.where(finite & (peak > 1.0), peak, 1.0)  # a ratio: samples near float64's range would overflow squared
    c = np.cumsum((np.where(finite, x, 0.0) * scale) ** 2, axis=-1)
    c = np.concatenate([np.zeros(c.shape[:-1] + (1,)), c], axis=-1)
    energy = np.sqrt(np.maximum(c[..., k:k + m] - c[..., :m], 0.0))
    top = np.maximum(energy.max(axis=-1, keepdims=True, initial=0.0), 1e-300)
    with np.errstate(over="ignore", invalid="ignore"):
        return np.divide(env * scale, energy, out=np.zeros(energy.shape),
                         where=(energy > 1e-12 * top) & np.isfinite(env) & finite)


def parabolic_peaks(y: np.ndarray, i: np.ndarray) -> np.ndarray:
    """Peaks' positions to a fraction of a sample, by a parabola through three samples.

    A peak at either end of ``y``, or where the three samples do not bend down, stays where it
    is.

    Parameters
    ----------
    y : numpy.ndarray, shape (n,) or (B, n), float
        The signal, or B of them.
    i : array_like, shape (m,) or (B,), int
        Sample indices of the peaks; with B signals, one peak in each.

    Returns
    -------
    numpy.ndarray, shape (m,) or (B,), float64
        Refined positions, in samples (with B signals or a few dozen peaks, in double
        precision whatever ``y``'s).

    Examples
    --------
    >>> parabolic_peaks(np.array([0.0, 1.0, 3.0, 2.0, 0.0]), [2])
    array([2.16666667])
    """
    i = np.asarray(i)
    if y.ndim == 2:  # one peak a row: its three samples
        n = y.shape[1]
        a, b, c = np.take_along_axis(y, np.clip(i[:, None] + _THREE, 0, n - 1), axis=1).astype(float).T
        return _vertex(i, (i > 0) & (i < n - 1), a, b, c)
    if i.size <= 32:  # a few dozen peaks: plain floats beat a dozen array calls
        last = len(y) - 1
        out = []
        for k in i.tolist():
            if 0 < k < last:
                a, b, c = y[k - 1:k + 2].tolist()
                den = a - 2 * b + c
                if den < 0:
                    out.append(k + 0.5 * (a - c) / den)
                    continue
            out.append(float(k))
        return np.array(out)
    return _vertex(i, (i > 0) & (i < len(y) - 1), y[np.maximum(i - 1, 0)], y[i], y[np.minimum(i + 1, len(y) - 1)])


_THREE = np.array([-1, 0, 1])


def _vertex(i: np.ndarray, inner: np.ndarray, a: np.ndarray, b: np.ndarray, c: np.ndarray) -> np.ndarray:
    """The parabola through ``a``, ``b``, ``c`` (samples ``i`` - 1, ``i``, ``i`` + 1): its
    vertex where ``inner`` and it bends down, ``i`` elsewhere."""
    den = a - 2 * b + c
    bend = inner & (den < 0)
    return i + np.where(bend, 0.5 * (a - c) / np.where(bend, den, -1.0), 0.0)


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
        Frames at their own rate, finite (as :func:`vrecho.features.check_frames` takes them).

    Returns
    -------
    numpy.ndarray [shape=() or (B,)], bool
        True where at least :data:`CLIP_SHARE` of a frame's samples reach :data:`CLIP_LEVEL`
        of full scale (of the frame's peak, where that exceeds 1).
    """
    x = np.asarray(audio)
    out = np.zeros(x.shape[:-1], bool)
    if not x.shape[-1]:
        return out
    peak = np.maximum(x.max(axis=-1), -x.min(axis=-1)).astype(np.float64)
    near = peak >= CLIP_LEVEL  # below it no sample reaches the rail: most frames end here, at two passes
    if np.any(near):
        mag = np.abs(x[near] if x.dtype.kind == "f" else np.asarray(x[near], np.float64))  # |int16 min| overflows
        rail = (CLIP_LEVEL * np.maximum(peak[near], 1.0)).astype(mag.dtype)
        out[near] = np.count_nonzero(mag >= rail[..., None], axis=-1) >= CLIP_SHARE * x.shape[-1]
    return out
