"""The headset call: warn before the wearer walks into glass, a mirror or a wall.

:class:`BoundaryMonitor` has the shape of a full-duplex audio callback (sounddevice's
``Stream(callback=...)``): each call gets the microphone's block and fills the loudspeaker's
block of the same length, on the same sample clock. It plays a ranging probe (:func:`ranging_probe`,
a 5 ms linear chirp from 4 to 20 kHz, Tukey-windowed, every 40 ms: a faint tick), and for each
pulse:

1. **Ranging.** Matched filter of the microphone signal with the probe (the envelope of the
   cross-correlation), the device's own direct sound as the time reference (so unknown audio
   latency cancels), echo peaks above the noise floor (``threshold`` times the envelope's
   median) and the direct sound's sidelobes (when the direct sound is clipped, above the
   clipped probe's own distortion, which spreads over one probe's length after it), each timed
   to a fraction of a sample by parabolic interpolation. A surface straight ahead at ``d``
   returns the echo path ``L = sqrt((2 d)^2 + s^2)`` (``s``: emitter to microphone): ``d`` follows.
2. **Tracking.** Echo distances are chained over pulses into tracks (nearest to each track's
   prediction, within 12 cm); an alpha-beta filter, started from its first two echoes' speed
   (a fast walk's echo moves 8 cm a pulse), gives each track's distance and closing speed (it
   follows a wearer who starts or stops within a few pulses), time to contact is distance /
   closing speed.
3. **Alerts with hysteresis.** Only surfaces the wearer moves toward count (``approach_m``
   nearer within 0.8 s, in the last second) and will not pass by: a point at lateral offset
   ``a`` nears as d(t)^2 = (v (t_c - t))^2 + a^2, so a quadratic fit over the last 0.3 to 0.6 s
   gives a^2, the closest point of approach; a surface is in the way when a^2 lies within
   +/- ``miss_m``^2 by two standard errors (a surface straight ahead has a = 0; the wall above a
   door, heard by way of the ceiling, or a wall beside it by way of a side wall, nears too but
   passes by, and a track whose fit is poor waits). This is what tells the wall ahead from the
   floor, the ceiling and walls alongside, which one microphone cannot tell by direction.
   *caution* when time to contact is under ``caution_ttc_s`` or distance under ``caution_m``,
   *stop* under ``stop_m``; an alert ends only ``hysteresis_m`` beyond its threshold (or when
   the surface stops approaching for a second).

The alert is the gravest any surface in the way calls for (the soonest to contact among equals),
judged again whenever something it rests on changes (a pulse's window completes, a surface's
approach grows a second old): while a surface in the way, or one not yet known to pass by, is
near a threshold, the block in which its echo of the pulse still arriving is predicted to end
(give or take 1.5 ms) also analyses that pulse (an undecided surface is asked again with that
echo), so an echo that crosses the threshold raises the alert in the block in which that echo
ends.

Robustness: clipped samples are flagged (the timing survives clipping, and the clipped direct
sound's distortion is kept out, see 1.); runs of exact zeros (dropouts) and non-finite samples
are flagged, and a pulse's window ends where they begin (the echoes heard wholly before them
count; none if they reach the direct sound); any block size, changing from call to call; 44.1
or 48 kHz.

``surface``: "opening" when the wearer moves and nothing ahead echoes; for an echoing surface
ahead, "closed" until the headset's camera has been shown it, then what the camera makes of it
(:meth:`BoundaryMonitor.see`, :mod:`vrecho.headset.view`): "wall" where the depth camera sees
the surface the echo comes from, "glass" or "mirror" (EchoCNN's visual branch on the pane's crop)
where it sees past it. The echo alone cannot tell them: glass, mirror and wall reflect a 4-20 kHz
chirp alike (their absorption differs by a few hundredths above 1 kHz, PROTOCOL.md), and the
cameras alone cannot find glass: it takes both.
"""

from __future__ import annotations

import bisect
from dataclasses import dataclass

import numpy as np
from scipy import fft
from scipy.ndimage import maximum_filter1d
from scipy.signal import chirp
from scipy.signal.windows import tukey

