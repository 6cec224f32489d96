"""Real captures: a phone's recording of vrecho's pulse train, cut into PROTOCOL.md's frames.

The capture (PROTOCOL.md): a loudspeaker beside the camera plays a pulse train (100 ms of the
probe, then 900 ms of silence) while the camera films; each frame is 1.0 s of microphone signal
from a pulse's onset. A real recording does not say where its pulses are: it starts anywhere,
the two clocks drift apart (a player's 44.1 kHz is not the recorder's), pulses are drowned by a
door slam or lost to a dropout, the microphone clips. :func:`find_onsets` finds them:

1. **Matched filter.** The recording correlated with the emitted pulse (FFT), and its envelope
   (analytic signal): a pulse's direct sound stands out by the pulse's time-bandwidth product
   (about 36 dB for the 100 ms probe) above noise, and clipping keeps the peak where it was.
2. **Candidates.** The strongest lag within each half period, at least ``min_snr_db`` above the
   envelope's median (the noise floor), of the sounds shaped like the pulse: where the matched
   filter explains at least :data:`~vrecho.signals.MIN_COHERENCE` of the window's energy
   (speech, claps and noise bursts rise above the noise too, but are not shaped like a sweep).
3. **The train.** The period is measured (the median spacing of candidates 0.95 to 1.05 nominal
   periods apart: the clocks' drift); a candidate is a pulse when another lies one to four whole
   periods away (within ``tolerance_s`` per period): a clap or a door does not recur on the
   period, and pulses missing on both sides of one do not lose it (nor does one alone between
   two pauses, as loud as the train to 1.5 dB). Where two pulses lie a whole number of periods
   apart (to a millisecond a period), the pulses between are missing; where the gap is not
   whole (the player paused, or looped its file), the train starts again and nothing is
   missing; fewer than half the gaps whole is no train (pulses played at random). A stronger
   echo is not taken for the direct sound: the onset is the highest lag within a quarter
   millisecond of the first, within 20 ms before the peak, whose envelope reaches half of it.
4. **Sub-sample time.** A parabola through the envelope's three samples at the peak.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from pathlib import Path

import librosa
import numpy as np
from scipy import fft
from scipy.ndimage import maximum_filter1d

from ..device import MIC_ABOVE_EMITTER_M
from ..errors import VrechoError, check_number
from ..features import BAND_FS
from ..signals import (FS, MIN_COHERENCE, PERIOD_S, SPEED_OF_SOUND, analytic_envelope, analytic_filter, check_fs,
                       clipped, coherence, parabolic_peaks, probe)

PULSE_TRAIN_WAV = Path(__file__).resolve().parent.parent / "assets" / "pulse_train.wav"
"""The pulse train for the second phone to play (on repeat): 30 s of vrecho's probe once a
second (:func:`~vrecho.signals.pulse_train` of :func:`~vrecho.signals.probe`), 44.1 kHz, 16-bit
PCM. A player's gap at the loop's seam costs nothing: :func:`find_onsets` restarts the train."""

@dataclass
class Onsets:
    """Pulses found in a recording (:func:`find_onsets`).

    Parameters
    ----------
    samples : numpy.ndarray [shape=(K,)], float
        Where each pulse's direct sound begins, in fractional samples from the recording's first.
    strength_db : numpy.ndarray [shape=(K,)], float
        Each pulse's matched-filter peak above the noise floor, in dB.
    missing : numpy.ndarray [shape=(J,)], float
        Where a pulse was due but none was found, in fractional samples.
    period_s : float
        The train's period as measured (the clocks' drift included), in seconds.
    fs : int
        The recording's sample rate, in Hz.
    """

    samples: np.ndarray
    strength_db: np.ndarray
    missing: np.ndarray
    period_s: float
    fs: int

    @property
    def seconds(self) -> np.ndarray:
        """The onsets (K,) in seconds from the recording's start."""
        return self.samples / self.fs


