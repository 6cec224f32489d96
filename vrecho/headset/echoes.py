"""A pulse's echoes in the microphone's envelope (:class:`EchoFinder`), and the geometry that turns
an echo's delay after the direct sound into the distance of the surface ahead
(:func:`mic_geometry`; the path itself and its inverse, compiled, are
:func:`~vrecho.headset.kernels.echo_path` and :func:`~vrecho.headset.kernels.echo_distance`).
"""

from __future__ import annotations

import numpy as np
from scipy.ndimage import maximum_filter1d

from ..errors import VrechoError
from ..signals import SPEED_OF_SOUND, analytic_envelope, analytic_filter
from .kernels import echo_distance, echo_peaks
from .ranging import GUARD, Envelope, at_rail


RINGING_DB_PER_MS = 20.0
"""How fast the floor beside the direct sound falls past one code's length, in dB per
millisecond. Within that length lies what a loudspeaker's distortion of the code spreads (the
matched filter's response to a distorted copy ends there); past it only the transducers' own
ringing, which decays by 8.7 dB per time constant Q / (pi f): 0.4 ms, some 22 dB a millisecond,
for a resonance of Q 5 at 4 kHz, the codes' lowest frequency. A transducer that rang longer
would read as a still surface just beyond 0.85 m, which does not approach and so does not alert.
The floor used to fall 6 dB per doubling of the lag all the way, and hid echoes 45 to 55 dB
under a loud direct sound 1 to 1.5 m out (a loudspeaker facing away from the wearer's way, in
a quiet room)."""


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

    Attributes
    ----------
    last : tuple
        What the last :meth:`find` that got as far as the echoes read (for
        :meth:`FaintEchoes.add <vrecho.headset.faint.FaintEchoes.add>`): the envelope from the
        direct sound's lag on, that lag less the direct sound's arrival, the envelope's median,
        the direct sound's peak, its sidelobes by lag, and the first lag looked at.
    """

    def __init__(self, probes, fs: int, window: int, *, threshold: float, min_range_m: float,
                 max_range_m: float, mic_offset_m):
        self.probes, self.fs, self.window = tuple(probes), fs, window
        self.threshold, self.min_range_m, self.max_range_m = threshold, min_range_m, max_range_m
        self._mic = mic_geometry(mic_offset_m)
        self._clipped_floors: dict[tuple[int, int], np.ndarray] = {}
        self.last: tuple = ()
        # The direct sound's sidelobes by lag: 6 dB above the codes' own (the matched filter's
        # response to the code itself), and never below a floor falling from -32 dB: what a real
        # loudspeaker's distortion spreads over one code's length after its peak (the matched
        # filter's response to a distorted copy ends there), and past it the transducers' own
        # ringing, decaying by RINGING_DB_PER_MS.
        m = len(self.probes[0])
        lag = np.arange(window + m, dtype=float)
        floor = 10 ** (-(32 + 6 * np.log2(np.maximum(lag, 1) / (0.0025 * fs) + 1)
                         + RINGING_DB_PER_MS * 1000.0 * np.maximum(lag - m, 0.0) / fs) / 20)
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
        self.last = ()
        good = env.sound_until(d0 - GUARD, stop + m)
        if good < d0 + m + GUARD:
            return None  # (the direct sound must be whole: it is the reference)
        stop = min(stop, good - m - GUARD + 1)  # damage ends the window: the echoes wholly heard before it count
        lo = int(ref + 2 * self.min_range_m / SPEED_OF_SOUND * self.fs)
        if lo >= stop - 2:
            return []
        span = env.envelope(d0, stop)
        sidelobe = self._sidelobe
        if clipped:
            rail = np.count_nonzero(at_rail(env.samples(d0, d0 + m)))
            if rail >= 3:  # the direct sound clipped: its distortion rises above the sidelobes, near it
                sidelobe = self._clipped_sidelobe(rail / m, code)
        peak_direct = float(max(span[0], span[1], env.envelope(d0 - 1, d0)[0]))
        d, strength, median = echo_peaks(span, lo - d0, self.threshold, peak_direct, sidelobe, self._lobes, d0 - ref,
                                         SPEED_OF_SOUND / self.fs, *self._mic, self.min_range_m, self.max_range_m)
        self.last = (span, d0 - ref, median, peak_direct, sidelobe, lo - d0)
        return list(zip(d.tolist(), strength.tolist()))


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
    try:
        o = np.atleast_1d(np.asarray(mic_offset_m, float))
    except (ValueError, TypeError):
        raise VrechoError(f"mic_offset_m: expected metres (a number, or 3 numbers), got {mic_offset_m!r}") from None
    if o.shape not in ((1,), (3,)) or not np.all(np.isfinite(o)):
        raise VrechoError(f"mic_offset_m: expected metres, or (forward, left, up) in metres, got {mic_offset_m!r}")
    s = float(np.linalg.norm(o))
    if not 0.0 <= s <= 0.5:
        raise VrechoError(f"mic_offset_m: expected a spacing of 0 to 0.5 m, got {s:.3f} m")
    return round(s, 12), round(float(o[0]) if o.shape == (3,) else 0.0, 12)