from ..errors import VrechoError
from ..signals import SPEED_OF_SOUND, analytic_envelope, analytic_filter, parabolic_peaks
from .tracks import Track
from .view import look_all


def ranging_probe(fs: int, *, duration_s: float = 0.005, f0: float = 4000.0, f1: float = 20000.0) -> np.ndarray:
    """The ranging probe: a linear chirp from ``f0`` to ``f1`` Hz over ``duration_s``, Tukey
    window (25 %), peak 0.5.

    Parameters
    ----------
    fs : int
        Sample rate in Hz.
    duration_s : float
        The chirp's length in seconds (default 5 ms).
    f0, f1 : float
        The chirp's start and end frequencies in Hz (default 4 and 20 kHz).

    Returns
    -------
    numpy.ndarray [shape=(round(duration_s * fs),), dtype=float64]

    Raises
    ------
    VrechoError
        When ``f1`` is not below the Nyquist frequency ``fs / 2``.

    Examples
    --------
    >>> from vrecho.headset import ranging_probe
    >>> ranging_probe(48000).shape
    (240,)
    """
    if f1 >= fs / 2:
        raise VrechoError(f"probe: {f1} Hz needs a sample rate above {2 * f1:.0f} Hz, got {fs}")
    t = np.arange(int(round(duration_s * fs))) / fs
    return (0.5 * chirp(t, f0, duration_s, f1) * tukey(len(t), 0.25)).astype(np.float64)


@dataclass
class Alert:
    """What the monitor says after a block.

    Parameters
    ----------
    level : str
        "clear", "caution" or "stop".
    distance_m : float or None
        The distance in metres of the surface the alert rests on: of those in the wearer's way,
        the gravest, then the soonest to contact (None if none).
    surface : str or None
        "wall", "glass", "mirror" (what the camera made of the surface,
        :meth:`BoundaryMonitor.see`), "closed" (not yet seen), "opening" or None (see the
        module's notes).
    confidence : float
        In [0, 1].
    closing_speed_mps : float or None
        That surface's closing speed in m/s (positive: nearing).
    time_to_contact_s : float or None
        That surface's time to contact in seconds (None when it closes at 5 cm/s or less).
    flags : tuple of str
        What was wrong with the input so far in this block ("nan", "dropout", "clipped",
        "no_echo").
    pulse_time_s : float or None
        When (seconds, on the stream's clock, from the first sample) the pulse that measured
        ``distance_m`` was emitted.
    """

    level: str = "clear"
    distance_m: float | None = None
    surface: str | None = None
    confidence: float = 0.0
    closing_speed_mps: float | None = None
    time_to_contact_s: float | None = None
    flags: tuple[str, ...] = ()
    pulse_time_s: float | None = None