def _mono(audio, fs) -> tuple[np.ndarray, int]:
    fs = check_fs(fs)
    x = np.asarray(audio)
    if x.dtype.kind not in "fiu" or x.ndim not in (1, 2) or x.size == 0:
        raise VrechoError(f"audio: expected a non-empty 1-D recording (or channels x samples) of real numbers, "
                          f"got shape {x.shape} ({x.dtype})")
    if x.ndim == 2:  # (n, channels) or (channels, n): the first channel
        x = x[:, 0] if x.shape[0] > x.shape[1] else x[0]
    x = x.astype(np.float64)
    if not np.all(np.isfinite(x)):
        raise VrechoError("audio: the recording holds NaN or infinite samples")
    return x, fs


def matched_envelope(audio, emitted, fs: int = FS) -> np.ndarray:
    """Envelope of the recording correlated with the emitted pulse: entry ``l`` is how much of
    the pulse starts at sample ``l``.

    Parameters
    ----------
    audio : numpy.ndarray [shape=(n,), (n, channels) or (channels, n)]
        The recording (the first channel is used: the longer axis is taken for time).
    emitted : numpy.ndarray [shape=(k,)]
        The pulse played, at ``fs``; 8 to n samples.
    fs : int
        Sample rate of both, in Hz (8000 to 384000, :func:`~vrecho.signals.check_fs`; default 44100).

    Returns
    -------
    numpy.ndarray [shape=(n - k + 1,)], float64
        The envelope of the correlation (analytic signal), divided by the pulse's norm.

    Raises
    ------
    VrechoError
        For an empty recording, one of more than two dimensions, not of real numbers or with
        NaN or infinite samples; a sample rate :func:`~vrecho.signals.check_fs` refuses; a
        pulse that is not 1-D, or shorter than 8 samples, or longer than the recording.
    """
    x, _ = _mono(audio, fs)
    return _envelope(x, _pulse(emitted, x.size))


def _pulse(emitted, n: int) -> np.ndarray:
    s = np.asarray(emitted, dtype=np.float64)
    if s.ndim != 1 or not 8 <= s.size <= n:
        raise VrechoError(f"emitted: expected a 1-D pulse shorter than the recording ({n} samples), got shape {s.shape}")
    return s


@functools.lru_cache(maxsize=4)
def _played_probe(fs: int) -> np.ndarray:
    """vrecho's probe as :data:`PULSE_TRAIN_WAV` plays it (44.1 kHz), heard at ``fs``: a
    recorder at a lower rate keeps the sweep's lower part, at its own times."""
    s = probe(FS).astype(np.float64)
    return s if fs == FS else librosa.resample(s, orig_sr=FS, target_sr=fs)


def _envelope(x: np.ndarray, s: np.ndarray) -> np.ndarray:
    """:func:`matched_envelope` of a checked recording and pulse."""
    n = fft.next_fast_len(x.size + s.size, real=True)
    return analytic_envelope(x, analytic_filter(s, n), n)[:x.size - s.size + 1] / np.linalg.norm(s)


