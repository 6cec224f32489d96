"""The headset call: warn before the wearer walks into glass, a mirror or a wall.

:class:`BoundaryMonitor` has the shape of a full-duplex audio callback: each call gets the
microphone's block and fills the loudspeaker's block of the same length (:meth:`~BoundaryMonitor.callback`
is sounddevice's ``Stream(callback=...)`` itself). It plays a ranging probe every 40 ms plus a
dither of up to 5 ms: a 5 ms chirp, Tukey-windowed, up or down through 4-20 kHz (two codes,
:data:`~.ranging.CODES_HZ`), the dither and the code of each pulse drawn from the monitor's own
seed (a faint tick), and:

0. **Its own round trip.** A real stream hands the loudspeaker's sound back 0 to 300 ms later
   (more on ordinary desktop and phone audio), unknown, and changes it by a block after an
   underrun. The monitor searches the microphone's stream for the delay at which its own
   dithered pulses arrive (:mod:`.roundtrip`), reports it (``alert.latency_s``), follows the
   clocks' drift and the steps, and while it is not locked says "unlocked" and raises no alarm
   ("no_direct_sound" after a second: a muted loudspeaker). Another headset's pings, dithered by
   its own seed, land somewhere else every pulse, and half the time in the other code, 20 dB
   down: a line of them is rare, and short of an alarm's score (:attr:`~.tracks.Track.alerting`).
1. **Ranging.** The microphone's stream is correlated with each pulse's code as it arrives (the
   envelope, :class:`~.ranging.Envelope`); each pulse's own direct sound is its time reference;
   echo peaks above the noise floor and the direct sound's sidelobes are timed to a fraction of a
   sample (:class:`~.ranging.EchoFinder`). A surface straight ahead at ``d`` returns the echo path
   ``L = sqrt((2 d)^2 + s^2)`` (``s``: loudspeaker to microphone): ``d`` follows.
2. **Tracking.** Echo distances are chained over pulses into tracks, Kalman filters of range and
   closing speed (the closest pairs of echo and prediction first, of the surest tracks, within each
   track's gate: 12 cm while young, then five times its rms residual, at least 4 cm, or the filter's
   spread if wider); a track starts from three echoes no track took (or took over half its gate off)
   in a line over three pulses at a walking pace (:func:`~.tracks.initiate`: where other headsets'
   pings crowd the range, one echo says nothing of its speed), or from a line of faint echoes summed
   along each approach over eight pulses (:mod:`.faint`), which also keep a track that missed one.
   A track closing at the wearer's pace (the walls behind recede at it) weighs as a surface ahead.
   Lines at that pace may start on echoes tracks off it took (lent: :func:`~.tracks.initiate`).
3. **Alerts with hysteresis** (:mod:`.judge`). Only surfaces the wearer moves toward count (``approach_m``
   nearer within 0.8 s, in the last second) and will not pass by: a point at lateral offset
   ``a`` nears as d(t)^2 = (v (t_c - t))^2 + a^2, so a quadratic fit over the last 0.3 to 0.6 s
   (to 1.2 s for a track nearing under 1 m/s: the curvature is over the way walked) gives a^2,
   the closest point of approach; a surface is in the way when a^2 lies within +/- ``miss_m``^2
   by two standard errors (a surface straight ahead has a = 0; the wall above a door, heard by way
   of the ceiling, or a wall beside it by way of a side wall, nears too but passes by, and a track
   whose fit is poor waits). This is what tells the wall ahead from the floor, the ceiling and
   walls alongside, which one microphone cannot tell by direction.
   The echo is as old as the round trip: the level reckons where the wearer may be by now (the
   pulse may have left as soon as it was written). *caution* when time to contact is under
   ``caution_ttc_s`` or distance under ``caution_m``, *stop* under ``stop_m``; an alert ends only
   ``hysteresis_m`` beyond its threshold (or when the surface stops approaching for a second).
   A surface that closes at under half the wearer's pace (the fastest any surface heard nears
   or recedes, over the last second or so) lies far to the side: a wall converged on at 10
   degrees while walking through a door, a metre away. Its time to contact cautions, not its
   distance, and only under three quarters of ``caution_ttc_s``.

The alert is the gravest any surface in the way calls for (the soonest to contact among equals),
judged again whenever something it rests on changes: a pulse's window completes, a surface's
approach grows a second old, the wearer walks on to the next threshold, or the echo of the pulse
still arriving of a surface near a threshold has come in (that pulse is then analysed in the block
its echo ends, an undecided surface asked again with it).

The per-pulse work (echoes, faint ones, association, the fits, each block's read) runs in kernels
compiled by numba and cached (at install and when the first monitor is made, never in a callback).

Robustness: clipped samples are flagged (the timing survives clipping, and the clipped direct sound's
distortion is kept out); runs of exact zeros (dropouts) and non-finite samples are flagged, and a
pulse's window ends where they begin (the echoes heard wholly before them count; none if they reach the
direct sound); any block size, changing from call to call; 44.1 or 48 kHz.

``surface``: "opening" when the wearer moves and nothing ahead echoes; for an echoing surface
ahead, "closed" until the headset's camera has been shown it, then what the camera makes of it
(:meth:`BoundaryMonitor.see`, :mod:`vrecho.headset.view`): "wall" where the depth camera sees
the surface the echo comes from, "glass" or "mirror" (EchoCNN's visual branch on the pane's crop)
where it sees past it. The echo alone cannot tell them: glass, mirror and wall reflect a 4-20 kHz
chirp alike (their absorption differs by a few hundredths above 1 kHz, PROTOCOL.md), and the
cameras alone cannot find glass: it takes both.
"""