class BoundaryMonitor:
    """Echo ranging for a headset: call it with each microphone block and the loudspeaker block
    to fill (see the module's notes).

    Parameters
    ----------
    fs : {44100, 48000}
        Sample rate of both streams in Hz (default 48000).
    period_s : float
        Time between probe pulses in seconds (default 0.04; sets the longest unambiguous range,
        c * period / 2). It must exceed the round trip to ``max_range_m`` plus 6 ms, and be at
        most 0.5 s.
    max_range_m, min_range_m : float
        Echoes are looked for between these distances in metres (default 4 and 0.12).
    mic_offset_m : float
        Distance in metres from the loudspeaker to the microphone (PROTOCOL's device: 0.07 m,
        the default).
    caution_ttc_s, caution_m, stop_m, hysteresis_m : float
        Alert thresholds, in seconds and metres (default 2 s, 1 m, 0.5 m, 0.1 m; see the
        module's notes); 0 < ``stop_m`` < ``caution_m``, ``caution_ttc_s`` > 0,
        ``hysteresis_m`` >= 0.
    approach_m : float
        A surface counts as approached when it came this much nearer, in metres, within 0.8 s
        (default 0.12: more than a head's bob).
    miss_m : float
        A surface the wearer will pass farther from than this, in metres (closest point of
        approach; default 0.4), is not in the way: the wall above a door, a corner to one side.
    threshold : float
        An echo must rise this many times above the envelope's median (4.5, 13 dB: a mirror
        2.5 m ahead is heard through pink noise 20 dB below the direct sound; the tracks keep
        single noise peaks from mattering).

    Attributes
    ----------
    alert : Alert
        The alert returned for the last block.

    Raises
    ------
    VrechoError
        For another sample rate, a ``period_s`` out of range, or thresholds out of order.

    Examples
    --------
    >>> import numpy as np
    >>> from vrecho.headset import BoundaryMonitor
    >>> monitor = BoundaryMonitor(48000)
    >>> speaker = np.zeros(480)  # a 10 ms block
    >>> mic = 1e-3 * np.random.default_rng(0).standard_normal(480)
    >>> alert = monitor(mic, speaker)  # speaker now holds the probe's first 5 ms
    >>> alert.level, alert.distance_m
    ('clear', None)
    >>> round(float(np.abs(speaker).max()), 3)
    0.5
    """

    def __init__(self, fs: int = 48000, *, period_s: float = 0.04, max_range_m: float = 4.0, min_range_m: float = 0.12,
                 mic_offset_m: float = 0.07, caution_ttc_s: float = 2.0, caution_m: float = 1.0, stop_m: float = 0.5,
                 hysteresis_m: float = 0.1, approach_m: float = 0.12, miss_m: float = 0.4, threshold: float = 4.5):
        if fs not in (44100, 48000):
            raise VrechoError(f"fs: expected 44100 or 48000 Hz, got {fs!r}")
        if not 2 * max_range_m / SPEED_OF_SOUND + 0.006 < period_s <= 0.5:
            raise VrechoError(f"period_s: must exceed the round trip to max_range_m plus the probe "
                              f"({2 * max_range_m / SPEED_OF_SOUND + 0.006:.3f} s) and be at most 0.5 s, got {period_s}")
        if not 0 < stop_m < caution_m and caution_ttc_s > 0 and hysteresis_m >= 0:
            raise VrechoError("thresholds: need 0 < stop_m < caution_m, caution_ttc_s > 0, hysteresis_m >= 0")
        self.fs = fs
        self.probe = ranging_probe(fs)
        self.period = int(round(period_s * fs))
        self.max_range_m, self.min_range_m, self.mic_offset_m = max_range_m, min_range_m, mic_offset_m
        self.caution_ttc_s, self.caution_m, self.stop_m = caution_ttc_s, caution_m, stop_m
        self.hysteresis_m, self.approach_m, self.threshold = hysteresis_m, approach_m, threshold
        self.miss_m = miss_m
        # The window of one pulse: the direct sound (with up to 10 ms of audio latency) and echoes
        # out to max_range_m, plus the probe's length.
        self.latency_max = int(0.010 * fs)
        self.window = min(self.period, self.latency_max + int((2 * max_range_m / SPEED_OF_SOUND) * fs) + 2 * len(self.probe))
        self._buf = np.zeros(self.period * 3)
        self._valid = np.zeros(self.period * 3, bool)
        self._now = 0  # samples received so far (= samples played: one clock)
        self._judged = 0  # samples received at the last judgement
        self._tracks: list[Track] = []
        self._pulse_done = -1  # last pulse committed to the tracks
        self._direct_delay: float | None = None  # samples from emission to the direct peak (latency + s / c)
        self._alert = self._verdict = Alert()  # the alert returned; the last judgement behind it
        self._verdict_track: Track | None = None  # the surface it rests on
        self._oldest_approach = np.inf  # the earliest approached_at among the surfaces judged
        self._still: list[float] = []  # distances of the surfaces that stay put, at the last commit
        self._level = "clear"
        self._kernels: dict[int, np.ndarray] = {}
        self._clipped_floors: dict[int, np.ndarray] = {}
        self._fft_sizes: dict[int, int] = {}
        lag = np.arange(self.window + len(self.probe), dtype=float)  # the direct sound's sidelobes by lag
        self._sidelobe = 10 ** (-(32 + 6 * np.log2(np.maximum(lag, 1) / (0.5 * len(self.probe)) + 1)) / 20)

    def _kernel(self, n: int) -> np.ndarray:
        """The probe's analytic matched filter for an FFT of ``n`` (:func:`~vrecho.signals.analytic_filter`),
        cached per size: a pulse still arriving is filtered with a shorter FFT."""
        if n not in self._kernels:  # single precision: a sample's thousandth is ample
            self._kernels[n] = analytic_filter(self.probe, n).astype(np.complex64)
        return self._kernels[n]

    def _clipped_sidelobe(self, fraction: float) -> np.ndarray:
        """The floor beside a clipped direct sound: the matched filter's response to the probe
        clipped so that ``fraction`` of its samples sit at the rail (its distortion spreads over
        one probe's length after the peak, up to some 30 dB below it), 6 dB above that, and never
        below the clean sidelobes. Cached in steps of 5 %."""
        step = max(1, int(round(fraction * 20)))
        if step not in self._clipped_floors:
            peak = np.abs(self.probe).max()  # (clipped wholly: its signs)
            level = max(np.quantile(np.abs(self.probe), 1 - step / 20), 1e-3 * peak)
            m = len(self.probe)
            n = 4 * m
            x = np.zeros(n - m)
            x[:m] = np.clip(self.probe, -level, level)
            env = analytic_envelope(x, analytic_filter(self.probe, n), n)[:n - m]  # past n - m: negative lags
            profile = np.zeros(max(len(self._sidelobe), n - m))
            profile[:len(env)] = maximum_filter1d(env / env[0], 9)  # a few samples' slack in timing
            self._clipped_floors[step] = np.maximum(self._sidelobe, 2.0 * profile[:len(self._sidelobe)])
        return self._clipped_floors[step]

    # -- The callback ------------------------------------------------------------------------------
    def __call__(self, mic, speaker=None) -> Alert:
        """:meth:`process`: the audio callback's call.

        Parameters
        ----------
        mic, speaker
            As for :meth:`process`.

        Returns
        -------
        Alert
            As :meth:`process` returns it.
        """
        return self.process(mic, speaker)

    def process(self, mic, speaker=None) -> Alert:
        """Read one microphone block, fill the loudspeaker block, and return the alert.

        Parameters
        ----------
        mic : numpy.ndarray [shape=(frames,) or (frames, channels)]
            Samples in [-1, 1] (channel 0 is used); any block size, changing from call to call.
        speaker : numpy.ndarray [shape=(frames,) or (frames, channels)], optional
            A writable array of the same number of frames, filled in place (every channel gets
            the probe); None when the probe is played some other way (:meth:`speaker_block`
            gives the samples).

        Returns
        -------
        Alert
            A new one per block (one already returned keeps its flags).

        Raises
        ------
        VrechoError
            For a ``mic`` block that is not numeric (frames,) or (frames, channels), or a
            ``speaker`` block of another length.
        """
        x = np.asarray(mic)
        if x.ndim == 2:
            x = x[:, 0]
        if x.ndim != 1 or not np.issubdtype(x.dtype, np.number):
            raise VrechoError(f"mic: expected a numeric (frames,) or (frames, channels) block, got shape {x.shape}")
        n = len(x)
        if speaker is not None:
            out = np.asarray(speaker)
            if len(out) != n:
                raise VrechoError(f"speaker: expected {n} frames like the microphone block, got {len(out)}")
            block = self.speaker_block(n)
            out[...] = block[:, None] if out.ndim == 2 else block
        x = x.astype(np.float64, copy=True)
        flags = []
        finite = np.isfinite(x)
        if not finite.all():
            flags.append("nan")
            x[~finite] = 0.0
        valid = finite.copy()
        zeros = _zero_runs(x, 32) & finite
        if zeros.any():
            flags.append("dropout")
            valid &= ~zeros
        if _clipped(x):
            flags.append("clipped")
        self._push(x, valid)
        self._update()
        v, tr = self._verdict, self._verdict_track  # a new Alert per block: one already returned keeps its flags
        surface = tr.surface if tr is not None else v.surface  # the camera may have seen it since
        self._alert = Alert(v.level, v.distance_m, surface, v.confidence, v.closing_speed_mps, v.time_to_contact_s,
                            tuple(dict.fromkeys(v.flags + tuple(flags))), v.pulse_time_s)
        return self._alert

    def speaker_block(self, n: int) -> np.ndarray:
        """The loudspeaker's next ``n`` samples (the probe at the start of every period).

        For the block that starts at the monitor's current sample: call it before
        :meth:`process` on that block (it does not advance the monitor's clock).

        Parameters
        ----------
        n : int
            The block's length in frames.

        Returns
        -------
        numpy.ndarray [shape=(n,), dtype=float64]
        """
        out = np.zeros(n)
        start = self._now
        k = start // self.period
        while k * self.period < start + n:
            e = k * self.period
            lo, hi = max(e, start), min(e + len(self.probe), start + n)
            if hi > lo:
                out[lo - start:hi - start] = self.probe[lo - e:hi - e]
            k += 1
        return out

    @property
    def alert(self) -> Alert:
        """The alert returned for the last block (a clear one before the first)."""
        return self._alert

    def see(self, image, depth, intrinsics, *, model=None) -> str | None:
        """Show the monitor the headset camera's latest frame: what the surfaces ahead are.

        Each surface the alert rests on or the wearer nears (the nearest, up to three) is looked for in
        the frame at its echo's distance (:func:`vrecho.headset.view.look`): "wall" where the depth
        camera sees it, "glass" or "mirror" where it sees past it; each frame's answer is a vote
        weighted by its confidence, and ``alert.surface`` reports the leading one from the next
        block on. Call it from the camera's thread a few times a second, not from the audio
        callback (some 5 to 15 ms a frame on one core: EchoCNN's visual branch).

        Parameters
        ----------
        image : numpy.ndarray [shape=(H, W)]
            Grayscale (uint8, or floats in [0, 1]), from a camera beside the microphone looking
            along the wearer's forward axis.
        depth : numpy.ndarray [shape=(H, W)]
            Z-depth in metres (0 or NaN: no return), registered to ``image``.
        intrinsics : numpy.ndarray [shape=(3, 3)]
            The camera's pinhole matrix.
        model : EchoCNN, optional
            The visual branch (the shipped one by default).

        Returns
        -------
        str or None
            The surface the alert now rests on, as the votes so far lead ("closed" while no
            frame could tell), or None when it rests on none.

        Raises
        ------
        VrechoError
            For a bad frame or intrinsics (:func:`vrecho.headset.view.look`).
        """
        t = self._now / self.fs
        verdict = self._verdict_track
        near = sorted((tr for tr in list(self._tracks)  # the audio thread may change the list meanwhile
                       if tr is not verdict and tr.ahead is not False and t - tr.times[-1] < 0.2
                       and (tr.speed or 0.0) < -0.2), key=lambda tr: tr.predict(t))
        asked = [(tr, tr.predict(t)) for tr in ([verdict] if verdict is not None else []) + near[:3 - (verdict is not None)]]
        asked = [(tr, d) for tr, d in asked if d > self.min_range_m]
        for (tr, _), v in zip(asked, look_all(image, depth, intrinsics, [d for _, d in asked], model=model)):
            if v is not None:
                tr.views[v.surface] = tr.views.get(v.surface, 0.0) + v.confidence
        return verdict.surface if verdict is not None else None

    # -- Internals ---------------------------------------------------------------------------------
    def _push(self, x: np.ndarray, valid: np.ndarray) -> None:
        size = len(self._buf)
        for lo in range(0, len(x), size):  # a block longer than the buffer: keep what fits, in order
            chunk, ok = x[lo:lo + size], valid[lo:lo + size]
            at = self._now % size
            first = min(len(chunk), size - at)  # up to the ring's end, then from its start
            self._buf[at:at + first], self._valid[at:at + first] = chunk[:first], ok[:first]
            self._buf[:len(chunk) - first], self._valid[:len(chunk) - first] = chunk[first:], ok[first:]
            self._now += len(chunk)
            if lo + size < len(x):
                self._update()

    def _samples(self, start: int, stop: int) -> tuple[np.ndarray, int]:
        """The samples from ``start`` to ``stop`` and how many of them come before the first
        damaged one (a dropout's or a NaN's)."""
        size = len(self._buf)
        a, b = start % size, (start % size) + (stop - start)
        idx = slice(a, b) if b <= size else np.arange(start, stop) % size  # across the ring's end
        valid = self._valid[idx]
        return self._buf[idx], len(valid) if valid.all() else int(np.argmin(valid))

    def _update(self) -> None:
        """Commit every pulse whose window is complete, then judge the current pulse from what has
        arrived of it."""
        last = (self._now - self.window) // self.period  # newest pulse with a complete window
        oldest = max(self._pulse_done + 1, (self._now - len(self._buf) + self.period) // self.period, 0)
        changed = False
        for k in range(oldest, last + 1):
            echoes = self._detect(k, k * self.period + self.window)
            if echoes is not None:
                self._commit(k, echoes)
                changed = True
            self._pulse_done = k
        current = self._now // self.period
        partial = None
        e = current * self.period
        if current > self._pulse_done and self._now - e > len(self.probe):
            # A surface in the way near a threshold: its echo of this pulse may cross it. Looked
            # for in the block in which that echo ends (as predicted, give or take 1.5 ms, a
            # quarter metre), not in every block.
            margin = 0.0015 * self.fs
            if any(self._judged < e + end + margin and self._now >= e + end - margin
                   for end in self._echo_ends(e / self.fs)):
                partial = self._detect(current, self._now)
        # The judgement changes only with the tracks, a pulse still arriving, or when a surface's
        # approach grows a second old: otherwise the last one stands.
        if changed or partial or self._now / self.fs - self._oldest_approach > 1.0:
            self._judge(partial, current)
        self._judged = self._now

    def _echo_ends(self, t: float) -> list[float]:
        """For each surface in the way (or not yet known not to be) that may cross an alert
        threshold with the pulse emitted at ``t`` (within 0.3 m of a distance threshold, or 0.5 s
        of the time-to-contact one): the lag (samples from the emission) at which its echo will
        have wholly arrived."""
        out = []
        for tr in self._tracks:
            if t - tr.approached_at <= 1.0 and (tr.ahead or (tr.ahead is None and len(tr.times) >= 7)):
                d = tr.predict(t)  # (an undecided track: one echo more may decide it)
                closing = -(tr.speed or 0.0)
                near = self.caution_m if tr.ahead else self.stop_m  # undecided: near the stop only
                if d < near + 0.3 or (tr.ahead and closing > 0.05 and d / closing < self.caution_ttc_s + 0.5):
                    s = self.mic_offset_m
                    path = np.sqrt((2 * max(d, 0.0)) ** 2 + s ** 2) - s
                    out.append((self._direct_delay or 0.0) + path / SPEED_OF_SOUND * self.fs + len(self.probe))
        return out

    def _detect(self, k: int, stop: int):
        """Echo distances (m) and strengths of pulse ``k`` from its samples up to ``stop``, keeping
        the echoes that have ended before any damage; None when damage reaches the direct sound."""
        e = k * self.period
        x, good = self._samples(e, min(stop, e + self.window))
        if good < len(x):  # damage ends the window: the echoes wholly heard before it count
            reference = self.latency_max if self._direct_delay is None else self._direct_delay
            if good < reference + 2 * len(self.probe):
                return None  # (the direct sound must be whole: it is the reference)
            x = x[:good]
        if len(x) < len(self.probe) + 8:
            return None
        n = self._fft_sizes.get(len(x))
        if n is None:
            n = self._fft_sizes[len(x)] = fft.next_fast_len(len(x) + len(self.probe), real=True)
        env = analytic_envelope(x.astype(np.float32), self._kernel(n), n)[:len(x) - len(self.probe) + 1]  # lags where the whole probe fits: ended echoes
        head = env[:self.latency_max]
        if not len(head):
            return None
        d0 = int(np.argmax(head))
        direct = float(parabolic_peaks(env, (d0,))[0])
        if self._direct_delay is None:
            self._direct_delay = direct
        elif 0.5 < abs(direct - self._direct_delay) <= 3:  # drift; a larger jump is a stray peak: kept out
            self._direct_delay = 0.9 * self._direct_delay + 0.1 * direct
        ref = self._direct_delay
        peak_direct = env[d0]
        sidelobe = self._sidelobe
        rail = np.count_nonzero(_at_rail(x[d0:d0 + len(self.probe)]))
        if rail >= 3:  # the direct sound clipped: its distortion rises above the sidelobes, near it
            sidelobe = self._clipped_sidelobe(rail / len(self.probe))
        lo = int(ref + 2 * self.min_range_m / SPEED_OF_SOUND * self.fs)
        if lo >= len(env) - 2:
            return []
        seg = env[lo:]
        quarter = seg[::4]  # every 4th lag: the floor, at a quarter of the cost
        noise = float(np.partition(quarter, len(quarter) // 2)[len(quarter) // 2]) + 1e-12
        # The direct sound's matched-filter sidelobes fall off with lag; an echo must rise above both.
        floor = np.maximum(self.threshold * noise, peak_direct * sidelobe[lo - int(ref):len(env) - int(ref)])
        above = np.flatnonzero(seg[1:-1] > floor[1:-1]) + 1  # few: the echoes' main lobes
        above = above[(seg[above] > seg[above - 1]) & (seg[above] >= seg[above + 1])]  # their local maxima
        if not len(above):
            return []
        peaks = above + lo
        s = self.mic_offset_m
        path = SPEED_OF_SOUND * (parabolic_peaks(env, peaks) - ref) / self.fs + s
        d = 0.5 * np.sqrt(np.maximum(path ** 2 - s ** 2, 0.0))
        ok = (path > s) & (d >= self.min_range_m) & (d <= self.max_range_m)
        return _merge(list(zip(d[ok].tolist(), (env[peaks][ok] / peak_direct).tolist())), 0.03)

    def _associate(self, t: float, echoes) -> list[tuple[Track | None, float, float]]:
        """Each echo (nearest first) with the nearest unclaimed track whose prediction lies within
        12 cm, or None (a new surface)."""
        order = sorted(range(len(self._tracks)), key=lambda i: self._tracks[i].predict(t))
        predicted = [self._tracks[i].predict(t) for i in order]  # ascending, plain floats
        free = [True] * len(predicted)
        pairs = []
        for d, strength in sorted(echoes):
            j, gap = -1, 0.12
            at = bisect.bisect_left(predicted, d)
            for i in range(at - 1, -1, -1):  # nearer tracks first, on either side, within 12 cm
                if d - predicted[i] >= gap:
                    break
                if free[i]:
                    j, gap = i, d - predicted[i]
                    break
            for i in range(at, len(predicted)):
                if predicted[i] - d >= gap:
                    break
                if free[i]:
                    j, gap = i, predicted[i] - d
                    break
            if j >= 0:
                free[j] = False
                pairs.append((self._tracks[order[j]], d, strength))
            else:
                pairs.append((None, d, strength))
        return pairs

    def _commit(self, k: int, echoes) -> None:
        t = k * self.period / self.fs
        updated = []
        for tr, d, strength in self._associate(t, echoes):
            if tr is None:
                tr = Track()
                self._tracks.append(tr)
            tr.update(t, d, strength)
            if tr.closed_in(0.8) >= self.approach_m:
                tr.approached_at = t
            updated.append(tr)
        # Only a surface being approached can need an alert: the fits are for those.
        still = self._still = [tr.d_hat for tr in self._tracks
                 if len(tr.times) >= 10 and tr.speed is not None and abs(tr.speed) < 0.25 and tr.d_hat >= self.miss_m]
        for tr in updated:
            tr.ahead = None
            closing = -(tr.speed or 0.0)
            soon = tr.d_hat < self.caution_m + 1.0 or (closing > 0.05 and tr.d_hat / closing < self.caution_ttc_s + 1.5)
            if t - tr.approached_at <= 1.0 and soon:  # the fit only where an alert may come within a second or so
                tr.ahead = tr.in_the_way(self.miss_m)
                if tr.ahead and tr.explained_by(still):
                    tr.ahead = False
        self._tracks = [tr for tr in self._tracks if t - tr.times[-1] <= 0.3]
        if len(self._tracks) > 32:  # clutter: keep the nearest
            self._tracks = sorted(self._tracks, key=lambda tr: tr.dists[-1])[:32]

    def _level_for(self, d: float, ttc: float) -> str:
        """The alert a surface at ``d`` m, ``ttc`` s from contact calls for, with hysteresis
        (an alert ends only ``hysteresis_m`` beyond its threshold)."""
        h = self.hysteresis_m
        if d < self.stop_m + (h if self._level == "stop" else 0.0):
            return "stop"
        if (d < self.caution_m + (h if self._level != "clear" else 0.0)
                or ttc < self.caution_ttc_s * (1.1 if self._level != "clear" else 1.0)):
            return "caution"
        return "clear"

    def _judge(self, partial, current: int) -> None:
        t_now = self._now / self.fs
        t_pulse = current * self.period / self.fs
        best = None
        provisional = {}
        if partial:  # echoes of the pulse still arriving: the alert may not wait for the window's end
            for tr, d, _ in self._associate(t_pulse, partial):
                if tr is not None:
                    provisional[id(tr)] = d
        self._oldest_approach = np.inf
        for tr in self._tracks:
            if t_now - tr.approached_at > 1.0 or tr.ahead is False:
                continue
            if tr.ahead is None and not (id(tr) in provisional
                                         and tr.ahead_with(t_pulse, provisional[id(tr)], self.miss_m, self._still)):
                continue  # not known to be in the way: asked again with the echo still arriving, if any
            self._oldest_approach = min(self._oldest_approach, tr.approached_at)
            v = tr.speed
            d = provisional.get(id(tr), tr.dists[-1])
            at = t_pulse if id(tr) in provisional else tr.times[-1]
            closing = -v if v is not None else 0.0
            ttc = d / closing if closing > 0.05 else np.inf
            level = self._level_for(d, ttc)
            if best is None or (-_RANK[level], ttc, d) < (-_RANK[best[5]], best[2], best[0]):  # gravest, then soonest
                best = (d, closing, ttc, tr, at, level)
        self._verdict_track = None if best is None else best[3]
        if best is None:
            self._level = "clear"
            moving = any(abs(tr.closed_in(0.8)) >= self.approach_m for tr in self._tracks)
            self._verdict = Alert("clear", None, "opening" if moving else None, 0.0, None, None,
                                () if self._tracks else ("no_echo",))
        else:
            d, closing, ttc, tr, at, level = best
            self._level = level
            conf = float(np.clip(min(len(tr.dists), 10) / 10 * min(1.0, np.mean(tr.strengths) * 200), 0, 1))
            self._verdict = Alert(level, float(d), "closed", conf, float(closing), None if np.isinf(ttc) else float(ttc),
                                (), float(at))


_RANK = {"clear": 0, "caution": 1, "stop": 2}


def _merge(echoes, within_m: float):
    """One echo per surface: peaks closer than ``within_m`` keep the strongest."""
    out = []
    for d, s in sorted(echoes):
        if out and d - out[-1][0] < within_m:
            if s > out[-1][1]:
                out[-1] = (d, s)
            continue
        out.append((d, s))
    return out


def _zero_runs(x: np.ndarray, min_len: int) -> np.ndarray:
    """Samples in runs of at least ``min_len`` exact zeros (a dropout, not silence: real
    microphones always carry noise)."""
    if np.count_nonzero(x) == len(x):
        return np.zeros(len(x), bool)
    z = np.concatenate([[False], x == 0, [False]])
    edges = np.flatnonzero(np.diff(z.astype(np.int8)))
    out = np.zeros(len(x), bool)
    for a, b in zip(edges[::2], edges[1::2]):
        if b - a >= min_len:
            out[a:b] = True
    return out


def _at_rail(x: np.ndarray) -> np.ndarray:
    """The samples at ``x``'s largest magnitude (none if it is silent)."""
    a = np.abs(x)
    m = float(a.max(initial=0.0))
    return a >= m * (1 - 1e-6) if m > 0.0 else np.zeros(len(a), bool)


def _clipped(x: np.ndarray) -> bool:
    """Flat tops: three or more consecutive samples at the block's largest magnitude (a clipping
    converter or limiter holds its rail; a real signal does not)."""
    top = _at_rail(x)
    if np.count_nonzero(top) < 3:  # the usual block: one loudest sample
        return False
    return bool(np.any(top[2:] & top[1:-1] & top[:-2]))
