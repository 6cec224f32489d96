"""The headset's ranging front end: its probe and when it plays it, the microphone's matched-filter
envelope as a stream, and the lock on its own round trip.

A real duplex stream delays what the loudspeaker plays by an unknown round trip before the
microphone hands it back (0 to 300 ms and more, changing after an underrun), and other headsets
in the room play the same call. So:

- :class:`ProbeSchedule`: each pulse leaves a whole period after the last plus a dither of up to
  a few milliseconds, drawn from the monitor's own seed. The monitor's own echoes keep their
  delays after its own direct sound from pulse to pulse; another headset's pings (its own dither)
  land somewhere else every pulse, so no track follows them.
- :class:`Envelope`: the microphone's samples and the envelope of their correlation with the
  probe, computed once per sample as the stream arrives (in pieces of any size; a few samples of
  guard at each piece's edges keep the analytic signal exact to -50 dB).
- :class:`EchoFinder`: a pulse's echoes in the envelope, timed against its direct sound.

The lock on the monitor's own round trip is :mod:`.roundtrip`'s.
"""

from __future__ import annotations

import numpy as np
from scipy import fft
from scipy.ndimage import maximum_filter1d
from scipy.signal import chirp
from scipy.signal.windows import tukey

from ..errors import VrechoError
from ..signals import SPEED_OF_SOUND, analytic_envelope, analytic_filter, parabolic_peaks

GUARD = 16
"""Samples of guard at each edge of a piece of the streamed envelope (the analytic signal's tails
are 50 dB down there)."""
POOL = 4
"""Samples per cell of the coarse envelope the round trip is first searched in (the envelope's
main lobe is some 3 samples wide)."""


def ranging_probe(fs: int, *, duration_s: float = 0.005, f0: float = 4000.0, f1: float = 20000.0) -> np.ndarray:
    """A ranging probe: a linear chirp from ``f0`` to ``f1`` Hz (up or down) over ``duration_s``,
    Tukey window (25 %), peak 0.5.

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
        When either frequency is not below the Nyquist frequency ``fs / 2``.

    Examples
    --------
    >>> from vrecho.headset import ranging_probe
    >>> ranging_probe(48000).shape
    (240,)
    """
    top = max(f0, f1)
    if top >= fs / 2:
        raise VrechoError(f"probe: {top} Hz needs a sample rate above {2 * top:.0f} Hz, got {fs}")
    t = np.arange(int(round(duration_s * fs))) / fs
    return (0.5 * chirp(t, f0, duration_s, f1) * tukey(len(t), 0.25)).astype(np.float64)


CODES_HZ = ((4000.0, 20000.0), (20000.0, 4000.0))
"""The probe's two codes: a chirp up or down through 4 to 20 kHz. Each pulse plays one, drawn
from the monitor's seed: another headset's ping in the other code reaches this one's matched
filter 20 dB down (the two have the same envelope of autocorrelation: the same ranging)."""
CODE_S = 0.005
"""Each code's length in seconds."""


def probe_codes(fs: int) -> tuple[np.ndarray, ...]:
    """The headset's probe codes at ``fs`` (:data:`CODES_HZ`, :data:`CODE_S` long).

    Parameters
    ----------
    fs : int
        Sample rate in Hz (above 40 kHz).

    Returns
    -------
    tuple of numpy.ndarray [shape=(round(CODE_S * fs),)]

    Examples
    --------
    >>> [len(c) for c in probe_codes(48000)]
    [240, 240]
    """
    return tuple(ranging_probe(fs, duration_s=CODE_S, f0=a, f1=b) for a, b in CODES_HZ)


def _mix(seed: int, k: int) -> int:
    """splitmix64 of (seed, k): a pulse's dither, at random access."""
    z = (seed + 0x9E3779B97F4A7C15 * (k + 1)) & 0xFFFFFFFFFFFFFFFF
    z = ((z ^ (z >> 30)) * 0xBF58476D1CE4E5B9) & 0xFFFFFFFFFFFFFFFF
    z = ((z ^ (z >> 27)) * 0x94D049BB133111EB) & 0xFFFFFFFFFFFFFFFF
    return z ^ (z >> 31)