from __future__ import annotations

import numpy as np

from ..errors import VrechoError, check_count, check_number
from ..signals import SPEED_OF_SOUND
from .alert import Alert
from .echoes import EchoFinder, mic_geometry
from .kernels import compile_kernels, take
from .ranging import GUARD, Envelope, ProbeSchedule, channel0, clipped, pcm_scale, probe_codes, zero_runs
from .roundtrip import RoundTrip
from .faint import FaintEchoes
from .judge import PACE_MAX_MPS, Judge
from .tracks import LEND_MPS, Track, associate, attach_faint, clutter_strength, crowding, initiate
from .view import look_all


class BoundaryMonitor(Judge):
    """Echo ranging for a headset: call it with each microphone block and the loudspeaker block
    to fill, or hand :meth:`callback` to ``sounddevice.Stream`` (see the module's notes).

    Parameters
    ----------
    fs : {44100, 48000}
        Sample rate of both streams in Hz (default 48000).
    period_s : float
        Time between probe pulses in seconds, before the dither (default 0.04; sets the longest
        unambiguous range, c * period / 2). It must exceed the round trip to ``max_range_m``,
        the probe and the dither, and be at most 0.5 s.
    dither_s : float
        Each pulse leaves up to this much after its period's start, in seconds, drawn from
        ``seed`` (default 0.005): another headset's pings, dithered by its own seed, never line
        up with this one's echoes.
    seed : int, optional
        The dither's seed (default: a fresh random one; give one only to repeat a run).
    max_latency_s : float
        The longest round trip, speaker write to microphone read, searched for in seconds
        (default 0.35).
    max_range_m, min_range_m : float
        Echoes are looked for between these distances in metres (default 4 and 0.12).
    mic_offset_m : float or sequence of 3 floats
        Where the microphone is from the loudspeaker, as the headset's maker gives it: a
        distance in metres across the wearer's forward axis (PROTOCOL's device: 0.07 m, the
        default), or (forward, left, up) in metres; the part along the forward axis changes
        the echo's path from a surface ahead.
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
        An echo must rise this many times above the envelope's median (3.5, 11 dB: a wall 1.5 m
        ahead is heard through noise 20 dB below the direct sound, or a headset whose microphone
        sits a centimetre from its loudspeaker; the tracks keep single noise peaks from mattering).
    on_alert : callable, optional
        Called with the new :class:`Alert` whenever the level changes, from the audio thread
        (keep it short: put the alert on a queue).

    Attributes
    ----------
    alert : Alert
        The alert returned for the last block.
    schedule : ProbeSchedule
        When the probe is played, and which code.
    probes : tuple of numpy.ndarray
        The codes (:func:`~.ranging.probe_codes`).

    Raises
    ------
    VrechoError
        For another sample rate, a ``period_s`` out of range, thresholds out of order, a
        parameter that is not a finite number at least 0 (``threshold`` at least 1,
        ``max_range_m`` at least 0.05, above ``min_range_m``) or a ``seed`` that is not a
        whole number from 0 to 2**32 - 1.

    Examples
    --------
    >>> import numpy as np
    >>> from vrecho.headset import BoundaryMonitor
    >>> monitor = BoundaryMonitor(48000, seed=0)
    >>> speaker = np.zeros(480)  # a 10 ms block
    >>> mic = 1e-3 * np.random.default_rng(0).standard_normal(480)
    >>> alert = monitor(mic, speaker)  # speaker now holds what is due of the probe
    >>> alert.level, alert.distance_m, alert.flags
    ('clear', None, ('unlocked',))
    """

    def __init__(self, fs: int = 48000, *, period_s: float = 0.04, dither_s: float = 0.005, seed: int | None = None,
                 max_latency_s: float = 0.35, max_range_m: float = 4.0, min_range_m: float = 0.12,
                 mic_offset_m=0.07, caution_ttc_s: float = 2.0, caution_m: float = 1.0, stop_m: float = 0.5,
                 hysteresis_m: float = 0.1, approach_m: float = 0.12, miss_m: float = 0.4, threshold: float = 3.5,
                 on_alert=None):
        if isinstance(fs, bool) or not isinstance(fs, (int, float, np.integer, np.floating)) \
                or fs not in (44100, 48000):
            raise VrechoError(f"fs: expected 44100 or 48000 Hz, got {fs!r}")
        fs = int(fs)
        for name, v, lo in (("period_s", period_s, 0.0), ("dither_s", dither_s, 0.0),
                            ("max_latency_s", max_latency_s, 0.0), ("max_range_m", max_range_m, 0.05),
                            ("min_range_m", min_range_m, 0.0), ("caution_ttc_s", caution_ttc_s, 0.0),
                            ("caution_m", caution_m, 0.0), ("stop_m", stop_m, 0.0), ("hysteresis_m", hysteresis_m, 0.0),
                            ("approach_m", approach_m, 0.0), ("miss_m", miss_m, 0.0), ("threshold", threshold, 1.0)):
            check_number(v, name, lo=lo)
        if not min_range_m < max_range_m:
            raise VrechoError(f"min_range_m: must be below max_range_m ({max_range_m} m), got {min_range_m}")
        if seed is not None:
            check_count(seed, "seed", 2**32 - 1, 0)
        probes = probe_codes(fs)
        m = len(probes[0])
        least = 2 * max_range_m / SPEED_OF_SOUND + (m + 2 * GUARD) / fs + dither_s + 0.001
        if not least < period_s <= 0.5 or dither_s < 0:
            raise VrechoError(f"period_s: must exceed the round trip to max_range_m, the probe and the dither "
                              f"({least:.3f} s) and be at most 0.5 s, got {period_s}")
        if not 0 < stop_m < caution_m and caution_ttc_s > 0 and hysteresis_m >= 0:
            raise VrechoError("thresholds: need 0 < stop_m < caution_m, caution_ttc_s > 0, hysteresis_m >= 0")
        if not 0 <= max_latency_s <= 2.0:
            raise VrechoError(f"max_latency_s: expected 0 to 2 s, got {max_latency_s}")
        self.fs = fs
        self.probes = probes
        self.schedule = ProbeSchedule(fs, probes, period_s=period_s, dither_s=dither_s, seed=seed)
        self.period = self.schedule.period
        self.max_range_m, self.min_range_m, self.mic_offset_m = max_range_m, min_range_m, mic_offset_m
        self._mic = mic_geometry(mic_offset_m)  # (spacing, its forward part)
        self.caution_ttc_s, self.caution_m, self.stop_m = caution_ttc_s, caution_m, stop_m
        self.hysteresis_m, self.approach_m, self.threshold = hysteresis_m, approach_m, threshold
        self.miss_m, self.on_alert = miss_m, on_alert
        # A pulse's window: from its direct sound to the echoes from max_range_m, and the probe.
        self.window = int((2 * max_range_m / SPEED_OF_SOUND) * fs) + m + 2
        self._lock = RoundTrip(self.schedule, max_latency_s, int(0.002 * fs))
        size = 1 << int(np.ceil(np.log2(self._lock.max + 4 * (self.period + self.schedule.dither) + self.window)))
        self._env = Envelope(probes, size)
        self._now = 0  # samples processed so far (the microphone's clock)
        self._written = 0  # samples written to the loudspeaker (= received from the microphone, staged ones too)
        self._played = 0  # the first pulse not yet wholly written to the loudspeaker (ProbeSchedule.fill)
        self._staged = 0  # samples received but not yet processed (small blocks, gathered in _stage)
        self._clipped_at = -(1 << 40)  # the sample at which a block last came clipped
        self._alerted = None  # the verdict the last alert told, when that alert had no flags of its own
        self._announced = "clear"  # the level on_alert was last called with
        self._judged = 0  # samples received at the last judgement
        self._searched = -self.period  # samples received at the last search for the round trip
        self._next = 0  # the next pulse to commit
        self._tracks: list[Track] = []
        self._fresh: list[tuple] = []  # the last pulses' echoes no track took (tracks.initiate)
        self._alert = self._verdict = Alert(flags=("unlocked",))  # the alert returned; the last judgement behind it
        self._verdict_track: Track | None = None  # the surface it rests on
        self._oldest_approach = self._judge_at = np.inf  # earliest approached_at judged; next threshold's time (s)
        self._stage = np.zeros(_STAGE, np.float32)
        self._block = np.zeros(0, np.float32)  # the block being read, as float32 (reused)
        self._ends_for, self._ends = -1, []  # the pulse whose echoes' lags _echo_ends gave, and those lags
        self._still: list[float] = []  # distances of the surfaces that stay put, at the last commit
        self._level, self._pace, self._behind, self._paced_at = "clear", 0.0, 0.0, 0.0  # the wearer's pace, the walls behind's
        self._echoes = EchoFinder(probes, fs, self.window, threshold=threshold, min_range_m=min_range_m,
                                  max_range_m=max_range_m, mic_offset_m=mic_offset_m)
        self._faint = FaintEchoes(fs, self.window, self._mic, threshold)  # (echoes too weak for one pulse: faint.py)
        compile_kernels()

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

    def callback(self, indata, outdata, frames: int, time, status) -> None:
        """sounddevice's full-duplex callback: ``sounddevice.Stream(callback=monitor.callback)``.

        Fills every output channel with the probe, reads input channel 0, and keeps the alert
        at :attr:`alert` (``on_alert`` is called when its level changes). A status that reports
        lost samples (an underrun or overrun) tells the lock on the round trip that it may have
        moved.

        Parameters
        ----------
        indata : numpy.ndarray [shape=(frames, channels)]
            The microphone's block.
        outdata : numpy.ndarray [shape=(frames, channels)]
            The loudspeaker's block, filled in place.
        frames : int
            The block's length.
        time : object
            The stream's timestamps (unused: the monitor finds its round trip itself).
        status : sounddevice.CallbackFlags
            True when the stream lost or invented samples.

        Raises
        ------
        VrechoError
            For ``frames`` other than the blocks' length, or blocks :meth:`process` refuses.
        """
        if (type(indata) is np.ndarray and type(outdata) is np.ndarray and indata.ndim == 2 == outdata.ndim
                and indata.dtype.char == "f" == outdata.dtype.char and type(frames) is int
                and frames == len(indata) == len(outdata) and indata.shape[1] and outdata.shape[1]
                and outdata.flags.writeable):  # (sounddevice's float32 blocks: no more to check)
            if status:
                self._lock.suspect()
            self._played = self.schedule.fill(self._written, outdata, self._played)
            self._read(indata[:, 0])
            return
        length = np.shape(indata)[0] if np.ndim(indata) else None
        if isinstance(frames, bool) or not isinstance(frames, (int, np.integer)) or frames != length:
            raise VrechoError(f"frames: expected the microphone block's length, {length}, got {frames!r}")
        if status:
            self._lock.suspect()
        self.process(indata, outdata)

    def process(self, mic, speaker=None) -> Alert:
        """Read one microphone block, fill the loudspeaker block, and return the alert.

        Parameters
        ----------
        mic : numpy.ndarray [shape=(frames,) or (frames, channels)]
            Samples in [-1, 1], or PCM integers (int32, int16, int8, uint8: their full scale);
            channel 0 is used; any block size, changing from call to call. NaN or infinite
            samples are flagged ("nan") and not listened to.
        speaker : numpy.ndarray [shape=(frames,) or (frames, channels)], optional
            A writable array of the same number of frames, floats or PCM integers, filled in
            place (every channel gets the probe, scaled to the integers' full scale); None when
            the probe is played some other way (:meth:`speaker_block` gives the samples).

        Returns
        -------
        Alert
            A new one per block (one already returned keeps its flags).

        Raises
        ------
        VrechoError
            For a ``mic`` or ``speaker`` block that is not (frames,) or (frames, channels) of
            floats or integers (bool, complex, no channel), a ``speaker`` block of another
            length, not a NumPy array or read-only; checked before anything is written or
            heard.
        """
        x = channel0(np.asarray(mic), "mic")
        n = len(x)
        if speaker is not None:
            if not isinstance(speaker, np.ndarray):
                raise VrechoError(f"speaker: expected a NumPy array to fill in place, got {type(speaker).__name__}")
            channel0(speaker, "speaker")
            if len(speaker) != n:
                raise VrechoError(f"speaker: expected {n} frames like the microphone block, got {len(speaker)}")
            if not speaker.flags.writeable:
                raise VrechoError("speaker: the block is read-only; the monitor writes its probe into it")
            if speaker.dtype.kind == "f":
                self._played = self.schedule.fill(self._written, speaker, self._played)
            else:  # PCM: the probe (peak under 1) scaled to the integers' full scale
                offset, scale = pcm_scale(speaker.dtype)
                info = np.iinfo(speaker.dtype)
                block = np.clip(np.round(offset + scale * self.speaker_block(n)), info.min, info.max)
                speaker[...] = block[:, None] if speaker.ndim == 2 else block
        if x.dtype.kind != "f":
            offset, scale = pcm_scale(x.dtype)
            x = (x.astype(np.float32) - offset) / scale
        return self._read(x)

    def _read(self, x: np.ndarray) -> Alert:
        """Listen to one microphone block of floats (:meth:`process` after its checks)."""
        n, staged = len(x), self._staged
        self._written += n
        if staged + n < _STAGE:  # small blocks wait for a few milliseconds' worth (the work is per block)
            if x.dtype.char == "f":
                self._stage[staged:staged + n] = x
            else:  # (float64: beyond float32's range, infinite without a warning)
                take(x, self._stage, staged)
            self._staged += n
            return self._alert
        if len(self._block) < staged + n:
            self._block = np.empty(staged + n, np.float32)
        got = self._block[:staged + n]  # (pushed, a copy, before the next block overwrites it)
        got[:staged] = self._stage[:staged]
        top, nonfinite, zeros, at_top = take(x, got, staged)  # (the usual block: one pass, no array)
        x, n, self._staged = got, staged + n, 0
        flags = []
        valid = _TRUE[:n] if n <= len(_TRUE) else np.ones(n, bool)
        if nonfinite:
            finite = np.isfinite(x)
            flags.append("nan")
            x[~finite] = 0.0
            valid = finite
        if zeros or nonfinite:
            zero = zero_runs(x, 32) & valid
            if zero.any():
                flags.append("dropout")
                valid = valid & ~zero
        if top > 0 and at_top >= 3 and clipped(x):
            flags.append("clipped")
            self._clipped_at = self._now + n
        size = self._env.size // 2
        for lo in range(0, n, size):  # a block longer than half the memory: in pieces, in order
            self._env.push(x[lo:lo + size], valid[lo:lo + size])
            self._now += len(x[lo:lo + size])
            self._update()
        v, tr = self._verdict, self._verdict_track
        surface = tr.surface if tr is not None else v.surface  # the camera may have seen it since
        latency = self.latency_s
        last = self._alert
        if flags or v is not self._alerted or surface != last.surface or latency != last.latency_s:
            self._alert = Alert(v.level, v.distance_m, surface, v.confidence, v.closing_speed_mps, v.time_to_contact_s,
                                tuple(dict.fromkeys(v.flags + tuple(flags))), v.pulse_time_s, latency)
            self._alerted = v if not flags else None
        if self.on_alert is not None and self._alert.level != self._announced:
            self._announced = self._alert.level
            self.on_alert(self._alert)
        return self._alert

    def speaker_block(self, n: int) -> np.ndarray:
        """The loudspeaker's next ``n`` samples (:attr:`schedule`'s pulses).

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
        return self.schedule.block(self._written, n)

    @property
    def alert(self) -> Alert:
        """The alert returned for the last block (a clear one before the first)."""
        return self._alert

    @property
    def latency_s(self) -> float | None:
        """The round trip the monitor is locked on, speaker write to microphone read, in seconds
        (the direct sound's flight over ``mic_offset_m`` taken out), or None while it is not."""
        d = self._lock.delay
        return None if d is None else max(d / self.fs - self._mic[0] / SPEED_OF_SOUND, 0.0)

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
        # The frame shows the wearer now; the echoes left half a round trip after they were written.
        t = self._now / self.fs - 0.5 * (self.latency_s or 0.0)
        fresh = t - (self.latency_s or 0.0) * 0.5
        verdict = self._verdict_track
        near = sorted((tr for tr in list(self._tracks)  # the audio thread may change the list meanwhile
                       if tr is not verdict and tr.ahead is not False and fresh - tr.times[-1] < 0.2
                       and (tr.speed or 0.0) < -0.2), key=lambda tr: tr.predict(t))
        asked = [(tr, tr.predict(t)) for tr in ([verdict] if verdict is not None else []) + near[:3 - (verdict is not None)]]
        asked = [(tr, d) for tr, d in asked if d > self.min_range_m]
        for (tr, _), v in zip(asked, look_all(image, depth, intrinsics, [d for _, d in asked], model=model)):
            if v is not None:
                tr.views[v.surface] = tr.views.get(v.surface, 0.0) + v.confidence
        return verdict.surface if verdict is not None else None

    # -- Internals ---------------------------------------------------------------------------------
    def _update(self) -> None:
        """While searching, look for the round trip (once a period); once locked, commit every
        pulse whose window is complete, then judge the current pulse from what has arrived of it."""
        env, lock = self._env, self._lock
        if lock.delay is None:
            if self._now - self._searched < self.period:  # (a search a pulse: each takes a pulse's worth more in)
                return
            self._searched = self._now
            env.compute(env.ready())
            if not lock.search(env):
                searching = (self._now - lock.searching_since) / self.fs
                flags = ("unlocked", "no_direct_sound") if searching > 1.0 else ("unlocked",)
                if self._verdict.flags != flags or self._verdict.level != "clear":
                    self._level, self._verdict_track = "clear", None
                    self._verdict = Alert(flags=flags)
                return
            env.searching = False
            held = env.n - env.size + 2 * GUARD + lock.guard - int(lock.delay)  # pulses whose direct sound is still held
            self._next = max(self._next, self.schedule.first_at_or_after(max(held, 0)))
            env.redo(int(lock.due(self._next)) - lock.guard - 4)  # the search's envelope was all codes': each its own now
        sch, changed = self.schedule, False
        while lock.delay is not None:
            k = self._next
            due = lock.due(k)
            end = int(due) + self.window
            ready = env.ready()
            if ready < end:
                break
            env.skip(int(due) - lock.guard - 4)  # locked: only the pulses' windows are looked at
            env.compute(end, code=sch.code(k))
            ref = lock.follow(env, k, self._now)
            if lock.delay is None:  # lost: no alarm, and search again from the next block
                self._searched = -self.period
                env.searching = True
                self._level, self._verdict_track, self._verdict = "clear", None, Alert(flags=("unlocked",))
                return
            if lock.replay is not None:  # a step (every one names the pulse it hid): heard afresh from that
                j, lock.replay, oldest = lock.replay, None, env.n - env.size + GUARD  # pulse (its samples held)
                self._next = j if int(lock.due(j)) - lock.guard - 4 >= oldest else k + 1
                env.redo(int(lock.due(self._next)) - lock.guard - 4)
                if self._next <= k:
                    continue
            if ref is not None:
                echoes = self._echoes.find(self._env, ref, end, code=sch.code(k), clipped=self._clipped_at > ref - 8192)
                if echoes is not None:
                    t = sch.emission(k) / self.fs
                    faint = self._faint.add(t, *self._echoes.last, self._still) if self._echoes.last else ((), ())
                    self._commit(t, echoes, *faint)
                    changed, self._ends_for = True, -1
            self._next = k + 1
        partial = None  # (k, due and ready: the pulse the loop stopped at)
        if ready > due + self._env.m:
            # A surface near a threshold: its echo of this pulse may cross it; looked for in the block it ends in (+/- 1.5 ms).
            margin = 0.0015 * self.fs
            judged = self._judged - self._env.m - GUARD + 1  # the envelope ready at the last judgement
            if self._ends_for != k:  # asked once a pulse: the tracks change only when a pulse is committed
                self._ends_for, self._ends = k, self._echo_ends(k)
            if any(judged < due + lag + margin and ready >= due + lag - margin for lag in self._ends):
                env.skip(int(due) - lock.guard - 4)
                env.compute(ready, code=sch.code(k))
                partial = self._echoes.find(env, due, ready, code=sch.code(k), clipped=self._clipped_at > due - 8192)
        # Judged again on new tracks, a pulse arriving, an approach a second old, or a threshold near.
        t_now = self._now / self.fs
        if changed or partial or t_now >= self._judge_at or t_now - self._oldest_approach > 1.0 \
                or "unlocked" in self._verdict.flags:
            self._judge(partial, sch.emission(k) / self.fs)
        self._judged = self._now

    def _commit(self, t: float, echoes, faint=(), lines=()) -> None:
        """Add the echoes of the pulse emitted at ``t`` (seconds), its faint ones and their lines, to the tracks."""
        updated, clutter = [], len(echoes) / (self.max_range_m - self.min_range_m)  # peaks per metre in this pulse
        behind = min(max(self._behind, 0.0), PACE_MAX_MPS)  # the wearer's pace as the walls behind recede (Track.update)
        mean_strength = clutter_strength(echoes)
        fresh, lent, near = [], [], sorted(d for d, _ in echoes)
        lending = self._pace_sure(behind)  # (initiate's lines at the pace borrow echoes only while it is sure)
        for tr, d, strength in associate(self._tracks, t, echoes):
            if tr is None or abs(d - tr.predict(t)) > 0.5 * tr.gate_m:  # (taken far off its track's line: may
                fresh.append((d, strength))  # be another surface's, whose range the track crossed, and start its own)
            elif lending and abs((tr.speed or 0.0) + behind) > LEND_MPS:
                lent.append((d, strength))
            if tr is not None:
                tr.update(t, d, strength, clutter_per_m=crowding(near, d, clutter), clutter_strength=mean_strength, pace=behind)
                updated.append(tr)
        fresh.sort()
        seeded, lifted = attach_faint(self._tracks, t, faint, lines, clutter, mean_strength, fresh, behind)
        for tr in (tr for tr in self._tracks if tr.times[-1] != t):
            tr.missed()
        # New surfaces: three echoes no track took (or lent), in a line over the last three pulses, or faint lines.
        self._fresh = self._fresh[-2:] + [(t, fresh, clutter, mean_strength, sorted(lent))]
        born = initiate(self._fresh, pace=behind) + seeded
        self._tracks += born
        updated += lifted + born
        for tr in (tr for tr in updated if tr.closed_in(0.8) >= self.approach_m):
            tr.approached_at = t
        # Only a surface being approached can need an alert: the fits are for those.
        still = self._still = [tr.d_hat for tr in self._tracks if len(tr.times) >= 10 and tr.speed is not None
                               and abs(tr.speed) < 0.25 and tr.d_hat >= self.miss_m and tr.confirmed]
        for tr in updated:
            was, tr.ahead = tr.ahead, None
            closing = -(tr.speed or 0.0)
            soon = tr.d_hat < self.caution_m + 0.5 or (closing > 0.05 and tr.d_hat / closing < self.caution_ttc_s + 0.75)
            # The fit only where an alert may come within half a second or so, for a surface (score).
            if t - tr.approached_at <= 1.0 and soon and tr.confirmed:
                tr.ahead = tr.in_the_way(self.miss_m)
                if tr.ahead and tr.explained_by(still):
                    tr.ahead = False
                elif tr.ahead is None and was:  # once in the way, until the fit says it passes by (or not a surface)
                    tr.ahead = True
        # Dropped: a track not heard for 0.3 s, and one proved stray (dense where other headsets ping).
        self._tracks = [tr for tr in self._tracks if t - tr.times[-1] <= 0.3 and not tr.stray]
        if len(self._tracks) > 32:  # clutter: keep the likeliest surfaces, then the nearest
            self._tracks = sorted(self._tracks, key=lambda tr: (-tr.score, tr.dists[-1]))[:32]


_TRUE = np.ones(8192, bool)  # every sample sound: the usual block's mask, never written to
_STAGE = 441  # smaller blocks are gathered to that many (10 ms at 44.1 kHz: 16 samples cost what 480 do)
