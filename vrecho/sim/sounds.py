"""What the room's sound sources play: synthetic speech, music, appliance hum and PROTOCOL.md's
sounds, generated here (nothing is downloaded), each instance different for a different
``numpy.random.Generator``.

- ``speech``: a glottal pulse train (pitch 85 to 240 Hz with a falling intonation per phrase)
  through three formant resonators that move from vowel to vowel, syllables of 90 to 280 ms,
  fricative and plosive noise bursts, pauses between phrases.
- ``music``: notes of a random scale at 80 to 150 beats per minute, one to three at a time, each
  a decaying, slightly inharmonic series with the click of its pluck or hammer; half the pieces
  have drums or a hi-hat on most beats.
- ``hum``: an appliance: mains harmonics (50 or 60 Hz, 1/k amplitudes, the even ones strong) and
  the broadband noise of its fan or motor, slowly modulated.
- any of :data:`vrecho.signals.SOUNDS`: that 100 ms sound repeated at random intervals of 0.2 to
  0.9 s.
"""

from __future__ import annotations

import numpy as np
import scipy.signal

from ..errors import VrechoError
from ..signals import SOUNDS, check_fs, colored_noise, emitted_sound

KINDS: tuple[str, ...] = ("speech", "music", "hum")
"""Continuous ambient sounds; :data:`vrecho.signals.SOUNDS` names are accepted too."""


HIGH_PASS_HZ = 40.0
"""Every ambient sound is high-passed here (second order): sources and microphones pass little
below it."""


_VOWELS = ((730, 1090, 2440), (270, 2290, 3010), (300, 870, 2240), (530, 1840, 2480), (570, 840, 2410),
           (440, 1020, 2240), (660, 1720, 2410), (490, 1350, 1690))
"""Formant frequencies F1, F2, F3 in Hz of eight English vowels (Peterson and Barney)."""


def ambient_sound(kind: str, duration_s: float, fs: int, rng: np.random.Generator) -> np.ndarray:
    """``duration_s`` of the named sound at ``fs`` Hz, peak 0.8 (float32).

    Parameters
    ----------
    kind : str
        "speech", "music", "hum" (:data:`KINDS`) or one of :data:`vrecho.signals.SOUNDS`
        (repeated at random intervals).
    duration_s : float
        Length in seconds.
    fs : int
        Sample rate in Hz.
    rng : numpy.random.Generator
        Source of the sound: a different generator gives a different instance.

    Returns
    -------
    numpy.ndarray [shape=(round(duration_s * fs),)], float32
        The sound, peak 0.8 (all zeros where it is silent).

    Raises
    ------
    VrechoError
        If ``kind`` is unknown, ``duration_s`` is not a positive finite number, or ``fs`` is not
        a whole number of hertz from 8000 to 384 000.

    Examples
    --------
    >>> import numpy as np
    >>> x = ambient_sound("speech", 2.0, 16000, np.random.default_rng(0))
    >>> x.shape, x.dtype, float(np.abs(x).max())
    ((32000,), dtype('float32'), 0.800000011920929)
    """
    fs = check_fs(fs)
    if not np.isfinite(duration_s) or duration_s <= 0:
        raise VrechoError(f"duration_s: expected a positive duration, got {duration_s!r}")
    n = int(round(duration_s * fs))
    if kind == "speech":
        x = _speech(n, fs, rng)
    elif kind == "music":
        x = _music(n, fs, rng)
    elif kind == "hum":
        x = _hum(n, fs, rng)
    elif kind in SOUNDS:
        x = _repeated(kind, n, fs, rng)
    else:
        raise VrechoError(f"sound: expected one of {KINDS + SOUNDS}, got {kind!r}")
    return radiated(x, fs)


def radiated(x: np.ndarray, fs: int) -> np.ndarray:
    """A generated sound as a source radiates it and a microphone takes it in: high-passed at
    :data:`HIGH_PASS_HZ` (the voice's glottal pulses through its formants and a fan's brown noise
    left a third of their power below 20 Hz, which no direction or mask can share out), peak 0.8.

    Parameters
    ----------
    x : numpy.ndarray [shape=(n,)]
        The sound.
    fs : int
        Its sample rate in Hz.

    Returns
    -------
    numpy.ndarray [shape=(n,)], float32
        Peak 0.8 (all zeros where it is silent).
    """
    x = scipy.signal.sosfilt(scipy.signal.butter(2, HIGH_PASS_HZ, "highpass", fs=fs, output="sos"), x)
    peak = np.max(np.abs(x))
    return (0.8 * x / peak).astype(np.float32) if peak > 0 else x.astype(np.float32)


def _add(out: np.ndarray, start: int, x: np.ndarray) -> None:
    """``out[start:] += x`` for the part of ``x`` that fits."""
    k = max(0, min(len(x), len(out) - start))
    out[start:start + k] += x[:k]


def _resonator(x: np.ndarray, f_hz: float, bw_hz: float, fs: int) -> np.ndarray:
    r = np.exp(-np.pi * bw_hz / fs)
    a = [1.0, -2 * r * np.cos(2 * np.pi * f_hz / fs), r * r]
    return scipy.signal.lfilter([1 - r], a, x)