class ProbeSchedule:
    """When and what the loudspeaker plays: pulse ``k`` starts at sample ``k * period + dither_k``
    and plays code ``code(k)``.

    Parameters
    ----------
    fs : int
        Sample rate in Hz.
    probes : numpy.ndarray [shape=(m,)] or sequence of them
        The codes a pulse may play (all ``m`` long); one array: every pulse plays it.
    period_s : float
        The nominal time between pulses in seconds (default 0.04).
    dither_s : float
        Each pulse leaves up to this much later than its period's start, in seconds (default
        0.005; 0 plays a regular train).
    seed : int, optional
        Draws the dithers and codes; a fresh random one by default, so that two headsets differ.

    Attributes
    ----------
    period, dither : int
        The period and the largest dither, in samples.
    probes : tuple of numpy.ndarray
        The codes.

    Examples
    --------
    >>> from vrecho.headset.ranging import ProbeSchedule, probe_codes
    >>> s = ProbeSchedule(48000, probe_codes(48000), seed=1)
    >>> [s.emission(k) for k in range(3)], [s.code(k) for k in range(3)]
    ([74, 2044, 3876], [0, 1, 1])
    >>> s.first_at_or_after(2000)
    1
    """

    def __init__(self, fs: int, probes, *, period_s: float = 0.04, dither_s: float = 0.005,
                 seed: int | None = None):
        self.fs = int(fs)
        probes = [probes] if isinstance(probes, np.ndarray) and probes.ndim == 1 else list(probes)
        self.probes = tuple(np.asarray(p, float) for p in probes)
        if len({len(p) for p in self.probes}) != 1:
            raise VrechoError("probes: every code must be as long as the others")
        self.period = int(round(period_s * fs))
        self.dither = int(round(dither_s * fs))
        self.seed = int(np.random.SeedSequence(seed).generate_state(1, np.uint64)[0])
        self._recent: dict[int, tuple[int, int]] = {}

    @property
    def length(self) -> int:
        """A pulse's length in samples."""
        return len(self.probes[0])

    def _pulse(self, k: int) -> tuple[int, int]:
        p = self._recent.get(k)
        if p is None:
            if len(self._recent) > 256:
                self._recent.clear()
            z = _mix(self.seed, k)
            p = self._recent[k] = (k * self.period + (z % (self.dither + 1) if self.dither else 0),
                                   (z >> 40) % len(self.probes))
        return p

    def emission(self, k: int) -> int:
        """The sample at which pulse ``k`` (0, 1, ...) starts.

        Parameters
        ----------
        k : int

        Returns
        -------
        int
        """
        return self._pulse(k)[0]

    def code(self, k: int) -> int:
        """Which of :attr:`probes` pulse ``k`` plays.

        Parameters
        ----------
        k : int

        Returns
        -------
        int
        """
        return self._pulse(k)[1]

    def probe(self, k: int) -> np.ndarray:
        """What pulse ``k`` plays.

        Parameters
        ----------
        k : int

        Returns
        -------
        numpy.ndarray [shape=(m,)]
        """
        return self.probes[self._pulse(k)[1]]

    def first_at_or_after(self, n: int) -> int:
        """The first pulse that starts at or after sample ``n``.

        Parameters
        ----------
        n : int

        Returns
        -------
        int
        """
        k = max((n - self.dither) // self.period, 0)
        while self.emission(k) < n:
            k += 1
        return k

    def block(self, start: int, n: int) -> np.ndarray:
        """The loudspeaker's samples ``start`` to ``start + n``.

        Parameters
        ----------
        start, n : int
            The block's first sample and its length.

        Returns
        -------
        numpy.ndarray [shape=(n,), dtype=float64]
        """
        out = np.zeros(n)
        m = self.length
        k = self.first_at_or_after(max(start - m + 1, 0))
        while (e := self.emission(k)) < start + n:
            lo, hi = max(e, start), min(e + m, start + n)
            if hi > lo:
                out[lo - start:hi - start] = self.probe(k)[lo - e:hi - e]
            k += 1
        return out


class Envelope:
    """The microphone's stream: its last samples, which of them are sound (not a dropout's zeros
    or NaNs), and the envelope of their correlation with the probe, by lag.

    The envelope at lag ``l`` says how much of a code starts at sample ``l``; it is computed
    once, in order, when asked for (:meth:`compute`), from samples ``l - GUARD`` to
    ``l + m + GUARD``, for one code (a pulse's window) or for all of them at once (the search
    for the round trip: their matched filters summed, each code's cross-talk with the others
    19 dB or more down).

    Parameters
    ----------
    probes : sequence of numpy.ndarray [shape=(m,)]
        The codes.
    size : int
        Samples kept (and envelope lags); older ones are forgotten.

    Attributes
    ----------
    n : int
        Samples received so far.
    done : int
        Lags whose envelope is computed: ``[done - size, done)`` are held.
    coarse : numpy.ndarray [shape=(size // POOL,)]
        The envelope's largest value in each cell of :data:`POOL` lags (cell ``g``: lags
        ``g * POOL`` on), as a ring like the envelope's; kept only while :attr:`searching`.
    searching : bool
        Keep :attr:`coarse` (setting it True fills it from the envelope held).
    """

    def __init__(self, probes, size: int):
        self.probes = tuple(np.asarray(p, np.float32) for p in probes)
        self.m = len(self.probes[0])
        self.size = int(size)
        self.x = np.zeros(self.size, np.float32)
        self.ok = np.zeros(self.size, bool)
        self.env = np.zeros(self.size, np.float32)
        self.coarse = np.zeros(self.size // POOL, np.float32)
        self._searching = True
        self.n = 0
        self.done = 0
        self._kernels: dict[int, np.ndarray] = {}

    def push(self, x: np.ndarray, ok: np.ndarray) -> None:
        """Append samples (at most :attr:`size` at a time).

        Parameters
        ----------
        x : numpy.ndarray [shape=(k,)]
            Samples, non-finite ones already zeroed.
        ok : numpy.ndarray [shape=(k,), dtype=bool]
            Which are sound.
        """
        at = self.n % self.size
        first = min(len(x), self.size - at)
        self.x[at:at + first], self.ok[at:at + first] = x[:first], ok[:first]
        self.x[:len(x) - first], self.ok[:len(x) - first] = x[first:], ok[first:]
        self.n += len(x)

    def ready(self) -> int:
        """The end of the lags whose envelope the samples received allow (exclusive).

        Returns
        -------
        int
        """
        return self.n - self.m - GUARD + 1

    def compute(self, upto: int, *, code: int | None = None) -> None:
        """Compute the envelope up to lag ``upto`` (exclusive), or as far as the samples allow.

        Parameters
        ----------
        upto : int
        code : int, optional
            The code to correlate with (all of them, summed, by default).
        """
        upto = min(upto, self.ready())
        self.done = max(self.done, self.n - self.size + GUARD)  # lags whose samples are gone stay unknown
        m = self.m
        while self.done < upto:
            lo = self.done
            hi = min(upto, lo + 8192)
            seg = self.samples(lo - GUARD, hi + m + GUARD - 1) if lo >= GUARD else \
                np.r_[np.zeros(GUARD - lo, np.float32), self.samples(0, hi + m + GUARD - 1)]
            nfft = fft.next_fast_len(len(seg) + m + GUARD, real=True)
            kernel = self._kernels.get((nfft, code))
            if kernel is None:
                sound = sum(self.probes) if code is None else self.probes[code]
                kernel = self._kernels[(nfft, code)] = analytic_filter(sound, nfft).astype(np.complex64)
            env = analytic_envelope(seg, kernel, nfft)[GUARD:GUARD + hi - lo]
            a = lo % self.size
            first = min(len(env), self.size - a)
            self.env[a:a + first] = env[:first]
            self.env[:len(env) - first] = env[first:]
            self.done = hi
            if self._searching:
                self._cells(lo, hi)

    def redo(self, frm: int) -> None:
        """Compute the envelope again from lag ``frm`` on (for another code), as far as the
        samples held allow.

        Parameters
        ----------
        frm : int
        """
        self.done = min(self.done, max(frm, self.n - self.size + GUARD))

    def skip(self, to: int) -> None:
        """Leave the envelope of lags up to ``to`` uncomputed (zero): none will be asked for.

        Parameters
        ----------
        to : int
        """
        if to > self.done and not self._searching:
            a, b = max(self.done, to - self.size), to
            a0 = a % self.size
            first = min(b - a, self.size - a0)
            self.env[a0:a0 + first] = 0.0
            self.env[:b - a - first] = 0.0
            self.done = to

    @property
    def searching(self) -> bool:
        """Whether :attr:`coarse` is kept (setting it True fills it from the envelope held)."""
        return self._searching

    @searching.setter
    def searching(self, on: bool) -> None:  # noqa: D102 (the property's docstring)
        if on and not self._searching:
            self._cells(max(self.done - self.size + POOL, 0), self.done)
        self._searching = bool(on)

    def _cells(self, lo: int, hi: int) -> None:
        """:attr:`coarse` for lags ``lo`` to ``hi`` (the first and last cells may be partly older or
        not yet done)."""
        g0, g1 = lo // POOL, -(-hi // POOL)
        cells = self._ring(self.env, g0 * POOL, g1 * POOL).reshape(-1, POOL).max(axis=1)
        c = self.coarse
        a = g0 % len(c)
        first = min(len(cells), len(c) - a)
        c[a:a + first], c[:len(cells) - first] = cells[:first], cells[first:]

    def _ring(self, ring: np.ndarray, a: int, b: int) -> np.ndarray:
        a0 = a % self.size
        if a0 + (b - a) <= self.size:
            return ring[a0:a0 + b - a]
        return ring[np.arange(a, b) % self.size]

    def cells(self, g0: int, g1: int) -> np.ndarray:
        """:attr:`coarse` cells ``g0`` to ``g1`` (computed ones only).

        Parameters
        ----------
        g0, g1 : int

        Returns
        -------
        numpy.ndarray [shape=(g1 - g0,), dtype=float32]
        """
        c = self.coarse
        a = g0 % len(c)
        return c[a:a + g1 - g0] if a + g1 - g0 <= len(c) else c[np.arange(g0, g1) % len(c)]

    def samples(self, a: int, b: int) -> np.ndarray:
        """Samples ``a`` to ``b`` (held ones only).

        Parameters
        ----------
        a, b : int

        Returns
        -------
        numpy.ndarray [shape=(b - a,), dtype=float32]
        """
        return self._ring(self.x, a, b)

    def envelope(self, a: int, b: int) -> np.ndarray:
        """The envelope at lags ``a`` to ``b`` (computed ones only).

        Parameters
        ----------
        a, b : int

        Returns
        -------
        numpy.ndarray [shape=(b - a,), dtype=float32]
        """
        return self._ring(self.env, a, b)

    def sound_until(self, a: int, b: int) -> int:
        """The first sample from ``a`` on, before ``b``, that is not sound (``b`` if none).

        Parameters
        ----------
        a, b : int

        Returns
        -------
        int
        """
        ok = self._ring(self.ok, a, b)
        return b if ok.all() else a + int(np.argmin(ok))


class EchoFinder:
    """A pulse's echoes in the envelope: peaks above the noise floor (``threshold`` times the
    envelope's median) and above the direct sound's sidelobes (when the direct sound is clipped,
    above the clipped probe's own distortion, which spreads over one probe's length after it),
    each timed to a fraction of a sample. A surface straight ahead at ``d`` returns the echo
    path ``L = sqrt((2 d)^2 + s^2)`` (``s``: loudspeaker to microphone): ``d`` follows.

    Parameters
    ----------
    probes : sequence of numpy.ndarray [shape=(m,)]
        The codes.
    fs : int
        Sample rate in Hz.
    window : int
        The longest lag after the direct sound looked at, in samples.
    threshold : float
        How far above the envelope's median an echo must rise (a factor).
    min_range_m, max_range_m : float
        The distances echoes are looked for between, in metres.
    mic_offset_m : float or sequence of 3 floats
        Loudspeaker to microphone (:func:`mic_geometry`).
    """

    def __init__(self, probes, fs: int, window: int, *, threshold: float, min_range_m: float,
                 max_range_m: float, mic_offset_m):
        self.probes, self.fs, self.window = tuple(probes), fs, window
        self.threshold, self.min_range_m, self.max_range_m = threshold, min_range_m, max_range_m
        self._mic = mic_geometry(mic_offset_m)
        self._clipped_floors: dict[tuple[int, int], np.ndarray] = {}
        # The direct sound's sidelobes by lag: 6 dB above the codes' own (the matched filter's
        # response to the code itself), and never below a floor falling from -32 dB (a real
        # loudspeaker's and microphone's own ringing).
        lag = np.arange(window + len(self.probes[0]), dtype=float)
        floor = 10 ** (-(32 + 6 * np.log2(np.maximum(lag, 1) / (0.0025 * fs) + 1)) / 20)
        own = np.max([self._response(p, len(lag)) for p in self.probes], axis=0)  # (doubled: 6 dB of slack)
        self._sidelobe = np.maximum(floor, own)
        reach = int(np.flatnonzero(own > 10 ** (-40 / 20))[-1]) + 1  # an echo's own sidelobes above -40 dB
        self._lobes = np.r_[1.0, own[1:reach]]

    @staticmethod
    def _response(x: np.ndarray, n_lags: int, probe: np.ndarray | None = None) -> np.ndarray:
        """The matched filter's envelope of ``probe`` (``x`` itself by default) on ``x``, relative
        to its lag-0 value, widened by a few samples (slack in timing) and doubled (6 dB)."""
        p = x if probe is None else probe
        m = len(p)
        n = 4 * m
        y = np.zeros(n - m)
        y[:m] = x
        env = analytic_envelope(y, analytic_filter(p, n), n)[:n - m]  # past n - m: negative lags
        out = np.zeros(max(n_lags, n - m))
        out[:len(env)] = 2.0 * maximum_filter1d(env / env[0], 9)
        out[:3] = 0.0  # (the main lobe itself)
        return out[:n_lags]

    def _clipped_sidelobe(self, fraction: float, code: int) -> np.ndarray:
        """The floor beside a clipped direct sound: the matched filter's response to the code
        clipped so that ``fraction`` of its samples sit at the rail (its distortion spreads over
        one code's length after the peak, up to some 30 dB below it), 6 dB above that, and never
        below the clean sidelobes. Cached in steps of 5 %."""
        step = max(1, int(round(fraction * 20)))
        if (step, code) not in self._clipped_floors:
            probe = self.probes[code]
            peak = np.abs(probe).max()  # (clipped wholly: its signs)
            level = max(np.quantile(np.abs(probe), 1 - step / 20), 1e-3 * peak)
            clipped = np.clip(probe, -level, level)
            self._clipped_floors[(step, code)] = np.maximum(self._sidelobe,
                                                            self._response(clipped, len(self._sidelobe), probe))
        return self._clipped_floors[(step, code)]

    def find(self, env: Envelope, ref: float, stop: int, *, code: int, clipped: bool = False):
        """The echoes of the pulse whose direct sound arrived at ``ref``, from the envelope up to
        lag ``stop``, keeping those that have ended before any damage.

        Parameters
        ----------
        env : Envelope
            The stream, its envelope computed up to ``stop``.
        ref : float
            The direct sound's arrival, in fractional samples: the time reference.
        stop : int
            The lag up to which to look (exclusive).
        code : int
            The code the pulse played (the envelope's).
        clipped : bool
            Whether a block near the direct sound came clipped (its distortion is then kept out).

        Returns
        -------
        list of (float, float) or None
            Each echo's distance in metres and strength (its peak as a share of the direct
            sound's); None when damage (a dropout, NaNs) reaches the direct sound.
        """
        d0 = int(round(ref))
        m = len(self.probes[0])
        good = env.sound_until(d0 - GUARD, stop + m)
        if good < d0 + m + GUARD:
            return None  # (the direct sound must be whole: it is the reference)
        stop = min(stop, good - m - GUARD + 1)  # damage ends the window: the echoes wholly heard before it count
        lo = int(ref + 2 * self.min_range_m / SPEED_OF_SOUND * self.fs)
        if lo >= stop - 2:
            return []
        span = env.envelope(d0, stop)
        peak_direct = float(env.envelope(d0 - 1, d0 + 2).max())
        sidelobe = self._sidelobe
        if clipped:
            rail = np.count_nonzero(at_rail(env.samples(d0, d0 + m)))
            if rail >= 3:  # the direct sound clipped: its distortion rises above the sidelobes, near it
                sidelobe = self._clipped_sidelobe(rail / m, code)
        seg = span[lo - d0:]
        quarter = seg[::4]  # every 4th lag: the floor, at a quarter of the cost
        noise = float(np.partition(quarter, len(quarter) // 2)[len(quarter) // 2]) + 1e-12
        above = np.flatnonzero(seg[1:-1] > self.threshold * noise) + 1  # few: the echoes' main lobes
        above = above[(seg[above] > seg[above - 1]) & (seg[above] >= seg[above + 1])]  # their local maxima
        # The direct sound's matched-filter sidelobes fall off with lag; an echo must rise above them too.
        peaks = above + lo - d0
        peaks = peaks[span[peaks] > peak_direct * sidelobe[peaks]]
        if len(peaks) > 1:  # one echo per surface: its own sidelobes (10, 18, 26... samples out) are not echoes
            peaks = self._own_lobes_out(span, peaks)
        if not len(peaks):
            return []
        excess = SPEED_OF_SOUND * (parabolic_peaks(span, peaks) + d0 - ref) / self.fs
        d = echo_distance(excess, *self._mic)
        ok = (excess > 0) & (d >= self.min_range_m) & (d <= self.max_range_m)
        return list(zip(d[ok].tolist(), (span[peaks][ok] / peak_direct).tolist()))

    def _own_lobes_out(self, span: np.ndarray, peaks: np.ndarray) -> np.ndarray:
        """The peaks less those that are a stronger peak's own sidelobes: within reach of it and
        no stronger, relative to it, than the codes' autocorrelation there (6 dB of slack)."""
        level = span[peaks].tolist()
        lags = peaks.tolist()
        reach = len(self._lobes)
        keep = []
        for i in sorted(range(len(lags)), key=level.__getitem__, reverse=True):
            if not any(abs(lags[i] - lags[j]) < reach and level[i] <= level[j] * self._lobes[abs(lags[i] - lags[j])]
                       for j in keep):
                keep.append(i)
        return peaks[sorted(keep)]


def mic_geometry(mic_offset_m) -> tuple[float, float]:
    """The loudspeaker-to-microphone spacing and its part along the wearer's forward axis.

    Parameters
    ----------
    mic_offset_m : float or sequence of 3 floats
        A spacing in metres across the forward axis, or the microphone's place from the
        loudspeaker, (forward, left, up) in metres, as the headset's maker gives it.

    Returns
    -------
    spacing, forward : float
        In metres.

    Raises
    ------
    VrechoError
        For a spacing that is not 0 to 0.5 m, or not three finite numbers.

    Examples
    --------
    >>> mic_geometry(0.07), mic_geometry((0.03, 0.0, 0.04))
    ((0.07, 0.0), (0.05, 0.03))
    """
    o = np.atleast_1d(np.asarray(mic_offset_m, float))
    if o.shape not in ((1,), (3,)) or not np.all(np.isfinite(o)):
        raise VrechoError(f"mic_offset_m: expected metres, or (forward, left, up) in metres, got {mic_offset_m!r}")
    s = float(np.linalg.norm(o))
    if not 0.0 <= s <= 0.5:
        raise VrechoError(f"mic_offset_m: expected a spacing of 0 to 0.5 m, got {s:.3f} m")
    return round(s, 12), round(float(o[0]) if o.shape == (3,) else 0.0, 12)


def echo_path(d, spacing: float, forward: float):
    """The echo path's excess over the direct path, for a surface ``d`` straight ahead.

    The image of the loudspeaker lies ``2 d`` ahead; the microphone ``forward`` ahead of the
    loudspeaker and ``spacing`` from it: the path is sqrt(4 d^2 - 4 d forward + spacing^2).

    Parameters
    ----------
    d : float or numpy.ndarray
        Distance to the surface's plane, metres.
    spacing, forward : float
        :func:`mic_geometry`'s.

    Returns
    -------
    float or numpy.ndarray
        Metres, the path less the direct path (``spacing``).
    """
    return np.sqrt(4 * d * d - 4 * d * forward + spacing * spacing) - spacing


def echo_distance(excess, spacing: float, forward: float):
    """:func:`echo_path` inverted: the distance to the surface ahead whose echo came ``excess``
    metres of path after the direct sound.

    Parameters
    ----------
    excess : float or numpy.ndarray
        Metres of path after the direct sound.
    spacing, forward : float
        :func:`mic_geometry`'s.

    Returns
    -------
    float or numpy.ndarray
        Metres.

    Examples
    --------
    >>> round(float(echo_distance(echo_path(1.2, 0.05, 0.03), 0.05, 0.03)), 9)
    1.2
    """
    path = excess + spacing
    return 0.5 * (forward + np.sqrt(np.maximum(forward * forward - spacing * spacing + path * path, 0.0)))


def zero_runs(x: np.ndarray, min_len: int) -> np.ndarray:
    """Samples in runs of at least ``min_len`` exact zeros (a dropout, not silence: real
    microphones always carry noise).

    Parameters
    ----------
    x : numpy.ndarray [shape=(n,)]
    min_len : int

    Returns
    -------
    numpy.ndarray [shape=(n,), dtype=bool]
    """
    if np.count_nonzero(x) == len(x):
        return np.zeros(len(x), bool)
    z = np.concatenate([[False], x == 0, [False]])
    edges = np.flatnonzero(np.diff(z.astype(np.int8)))
    out = np.zeros(len(x), bool)
    for a, b in zip(edges[::2], edges[1::2]):
        if b - a >= min_len:
            out[a:b] = True
    return out


def at_rail(x: np.ndarray) -> np.ndarray:
    """The samples at ``x``'s largest magnitude (none if it is silent).

    Parameters
    ----------
    x : numpy.ndarray [shape=(n,)]

    Returns
    -------
    numpy.ndarray [shape=(n,), dtype=bool]
    """
    a = np.abs(x)
    m = float(a.max(initial=0.0))
    return a >= m * (1 - 1e-6) if m > 0.0 else np.zeros(len(a), bool)


def clipped(x: np.ndarray) -> bool:
    """Flat tops: three or more consecutive samples at the block's largest magnitude (a clipping
    converter or limiter holds its rail; a real signal does not).

    Parameters
    ----------
    x : numpy.ndarray [shape=(n,)]

    Returns
    -------
    bool
    """
    top = at_rail(x)
    if np.count_nonzero(top) < 3:  # the usual block: one loudest sample
        return False
    return bool(np.any(top[2:] & top[1:-1] & top[:-2]))