def find_onsets(audio, fs: int = FS, *, emitted=None, period_s: float = PERIOD_S, min_snr_db: float = 12.0,
                tolerance_s: float = 0.01) -> Onsets:
    """The pulse train's onsets in a recording (see the module's notes).

    Parameters
    ----------
    audio : numpy.ndarray [shape=(n,), (n, channels) or (channels, n)]
        The recording (the first channel is used: the longer axis is taken for time).
    fs : int
        Its sample rate in Hz (8000 to 384000; default 44100).
    emitted : numpy.ndarray [shape=(k,)], optional
        The pulse played, at ``fs`` (default: vrecho's probe as :data:`PULSE_TRAIN_WAV` plays it,
        at 44.1 kHz, resampled to ``fs``: below 40 kHz the recorder keeps the sweep's lower part).
    period_s : float
        The nominal period in seconds (PROTOCOL.md: 1 s; 0.1 to 10 s); the measured one may
        differ by a few per cent.
    min_snr_db : float
        How far above the noise floor, in dB, a pulse's matched-filter peak must rise
        (default 12).
    tolerance_s : float
        How far from its due time, in seconds, a pulse may be (per period of a gap; default
        0.01).

    Returns
    -------
    Onsets
        The pulses found, where pulses are missing, and the measured period.

    Raises
    ------
    VrechoError
        When no pulse train is found: fewer than two sounds shaped like the pulse
        (:data:`~vrecho.signals.MIN_COHERENCE`) a period apart, or fewer than half the gaps
        between them whole periods (speech, noise bursts, a pulse played at random times); for a ``period_s``
        outside 0.1 to 10 s, a ``min_snr_db`` outside 0 to 60, a ``tolerance_s`` outside
        0.0001 to 0.1 s, a recording shorter than the pulse; and for a recording, rate or pulse
        :func:`matched_envelope` refuses.

    Examples
    --------
    Four of vrecho's pulses half a second into a recording, with a little noise:

    >>> import numpy as np
    >>> from vrecho.capture import find_onsets
    >>> from vrecho.signals import probe, pulse_train
    >>> x = np.r_[np.zeros(22050), pulse_train(probe(), 4), np.zeros(22050)]
    >>> x = x + 1e-3 * np.random.default_rng(0).standard_normal(x.size)
    >>> onsets = find_onsets(x, 44100)
    >>> onsets.seconds.round(3)
    array([0.5, 1.5, 2.5, 3.5])
    >>> len(onsets.missing)
    0
    """
    x, fs = _mono(audio, fs)
    s = _played_probe(fs) if emitted is None else _pulse(emitted, x.size)
    if isinstance(period_s, bool) or not isinstance(period_s, (int, float, np.integer, np.floating)) \
            or not 0.1 <= period_s <= 10:
        raise VrechoError(f"period_s: expected 0.1 to 10 s, got {period_s!r}")
    for name, v, lo, hi in (("min_snr_db", min_snr_db, 0, 60), ("tolerance_s", tolerance_s, 1e-4, 0.1)):
        check_number(v, name, lo=lo, hi=hi)
    if x.size < s.size:
        raise VrechoError(f"audio: {x.size / fs:.3f} s is shorter than one pulse ({s.size / fs:.3f} s)")
    env = _envelope(x, s)
    period = period_s * fs
    floor = float(np.median(env)) + 1e-12
    loud = env > floor * 10 ** (min_snr_db / 20)
    # Only what has the pulse's shape: speech, claps, doors and noise bursts rise above the noise
    # too, but the matched filter gathers a small share of their energy (coherence 0.2 or less).
    shaped = loud & (coherence(x, env, s.size) >= MIN_COHERENCE)
    if not shaped.any():
        raise VrechoError(f"audio: no pulse train found: {'nothing' if not loud.any() else 'no sound'} "
                          f"{min_snr_db:g} dB above the noise has the shape of vrecho's probe (its matched "
                          f"filter) in {x.size / fs:.1f} s; expected the probe every {period_s:g} s")
    env_shaped = np.where(shaped, env, 0.0)
    half = max(int(period // 2), 1)
    peaks = np.flatnonzero((env_shaped == maximum_filter1d(env_shaped, half, mode="nearest")) & shaped)
    if len(peaks) < 2:
        raise VrechoError(f"audio: no pulse train found ({len(peaks)} pulse(s) {min_snr_db:g} dB above the noise "
                          f"in {x.size / fs:.1f} s); expected vrecho's pulse every {period_s:g} s")
    # The train: candidates with another a whole number of periods away (up to four: pulses may be
    # missing on both sides); a clap or a door does not recur on the period.
    tol = tolerance_s * fs
    pairs = [(j, peaks[j:] - peaks[:-j]) for j in range(1, len(peaks)) if (peaks[j:] - peaks[:-j]).min() < 4.5 * period]
    near = np.concatenate([d[(d > 0.95 * period) & (d < 1.05 * period)] for _, d in pairs])
    period = float(np.median(near)) if len(near) else period  # the clocks' drift, measured
    support = np.zeros(len(peaks), bool)
    for j, d in pairs:
        m = np.round(d / period)
        ok = (m >= 1) & (m <= 4) & (np.abs(d - m * period) <= tol * np.maximum(m, 1))
        support[j:] |= ok
        support[:-j] |= ok
    # The direct sound comes as loud every time (the loudspeaker stays beside the microphone):
    # two noise peaks that happen to lie periods apart are far weaker than the train, and a
    # pulse alone between two pauses is as strong as the rest.
    if support.any():
        level = np.median(env[peaks[support]])
        support = (support & (env[peaks] >= 0.1 * level)) | (np.abs(20 * np.log10(env[peaks] / level)) <= 1.5)
    idx = peaks[support]
    if len(idx) < 2:
        raise VrechoError(f"audio: no pulse train found: pulses do not recur every {period_s:g} s "
                          f"(within {tolerance_s * 1000:.0f} ms)")
    # The direct sound is the first strong arrival: an echo may outdo it by a little.
    lead, lobe = int(0.02 * fs), max(int(0.00025 * fs), 3)  # a quarter millisecond: past the main lobe, before any echo
    for j, i in enumerate(idx):
        w = env[max(i - lead, 0):i + 1]
        first = max(i - lead, 0) + int(np.flatnonzero(w >= 0.5 * env[i])[0])
        idx[j] = first + int(np.argmax(env[first:first + lobe]))  # that arrival's own peak
    samples = parabolic_peaks(env, idx)
    gaps = np.diff(samples)
    k = np.round(gaps / period)
    whole = (k >= 1) & (np.abs(gaps - k * period) <= tol * np.maximum(k, 1))
    if whole.sum() < len(gaps) / 2:  # a train restarts now and then (a pause, a loop), not at every pulse
        raise VrechoError(f"audio: no pulse train found: of {len(samples)} probe-shaped sounds, {int(whole.sum())} of "
                          f"{len(gaps)} gaps are whole periods ({period_s:g} s, within {tolerance_s * 1000:g} ms)")
    period = float(np.median(gaps[whole] / k[whole]))
    # Missing pulses: where two found lie a whole number of periods apart, to a millisecond a
    # period (the player's clock keeps the beat to a sample); any other gap (the player paused,
    # or looped its file) starts the train again and misses nothing.
    k = np.round(gaps / period).astype(int)
    missing = [a + j * g / m for a, g, m in zip(samples, gaps, k)
               if m >= 2 and abs(g - m * period) <= 0.001 * fs * m for j in range(1, m)]
    return Onsets(samples, 20 * np.log10(env[idx] / floor), np.array(missing), period / fs, fs)


def _emissions(onsets: Onsets, mic_offset_m: float | None) -> np.ndarray:
    """Each pulse's emission, in fractional samples at ``onsets.fs``: its direct sound's onset less
    its flight from the loudspeaker, ``mic_offset_m`` away (PROTOCOL's device by default)."""
    if not isinstance(onsets, Onsets):
        raise VrechoError(f"onsets: expected the Onsets find_onsets gives, got {type(onsets).__name__}")
    offset = MIC_ABOVE_EMITTER_M if mic_offset_m is None else check_number(mic_offset_m, "mic_offset_m", lo=0.0, hi=3.0)
    return onsets.samples - offset / SPEED_OF_SOUND * onsets.fs


def frame_flags(audio, onsets: Onsets, index, *, length_s: float = 1.0,
                mic_offset_m: float | None = None) -> list[tuple[str, ...]]:
    """What the recording says of each frame :func:`cut_frames` cut from it, by EchoCNN's rules
    (:mod:`vrecho.classifier`), before the resampling and the fractional shift (which ring past
    the rail and hide clipping): ``clipped``, the frame's ``length_s`` as recorded
    (:func:`vrecho.signals.clipped`); ``low_rate``, a recording below
    :data:`~vrecho.features.BAND_FS` (40 kHz: the probe's band does not fit).

    Parameters
    ----------
    audio : numpy.ndarray [shape=(n,), (n, channels) or (channels, n)]
        The recording, at ``onsets.fs`` (the first channel is used).
    onsets : Onsets
        Its pulses (:func:`find_onsets`).
    index : numpy.ndarray [shape=(K,)], int
        The onsets the frames were cut from (``cut_frames(..., return_index=True)``).
    length_s, mic_offset_m : float
        As given to :func:`cut_frames`.

    Returns
    -------
    list of tuple of str
        One per frame, for :meth:`~vrecho.classifier.Classifier.predict_batch`'s ``flags``.

    Raises
    ------
    VrechoError
        For arguments :func:`cut_frames` refuses, or an ``index`` outside the onsets.
    """
    at = _emissions(onsets, mic_offset_m)
    x, fs = _mono(audio, onsets.fs)
    n = int(round(check_number(length_s, "length_s", lo=0.01, hi=10.0) * fs))
    index = np.asarray(index)
    if index.dtype.kind not in "iu" or index.ndim != 1 or np.any(index < 0) or np.any(index >= len(at)):
        raise VrechoError(f"index: expected onsets' indices 0 to {len(at) - 1}, got {index!r}")
    low = ("low_rate",) if fs < BAND_FS else ()
    return [(("clipped",) if clipped(x[i:i + n]) else ()) + low for i in np.maximum(np.floor(at[index]), 0).astype(int)]


def cut_frames(audio, onsets: Onsets, *, length_s: float = 1.0, mic_offset_m: float | None = None,
               return_index: bool = False):
    """PROTOCOL.md's frames: ``length_s`` of the recording from each pulse's emission (the direct
    sound's onset less its flight from the loudspeaker, ``mic_offset_m`` away: PROTOCOL's device
    by default), resampled to 44.1 kHz, each shifted by its fraction of a sample (a linear phase)
    so that sample 0 is the emission. Frames that would run past the recording's end, or start
    less than 64 samples (at 44.1 kHz) after its start, are left out.

    Parameters
    ----------
    audio : numpy.ndarray [shape=(n,), (n, channels) or (channels, n)]
        The recording, at ``onsets.fs`` (the first channel is used).
    onsets : Onsets
        Its pulses (:func:`find_onsets`).
    length_s : float
        Length of a frame in seconds (default 1).
    mic_offset_m : float, optional
        From the loudspeaker to the microphone, in metres (default
        :data:`~vrecho.device.MIC_ABOVE_EMITTER_M`, 7 cm).
    return_index : bool
        Also return which of the onsets the frames are (default False).

    Returns
    -------
    frames : numpy.ndarray [shape=(K, round(length_s * 44100))], float32
        One frame per pulse kept, at 44.1 kHz, in the onsets' order.
    index : numpy.ndarray [shape=(K,)], int
        With ``return_index``: the onset each frame is cut from.

    Raises
    ------
    VrechoError
        For a recording or rate :func:`matched_envelope` refuses, ``onsets`` that are not
        :class:`Onsets`, a ``length_s`` outside 0.01 to 10 s or a ``mic_offset_m`` outside 0
        to 3 m.

    Examples
    --------
    >>> import numpy as np
    >>> from vrecho.capture import cut_frames, find_onsets
    >>> from vrecho.signals import probe, pulse_train
    >>> x = np.r_[np.zeros(22050), pulse_train(probe(), 4), np.zeros(22050)]
    >>> cut_frames(x, find_onsets(x, 44100)).shape
    (4, 44100)
    """
    if not isinstance(onsets, Onsets):
        raise VrechoError(f"onsets: expected the Onsets find_onsets gives, got {type(onsets).__name__}")
    x, fs = _mono(audio, onsets.fs)
    check_number(length_s, "length_s", lo=0.01, hi=10.0)
    starts = _emissions(onsets, mic_offset_m) * FS / fs
    if fs != FS:
        x = librosa.resample(x, orig_sr=fs, target_sr=FS)
    n, pad = int(round(length_s * FS)), 64
    frames, kept = [], []
    for k, t in enumerate(starts):
        i = int(np.floor(t))
        if i - pad < 0 or i + n + pad > x.size:
            continue
        seg = x[i - pad:i + n + pad]
        f = np.fft.rfftfreq(seg.size)
        seg = np.fft.irfft(np.fft.rfft(seg) * np.exp(2j * np.pi * f * (t - i)), seg.size)  # advance by the fraction
        frames.append(seg[pad:pad + n])
        kept.append(k)
    frames = np.array(frames, np.float32).reshape(-1, n)
    return (frames, np.array(kept, int)) if return_index else frames
