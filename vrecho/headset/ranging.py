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
A pulse's echoes in the envelope are :mod:`.echoes`'s; the lock on the monitor's own round
trip is :mod:`.roundtrip`'s.
"""

from __future__ import annotations

import numpy as np
from scipy.signal import chirp
from scipy.signal.windows import tukey

from ..errors import VrechoError
from ..signals import analytic_filter
from .kernels import correlate

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
        self._silent = (0, 0, 0)  # samples [from, to) known to hold no pulse, and the first pulse after them

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
        self.fill(start, out)
        return out

    def fill(self, start: int, out: np.ndarray, k: int = 0) -> int:
        """Write the loudspeaker's samples from ``start`` on into ``out`` in place, every channel
        the same (an audio callback's output block, no new array).

        Parameters
        ----------
        start : int
            The block's first sample.
        out : numpy.ndarray [shape=(n,) or (n, channels)], float
            The block.
        k : int
            The first pulse that may still sound there (what the last call returned; looked up
            afresh when it has ended before ``start``).

        Returns
        -------
        int
            The first pulse that may sound after this block: ``k`` for the next call.
        """
        out.fill(0.0)
        end = start + len(out)
        silent_from, silent_to, after = self._silent
        if silent_from <= start and end <= silent_to:  # (most small blocks: between two pulses)
            return after
        m = self.length
        if self.emission(k) + m <= start:
            k = self.first_at_or_after(max(start - m + 1, 0))
        while (e := self.emission(k)) < end:
            lo, hi = max(e, start), min(e + m, end)
            seg = self.probe(k)[lo - e:hi - e]
            out[lo - start:hi - start] = seg[:, None] if out.ndim == 2 else seg
            if e + m > end:
                return k
            k += 1
        self._silent = (end, e, k)  # nothing sounds from this block's end to pulse k
        return k


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
        n = len(x)
        at = self.n % self.size
        if at + n <= self.size:  # (the usual block: no wrap)
            self.x[at:at + n], self.ok[at:at + n] = x, ok
        else:
            first = self.size - at
            self.x[at:], self.ok[at:] = x[:first], ok[:first]
            self.x[:n - first], self.ok[:n - first] = x[first:], ok[first:]
        self.n += n

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
        while self.done < upto:
            lo = self.done
            hi = min(upto, lo + 8192)
            env = self._correlate(lo, hi, code)
            a = lo % self.size
            first = min(len(env), self.size - a)
            self.env[a:a + first] = env[:first]
            self.env[:len(env) - first] = env[first:]
            self.done = hi
            if self._searching:
                self._cells(lo, hi)

    def _correlate(self, lo: int, hi: int, code: int | None) -> np.ndarray:
        """The envelope at lags ``lo`` to ``hi`` from the samples held (not stored)."""
        m = self.m
        seg = self.samples(lo - GUARD, hi + m + GUARD - 1) if lo >= GUARD else \
            np.r_[np.zeros(GUARD - lo, np.float32), self.samples(0, hi + m + GUARD - 1)]
        need = len(seg) + m + GUARD
        nfft = 1 << (need - 1).bit_length()  # a power of two or three quarters of one: few sizes, their kernels kept
        nfft = 3 * nfft // 4 if 3 * nfft // 4 >= need else nfft
        kernel = self._kernels.get((nfft, code))
        if kernel is None:
            sound = sum(self.probes) if code is None else self.probes[code]
            kernel = self._kernels[(nfft, code)] = analytic_filter(sound, nfft).astype(np.complex64)
        return correlate(seg, kernel, nfft, GUARD, hi - lo)

    def scan(self, lo: int, hi: int, code: int) -> tuple[int, np.ndarray]:
        """The envelope for one code at lags ``lo`` to ``hi``, computed afresh from the samples
        held, whatever was computed there before (the lock's look for its direct sound after a
        step); clipped to the lags the samples held allow.

        Parameters
        ----------
        lo, hi : int
        code : int

        Returns
        -------
        (int, numpy.ndarray)
            The first lag given, and the envelope from it (empty where none can be).
        """
        lo, hi = max(lo, self.n - self.size + GUARD, 0), min(hi, self.ready())
        return lo, (self._correlate(lo, hi, code) if hi > lo else np.zeros(0, np.float32))

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


def channel0(a: np.ndarray, name: str) -> np.ndarray:
    """Channel 0 of an audio block (frames,) or (frames, channels) of floats or PCM integers.

    Parameters
    ----------
    a : numpy.ndarray
        The block.
    name : str
        Its name, which errors give ("mic", "speaker").

    Returns
    -------
    numpy.ndarray [shape=(frames,)]
        A view of channel 0, of ``a``'s dtype.

    Raises
    ------
    VrechoError
        Naming ``name``, for another shape (0-d, no channel, more dimensions) or dtype (bool,
        complex, strings, objects).
    """
    if a.ndim not in (1, 2) or (a.ndim == 2 and a.shape[1] == 0) or a.dtype.kind not in "fiu":
        raise VrechoError(f"{name}: expected a block (frames,) or (frames, channels) of floats or PCM integers "
                          f"(sounddevice's float32, int32, int16, int8, uint8), got shape {a.shape} ({a.dtype})")
    return a[:, 0] if a.ndim == 2 else a


def pcm_scale(dtype: np.dtype) -> tuple[float, float]:
    """The zero and the full scale of integer samples, ``x = zero + scale * value`` for a value
    in [-1, 1] (PCM: uint8 centred on 128).

    Parameters
    ----------
    dtype : numpy.dtype
        An integer dtype.

    Returns
    -------
    zero, scale : float
    """
    info = np.iinfo(dtype)
    return (0.0, -float(info.min)) if info.min < 0 else ((info.max + 1) / 2, (info.max + 1) / 2)