def _speech(n: int, fs: int, rng: np.random.Generator) -> np.ndarray:
    out = np.zeros(n)
    t = int(rng.uniform(0, 0.2) * fs)
    base = rng.uniform(85, 240)
    while t < n:
        n_syll = int(rng.integers(3, 12))
        for k in range(n_syll):
            if t >= n:
                break
            if rng.random() < 0.5:  # a consonant: fricative hiss or plosive burst
                m = int(rng.uniform(0.02, 0.09) * fs)
                lo = rng.uniform(1500, 4000)
                b, a = scipy.signal.butter(2, [lo / (fs / 2), min(0.95, rng.uniform(5000, 7500) / (fs / 2))], "band")
                burst = scipy.signal.lfilter(b, a, rng.standard_normal(m)) * np.hanning(m) * rng.uniform(0.05, 0.3)
                _add(out, t, burst)
                t += m
            m = int(rng.uniform(0.09, 0.28) * fs)
            f0 = base * (1.1 - 0.3 * k / n_syll) * np.exp(0.05 * rng.standard_normal())
            f0_track = f0 * (1 + 0.06 * np.linspace(-1, 1, m) * rng.choice([-1, 1]))
            phase = np.cumsum(f0_track / fs)
            pulses = np.diff(np.floor(phase), prepend=0.0)  # one impulse per glottal period
            glottal = scipy.signal.lfilter([1.0], [1.0, -0.97], pulses)  # spectral tilt
            v = _VOWELS[int(rng.integers(len(_VOWELS)))]
            y = sum(_resonator(glottal, f * rng.uniform(0.9, 1.15), 60 + 0.06 * f, fs) * g
                    for f, g in zip(v, (1.0, 0.6, 0.3)))
            y = y + 0.02 * rng.standard_normal(m) * np.std(y)  # breath
            _add(out, t, y * np.hanning(m))
            t += m
        t += int(rng.uniform(0.15, 0.6) * fs)  # pause between phrases
        base *= np.exp(0.1 * rng.standard_normal())
    return out


def _music(n: int, fs: int, rng: np.random.Generator) -> np.ndarray:
    out = np.zeros(n)
    beat = 60.0 / rng.uniform(80, 150)
    scales = ((0, 2, 4, 5, 7, 9, 11), (0, 2, 3, 5, 7, 8, 10), (0, 3, 5, 7, 10))
    scale = np.array(scales[int(rng.integers(len(scales)))])
    root = rng.uniform(110, 260)
    decay = rng.uniform(2, 8)
    n_harm = int(rng.integers(6, 16))
    drums = rng.random() < 0.5
    t = 0.0
    while t * fs < n:
        dur = beat * rng.choice([0.5, 1, 1, 2])
        for _ in range(int(rng.integers(1, 4))):
            step = scale[int(rng.integers(len(scale)))] + 12 * int(rng.integers(-1, 2))
            f = root * 2 ** (step / 12)
            m = int(min(dur * 1.5, 3.0) * fs)
            tt = np.arange(m) / fs
            harmonics = np.arange(1, n_harm + 1)
            harmonics = harmonics[harmonics * f < 0.45 * fs]
            amps = rng.uniform(0.3, 1.0, len(harmonics)) / harmonics
            note = np.sin(2 * np.pi * f * np.outer(tt, harmonics * (1 + 4e-4 * harmonics ** 2))
                          + rng.uniform(0, 2 * np.pi, len(harmonics))) @ amps
            note *= np.exp(-decay * tt) * np.minimum(1.0, tt / 0.005)
            k = min(m, int(rng.uniform(0.004, 0.02) * fs))  # the pluck or hammer: a broadband click
            note[:k] += rng.uniform(0.1, 0.5) * amps.sum() * rng.standard_normal(k) * np.exp(-np.arange(k) / (0.3 * k))
            _add(out, int(t * fs), note)
        if drums and rng.random() < 0.7:  # a drum or hi-hat on the beat
            k = int(rng.uniform(0.03, 0.15) * fs)
            hit = colored_noise(k, rng.uniform(0, 1.5), rng) * np.exp(-np.arange(k) / (0.2 * k))
            _add(out, int(t * fs), rng.uniform(0.2, 0.6) * hit / np.std(hit) * np.std(out[:max(1, int(t * fs))] + 1e-3))
        t += dur
    return out


def _hum(n: int, fs: int, rng: np.random.Generator) -> np.ndarray:
    tt = np.arange(n) / fs
    mains = rng.choice([50.0, 60.0])
    k = np.arange(1, int(min(40, 0.45 * fs / mains)) + 1)
    amps = rng.uniform(0.2, 1.0, len(k)) / k * np.where(k % 2 == 0, 2.0, 1.0)
    tone = np.zeros(n)
    for kk, a in zip(k, amps):
        tone += a * np.sin(2 * np.pi * mains * kk * tt + rng.uniform(0, 2 * np.pi))
    motor = colored_noise(n, rng.uniform(0.5, 1.2), rng)
    b, a = scipy.signal.butter(2, [80 / (fs / 2), min(0.95, rng.uniform(4000, 7500) / (fs / 2))], "band")
    motor = scipy.signal.lfilter(b, a, motor)
    motor *= 1 + 0.2 * np.sin(2 * np.pi * rng.uniform(0.2, 2) * tt)
    return tone / np.std(tone) + rng.uniform(0.5, 1.5) * motor / np.std(motor)


def _repeated(name: str, n: int, fs: int, rng: np.random.Generator) -> np.ndarray:
    out = np.zeros(n)
    t = int(rng.uniform(0, 0.3) * fs)
    while t < n:
        s = emitted_sound(name, fs, rng).astype(np.float64)
        _add(out, t, s)
        t += len(s) + int(rng.uniform(0.1, 0.8) * fs)
    return out
