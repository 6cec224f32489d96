"""A surface the headset's echoes follow over pulses (:class:`Track`): its distance and closing
speed (a Kalman filter), whether it lies in the wearer's way (the closest point of approach,
:meth:`Track.in_the_way`) or is a second-order echo passing by (:meth:`Track.explained_by`), and
what the headset's camera made of it. :class:`~vrecho.headset.BoundaryMonitor` keeps them, and
gives each pulse's echoes to them with :func:`associate`, and starts new ones from the echoes
left over with :func:`initiate`.
"""

from __future__ import annotations

import bisect
import math
from collections import deque
from dataclasses import dataclass, field

import numpy as np

from .kernels import amplitude_llr, closest_approach, lines, pair, passing, predicted_cov, theil_sen


_SIGMA_M = 0.01
"""How far a surface's echo strays from where the surface is (head bob, the echo's peak)."""
_VAR_M = _SIGMA_M ** 2
_ACCEL = 3.0
"""How fast the wearer's pace changes, m/s^2 (the tracks' filter's white acceleration)."""
_LOG_MISS = math.log(0.4)
_LOG_QUARTER = math.log(0.25)
_LOG_YOUNG_GATE = math.log(2 * 0.12)
_FLOOR, _CEILING = -6.0, 30.0  # the score's bounds: the last half second of echoes tells (a surface's
# track that took stray peaks where other headsets' pings crowd it climbs back from -6 within some four pulses)
_SPAN_MPS = 1.0  # the closest-approach fits' spans stretched for a track nearing slower (Track.in_the_way)
_SPAN_MAX = 2.0  # ... up to so many times
_CROWD_M = 0.1  # crowding(): the peaks this near an echo tell how densely stray ones fall there
_LINE_PEAKS = 5  # a line of faint echoes starts a track with five peaks of its own (attach_faint)
_PACE_SHARE = 0.1  # a track within 10 % of the wearer's pace closes as a surface ahead does (Track.update)
_PACE_MIN_MPS = 0.3  # ... once the wearer walks
_APPROACH_MPS, _RECEDE_MPS = 2.6, 0.6  # the fastest a new track may approach and recede (initiate)
_SPEEDS_MPS = _APPROACH_MPS + _RECEDE_MPS  # ... the span of speeds a new track may have
_PACE_TOLERANCE_M = 0.012  # initiate: a line at the wearer's pace may bend this much (a fast walk's head bob)
_PACE_BAND_MPS = 0.25  # ... within so much of the pace
LEND_MPS = 0.3
"""How far from closing at the wearer's pace a track's speed lies (m/s) for its echoes to be lent
to :func:`initiate`'s lines at the pace: just beyond :data:`_PACE_BAND_MPS`, so a track at the pace
never lends its own echoes to a second one."""
CONFIRMED = math.log(100.0)
"""A track's :attr:`~Track.score` from which its echoes count as a surface's."""
ALERTING = 8.0
"""The score from which a track may raise an alert (:attr:`Track.alerting`): lines of stray peaks
among other headsets' pings stay confirmed at 5 to 7."""
SURE = 15.0
"""The score from which a track alerts on a looser line (:data:`SURE_M`), its echoes however sparse
(:attr:`Track.alerting`)."""
STRAY_M = 0.003
"""The most a track under :data:`SURE` may scatter about a line (:meth:`Track.straight`, the last
eight echoes' median) and alert: a surface's echoes, walked toward, lie on one within 1.4 mm in
99 % of the first alerts on the recorded walks (2 mm at most under :data:`SURE`); a line of
other headsets' pings that scored 9 scattered 6.3 mm."""
SURE_M = 0.006
"""The most a track of :data:`SURE`'s score and more may scatter about that line and alert: other
headsets' pings loud enough to score 16 on their strength alone, taken 0.2 to 0.4 m off in
uneven steps, scattered 18 mm."""
SPAN_S = 0.6
"""The longest a track under :data:`SURE` may take to gather its last eight echoes and alert (eight
of some fifteen pulses): a surface within reach of an alert is heard in most pulses; a line of
stray peaks taken one in three pulses is not one."""


def clutter_strength(echoes) -> float:
    """The mean strength of a pulse's peaks, or 0 where there are too few (under 4) to tell
    stray peaks' strengths by: what :func:`amplitude_llr` weighs an echo against.

    Parameters
    ----------
    echoes : list of (float, float)
        Each echo's distance in metres and strength.

    Returns
    -------
    float
        A share of the direct sound's peak, or 0.

    Examples
    --------
    >>> clutter_strength([(1.0, 0.1), (1.5, 0.2), (2.0, 0.3), (2.5, 0.2)]), clutter_strength([(1.0, 0.1)])
    (0.2, 0.0)
    """
    return sum(a for _, a in echoes) / len(echoes) if len(echoes) >= 4 else 0.0


def crowding(dists, d: float, mean_per_m: float) -> float:
    """How densely a pulse's peaks crowd the echo at ``d``: the others within :data:`_CROWD_M` of
    it per metre, or the pulse's mean density where that is higher.

    A stray peak falls near a track's prediction as often as peaks crowd that part of the pulse.
    Where another headset's ping overlaps the window, the envelope holds a comb of peaks some 3
    cm apart, and a line through it finds one within 1.5 cm on every such pulse; over the
    3.9 m looked at, the pulse's mean density understates that tenfold (seed 40000's other
    headsets, room 15: a track fed by such combs at the wearer's pace cautioned 1.7 m before an
    open door).

    Parameters
    ----------
    dists : list of float
        The pulse's peaks' distances in metres, sorted.
    d : float
        The echo's distance in metres.
    mean_per_m : float
        The pulse's peaks per metre over the range looked at.

    Returns
    -------
    float
        Peaks per metre.

    Examples
    --------
    >>> crowding([1.0, 1.03, 1.06, 1.09, 2.5], 1.03, 1.3), crowding([1.0, 2.5], 1.0, 1.3)
    (15.0, 1.3)
    """
    others = bisect.bisect_right(dists, d + _CROWD_M) - bisect.bisect_left(dists, d - _CROWD_M) - 1
    return max(others / (2 * _CROWD_M), mean_per_m)


@dataclass(slots=True)
class Track:
    """A surface the echoes follow over pulses, as :class:`~vrecho.headset.BoundaryMonitor` keeps it.

    Parameters
    ----------
    times : collections.deque of float
        When (seconds, on the stream's clock) each of its echoes' pulses was emitted; the last 64.
    dists : collections.deque of float
        Each echo's distance in metres, as measured; the last 64.
    strengths : collections.deque of float
        Each echo's matched-filter peak as a share of the direct sound's; the last 64.
    approached_at : float
        When (seconds) the surface last counted as approached; -inf until it has.
    speed : float or None
        d distance / dt in m/s (negative: approaching), the Kalman filter's; None until the
        second echo.
    ahead : bool or None
        In the wearer's way at the last update (None: cannot tell yet).
    d_hat : float
        The filtered distance in metres at the last echo.
    views : dict of str to float
        What the camera made of it: surface ("wall", "glass", "mirror") to summed confidence.
    jitter : float
        The filter's residuals' mean square, in square metres (their mean over the first five,
        then a running mean): how far its echoes stray from its prediction.
    gate_m : float
        How far from its prediction an echo may lie and still be this surface's, in metres:
        12 cm while the track is young (its speed not yet known), then five times its rms
        residual, at least 4 cm (so another headset's pings, which land elsewhere every pulse,
        seldom fall in it); :func:`associate` widens it to the filter's spread where that is
        wider.
    score : float
        The evidence that the echoes are one surface's and not stray peaks that happened near the
        prediction: the log-likelihood ratio summed over pulses (:meth:`update`, :meth:`missed`);
        :attr:`confirmed` above :data:`CONFIRMED`.
    cov : tuple of float
        The filter's covariance of distance and speed at the last echo: (m^2, m^2/s, m^2/s^2).
    lent : bool
        Started on an echo another track took (:func:`initiate`'s lending): a stray line or a
        passer-by more often than one started on echoes no track took, so the monitor asks more of
        it before it cautions ahead of the fit.
    """

    times: deque = field(default_factory=lambda: deque(maxlen=64))
    dists: deque = field(default_factory=lambda: deque(maxlen=64))
    strengths: deque = field(default_factory=lambda: deque(maxlen=64))
    approached_at: float = -np.inf
    speed: float | None = None  # d distance / dt (negative: approaching), the filter's
    ahead: bool | None = None  # in the wearer's way, at the last update (None: cannot tell yet)
    d_hat: float = 0.0
    views: dict = field(default_factory=dict)  # what the camera made of it: surface -> summed confidence
    jitter: float = 0.0025  # residuals' mean square (m^2): starts at (5 cm)^2
    gate_m: float = 0.12  # how far from its prediction an echo may lie and be this surface's
    score: float = 0.0  # log-likelihood ratio, a surface against stray peaks (see update)
    cov: tuple = (0.0, 0.0, 0.0)  # the filter's covariance of (distance, speed): dd, dv, vv
    lent: bool = False  # started on echoes another track took (initiate)

    @property
    def surface(self) -> str:
        """What the camera's views lead with ("wall", "glass", "mirror"), or "closed" if none."""
        return max(self.views, key=self.views.get) if self.views else "closed"

    def predict(self, t: float) -> float:
        """The filtered distance extrapolated to a later time.

        Parameters
        ----------
        t : float
            The time in seconds, on the stream's clock.

        Returns
        -------
        float
            ``d_hat`` moved on at ``speed`` (0 while unknown) from the last echo, in metres.
        """
        return self.d_hat + (self.speed or 0.0) * (t - self.times[-1])

    def spread(self, t: float) -> float:
        """How far a surface's echo may stray from :meth:`predict`, as the filter has it.

        Parameters
        ----------
        t : float
            The time in seconds, on the stream's clock, after the last echo.

        Returns
        -------
        float
            The variance in square metres: the echo's own (:data:`_SIGMA_M` squared) and the
            prediction's, which grows with the time since the last echo (the wearer's pace may
            change at up to :data:`_ACCEL`: :func:`~.kernels.predicted_cov`). (:func:`~.kernels.pair`
            widens the gates by the same, compiled, for every track at once.)

        Examples
        --------
        >>> tr = Track()
        >>> for t, d in ((0.0, 2.0), (0.04, 1.96), (0.08, 1.92)):
        ...     tr.update(t, d, 0.02)
        >>> bool(tr.spread(0.12) < tr.spread(0.20))
        True
        """
        return predicted_cov.py_func(*self.cov, max(t - self.times[-1], 1e-3), _ACCEL)[0] + _VAR_M

    @property
    def stray(self) -> bool:
        """Whether five echoes and more have shown the track's echoes to be stray peaks (its
        :attr:`score` at the floor): such a track would claim the peaks of a surface passing
        through its gate."""
        return self.score <= _FLOOR and len(self.times) >= 5

    @property
    def confirmed(self) -> bool:
        """Whether the echoes are a surface's beyond reasonable doubt (:attr:`score`)."""
        return self.score >= CONFIRMED

    @property
    def alerting(self) -> bool:
        """Whether the track may raise an alert: a score of :data:`ALERTING`, and from five
        echoes on, its last eight on a line within :data:`STRAY_M` (the median; :data:`SURE_M`
        from a score of :data:`SURE`), gathered within :data:`SPAN_S` under :data:`SURE`."""
        times = self.times
        if self.score < ALERTING or len(times) < 5:
            return self.score >= ALERTING
        k = min(8, len(times))
        if self.score < SURE and times[-1] - times[-k] > SPAN_S * (k - 1) / 7:
            return False
        return self.straight(8)[0] <= (SURE_M if self.score >= SURE else STRAY_M)

    def missed(self) -> None:
        """A pulse came without an echo for it: evidence against (a surface's echo is heard three
        times in five at least: a wall 2 to 3 m off, among other headsets' pings, noise and
        dropouts, is found in 60 to 70 % of pulses; four in five, as this once took, kept such
        walls' tracks from confirming for a metre)."""
        self.score = max(self.score + _LOG_MISS, _FLOOR)

    def update(self, t: float, d: float, strength: float, *, clutter_per_m: float = 1.0,
               clutter_strength: float = 0.0, pace: float = 0.0) -> None:
        """Add one echo: a Kalman filter of distance and speed, and the raw history.

        The wearer's pace changes (starting, stopping, a stride's surge) at up to some 3 m/s^2
        (:data:`_ACCEL`): the filter's prediction is that uncertain, more so for a young track
        (its speed from two or three echoes) and after missed pulses, and an echo is weighed
        against that spread, not a fixed one (a track started on a wearer speeding up, whose
        echoes came every other pulse, lost 4 cm to its prediction and was dropped as stray).
        In steady walking it is the alpha-beta filter of gains 0.6 and 0.3. The first echo sets
        the distance; the second sets the speed from the two (a fast walk's echo moves some 8 cm
        a pulse); from the third on, the filter corrects both.

        Parameters
        ----------
        t : float
            When the echo's pulse was emitted, in seconds.
        d : float
            The echo's distance in metres.
        strength : float
            The echo's peak as a share of the direct sound's.
        clutter_per_m : float
            Stray peaks per metre of range where the echo lies (the monitor gives
            :func:`crowding`'s: the pulse's peaks around it, or its mean density): the score
            weighs how near the prediction the echo fell against how likely a stray peak is to
            fall as near.
        clutter_strength : float
            The mean strength of this pulse's peaks (0: not weighed). Stray peaks' strengths
            spread about their mean as a noise's envelope peaks do (an exponential tail); a
            surface's echo standing out above them is weighed as evidence (:func:`amplitude_llr`).
        pace : float
            The wearer's pace in m/s, as the walls behind recede (0: not known; not the
            track's own, nor any surface's that nears: a person walking toward the wearer would
            be its own pace). A surface straight ahead closes at that pace; a line of stray
            peaks at any speed a track may have (:data:`_SPEEDS_MPS` wide). An echo that keeps
            a track within :data:`_PACE_SHARE` of it counts log(3.2 / (2 * 0.1 * pace)) more
            (2.4 at 1.5 m/s): where other headsets' pings, noise and a loudspeaker facing away
            leave a wall's echo 2 to 4 times the envelope's median, its track took stray peaks
            and climbed back too slowly to caution before 0.5 m (seed 5000's all at once: 68 of
            90 walks cautioned in time without it, 72 with it, :func:`initiate`'s lines at the
            pace and the score's floor at -6).
        """
        log_clutter = math.log(clutter_per_m) if clutter_per_m > 0.25 else _LOG_QUARTER  # (plain floats: per echo)
        times = self.times
        if not times:
            self.d_hat, self.speed = d, None
        else:
            dt = t - times[-1]
            if dt < 1e-3:
                dt = 1e-3
            if self.speed is None:  # the second echo: the speed from the two (a fast walk's echo moves ~8 cm a pulse)
                self.d_hat, self.speed = d, (d - self.d_hat) / dt
                self.cov = (_VAR_M, _VAR_M / dt, 2 * _VAR_M / (dt * dt))
                self.score -= _LOG_YOUNG_GATE + log_clutter  # anywhere within the young gate
            else:
                pdd, pdv, pvv = predicted_cov.py_func(*self.cov, dt, _ACCEL)  # (numba's call costs more here)
                s = pdd + _VAR_M  # the echo's spread about the prediction
                predicted = self.d_hat + self.speed * dt
                r = d - predicted
                # A surface's echo falls within that spread of the prediction; a stray peak anywhere,
                # at the pulse's density of peaks. (Bounded: the last half second tells.)
                score = self.score - 0.5 * (math.log(2 * math.pi * s) + r * r / s) - log_clutter
                if clutter_strength > 0.0:
                    score += amplitude_llr.py_func(strength, clutter_strength)  # (numba's call costs more here)
                if pace > _PACE_MIN_MPS and abs(self.speed + pace) < _PACE_SHARE * pace:
                    score += math.log(_SPEEDS_MPS / (2 * _PACE_SHARE * pace))
                self.score = _FLOOR if score < _FLOOR else _CEILING if score > _CEILING else score
                n = len(times) - 1  # residuals so far, this one included: their mean, then a running one
                self.jitter = r * r if n == 1 else self.jitter + (0.2 if n > 5 else 1.0 / n) * (r * r - self.jitter)
                kd, kv = pdd / s, pdv / s
                self.d_hat = predicted + kd * r
                self.speed += kv * r
                self.cov = ((1 - kd) * pdd, (1 - kd) * pdv, pvv - kv * pdv)
        times.append(t)
        self.dists.append(d)
        self.strengths.append(strength)
        if len(times) >= 5:
            gate = 5.0 * self.jitter ** 0.5
            self.gate_m = 0.04 if gate < 0.04 else 0.12 if gate > 0.12 else gate

    def _history(self, extra=None):
        """The track's times and distances, with one more point ``extra`` = (t, d) if given."""
        if extra is None:
            return self.times, self.dists
        return [*self.times, extra[0]], [*self.dists, extra[1]]

    def explained_by(self, offsets: list[float], *, span_s: float = 0.6, extra=None) -> bool:
        """Whether the track reads better as a second-order echo passing by than as a surface ahead.

        A wall's echo by way of the ceiling nears like a point that far overhead: for a
        second-order echo passing by at offset ``a``, sqrt(d^2 - a^2) is the one that falls
        linearly, not d. True when, over the last ``span_s``, some offset's sqrt(d^2 - a^2) has an
        rms residual about a straight line in time below 0.7 of that of d itself.

        Parameters
        ----------
        offsets : list of float
            The distances in metres of surfaces that stay put (floor, ceiling, side walls); only
            those more than 2 cm nearer than the span's nearest echo are tried.
        span_s : float
            The stretch of history fitted, in seconds (default 0.6); fewer than 8 echoes in it
            answer False.
        extra : tuple of float, optional
            One more point (t, d), seconds and metres, after the history.

        Returns
        -------
        bool
        """
        if not offsets:
            return False
        times, dists = self._history(extra)
        return passing(np.fromiter(times, float, len(times)), np.fromiter(dists, float, len(dists)),
                        np.asarray(offsets, float), float(span_s))

    def straight(self, n: int) -> tuple[float, float]:
        """How far the last ``n`` echoes stray from a straight line in time, or from the curve of an
        approach speeding up by at most :data:`_ACCEL` where that fits within
        :data:`~.kernels.CURVE_M` (a wearer setting off: :func:`~.kernels.theil_sen`): the median
        absolute residual about the line of their median pairwise slope (Theil-Sen), in metres. A
        surface's echoes, walked toward at a steady pace or speeding up: a millimetre or so,
        whatever one pulse timed off after the round trip stepped (a wearer speeding up from
        standing to 2 m/s 1.4 m from a mirror bent the line by 8 to 10 mm, and was cautioned only
        at 0.38 m before the curve: seed 53000's room 11, every row); a still surface's track that
        took a line of stray peaks: centimetres, where it bends. And the newest echo's own
        residual, which the median overlooks: a track that has just taken a stray peak 10 to 30 cm
        nearer than its surface (another headset's ping) lies on its line but for that echo.

        Parameters
        ----------
        n : int
            How many of the last echoes (all there are if fewer; at least 2).

        Returns
        -------
        median, newest : float
        """
        median, newest, _ = self._theil_sen(n, _ACCEL)
        return float(median), float(newest)

    def steady_speed(self, n: int = 16) -> float:
        """The speed the line through the last ``n`` echoes gives: their median pairwise slope
        (Theil-Sen), in m/s. The filter's speed follows a few echoes of another surface taken as
        the two cross: a wall behind's track, receding at 1.4 m/s, read 2.6 within 0.15 s,
        faster than a wearer walks (seed 5000's all at once room 2). The median holds while
        such echoes are under a quarter of the ``n``; it lags a wearer speeding up.

        Parameters
        ----------
        n : int
            The line goes through that many of the last echoes (default 16; all if fewer).

        Returns
        -------
        float
        """
        return float(self._theil_sen(n)[2])

    def _theil_sen(self, n: int, accel: float = 0.0) -> tuple:
        """:func:`~.kernels.theil_sen` of the last ``n`` echoes (all there are if fewer)."""
        k = min(n, len(self.times))
        return theil_sen(np.fromiter(self.times, float, len(self.times))[-k:],
                         np.fromiter(self.dists, float, len(self.dists))[-k:], float(accel))

    def ahead_with(self, t: float, d: float, miss_m: float, still: list[float]) -> bool:
        """Whether the surface is in the way with one more echo, the history left as it is.

        In the way: :meth:`in_the_way` says True, and it is not :meth:`explained_by` a surface
        that stays put.

        Parameters
        ----------
        t : float
            When the extra echo's pulse was emitted, in seconds.
        d : float
            The extra echo's distance in metres.
        miss_m : float
            The closest approach, in metres, beyond which the surface is not in the way.
        still : list of float
            The distances in metres of the surfaces that stay put.

        Returns
        -------
        bool
        """
        return bool(self.in_the_way(miss_m, extra=(t, d))) and not self.explained_by(still, extra=(t, d))

    def closed_in(self, span_s: float) -> float:
        """How much nearer the surface came over the last ``span_s``.

        Parameters
        ----------
        span_s : float
            The stretch of history in seconds.

        Returns
        -------
        float
            The distance in metres it closed (negative: it receded); 0 until the track spans 0.6
            of ``span_s``.
        """
        t = self.times
        if t[-1] - t[0] < 0.6 * span_s:
            return 0.0
        k = max(bisect.bisect_right(t, t[-1] - span_s) - 1, 0)
        return float(self.dists[k] - self.dists[-1])

    def in_the_way(self, miss_m: float, *, spans_s=(0.6, 0.45, 0.32), extra=None) -> bool | None:
        """Whether the wearer will pass within ``miss_m`` of the surface (closest point of approach).

        A point at lateral offset ``a`` nears as d(t)^2 = (v (t_c - t))^2 + a^2, a quadratic in t
        (fitted to the last ``span_s``) whose minimum is a^2; a surface straight ahead has a = 0.
        The longest of ``spans_s`` that tells answers (a track may have picked up another echo's
        history where the two crossed); a span the track does not reach 0.9 of, or with fewer
        than 8 echoes, or whose fit is not nearing at a steady pace, does not tell.

        What tells a point aside from a surface ahead is the curvature of its echoes' line over the
        way walked, not over the time taken: passed ``a`` off at distance ``D``, its line bends by
        some a^2 L^2 / (8 D^3) over ``L`` metres walked. A track nearing slower than
        :data:`_SPAN_MPS` has its spans stretched by :data:`_SPAN_MPS` / speed (up to
        :data:`_SPAN_MAX` times): at 0.55 m/s, 0.6 s is 0.33 m walked, over which a point passed
        0.4 m off at a metre bends its line by some 2 mm, about as much as its echoes scatter (seed
        39000's slow walks: a wall straight ahead read as passed by at 0.97 m, in the way at
        0.6 m).

        Parameters
        ----------
        miss_m : float
            The closest approach in metres beyond which the surface is not in the way.
        spans_s : tuple of float
            The stretches of history fitted, in seconds (default 0.6, 0.45 and 0.32), before the
            stretch for a slow track.
        extra : tuple of float, optional
            One more point (t, d), seconds and metres, after the history.

        Returns
        -------
        bool or None
            True when a^2 lies below miss_m^2 by two standard errors of the fit (and not far
            below 0, which no steady motion gives: above -miss_m^2), False when above by two,
            None while it cannot tell (a short track, a far surface: the minimum is then an
            extrapolation, and a head's bob hides the curvature).
        """
        times, dists = self._history(extra)
        t = np.fromiter(times, float, len(times))
        d = np.fromiter(dists, float, len(dists))
        stretch = min(max(_SPAN_MPS / abs(self.speed), 1.0), _SPAN_MAX) if self.speed else 1.0
        way = closest_approach(t, d, np.asarray(spans_s, float) * stretch, float(miss_m))
        return None if way < 0 else bool(way)


def initiate(pulses, *, tolerance_m: float = 0.006, approach_mps: float = _APPROACH_MPS,
             recede_mps: float = _RECEDE_MPS, pace: float = 0.0) -> list[Track]:
    """New tracks from the echoes no track took in the last three pulses: three, one a pulse, that
    lie on a line in time (within ``tolerance_m`` of it at the middle pulse) at a walking pace.

    One echo alone says nothing of its surface's speed: where stray peaks are dense (another
    headset's pings and their reverberation, some 30 a pulse), a track started from one echo
    took the stray peak nearest it as its second and lost the surface's, which had moved on (a
    fast walk's echo moves 8 cm a pulse). Three in a line are seldom stray (some 2 % of a
    pulse's peaks by chance where 30 crowd it; the tracks' scores weigh what is left), and they
    give the speed. The likeliest lines first (nearest the middle echo); each of the older echoes
    starts one track at most, the newest two (a stray line through it, by chance as straight,
    would take it from its surface's: the next pulse's echo tells the two apart). Lines closing
    at the wearer's pace, where it is known, are looked for first and may bend twice as much
    (:data:`_PACE_TOLERANCE_M`): a wall's echo walked toward at 1.8 m/s bent 6.5 to 7.5 mm over
    three pulses with the head's bob, and started no track for 0.4 m (seed 5000's all at once,
    room 23), while a line at one speed is some six times rarer by chance than one at any.

    A surface's echo that another track took where the two crossed in range (a line of stray peaks
    nearing at another speed, a person passing) is lent to the lines at the pace: with others'
    pings, noise and people, some 30 peaks a pulse, a wall's echoes walked toward at 1.7 m/s went
    to such tracks wherever they crossed them, and its own track started at 0.77 m (one of seed
    5000's all-at-once walks; over all 90 of them, 72 cautioned in time without the lending, 74
    with it and the monitor's gates on it, no false alarm either way in 39). Only tracks closing
    :data:`LEND_MPS` and more off the pace lend theirs; a track started on a lent echo says so
    (:attr:`Track.lent`).

    Parameters
    ----------
    pulses : sequence of tuple
        The last pulses, oldest first: (t, echoes, clutter_per_m, clutter_strength[, lent]),
        ``t`` the pulse's emission in seconds, ``echoes`` the (distance in metres, strength) pairs
        no track took, sorted by distance, the pulse's stray-peak density and mean strength
        (:meth:`Track.update`), and, optionally, ``lent``: the echoes taken by tracks closing
        :data:`LEND_MPS` or more off the pace, sorted (for the lines at the pace only). Only the
        last three are read.
    tolerance_m : float
        How far, in metres, the middle echo may lie from the line through the other two.
    approach_mps, recede_mps : float
        The fastest approach and retreat a line may have, in m/s (default 2.6 and 0.6).
    pace : float
        The wearer's pace in m/s (0: not known): lines within :data:`_PACE_BAND_MPS` of closing
        at it first, and the tracks' scores weigh it (:meth:`Track.update`).

    Returns
    -------
    list of Track
        Each with its three echoes (:meth:`Track.update`, in order); the echoes taken are
        removed from ``pulses``' lists (lent ones from ``lent``).
    """
    if len(pulses) < 3:
        return []
    (t2, e2, c2, s2, *l2), (t1, e1, c1, s1, *l1), (t0, e0, c0, s0, *l0) = pulses[-3:]
    if not t2 < t1 < t0:
        return []
    span, middle = t0 - t2, (t1 - t2) / (t0 - t2)
    chosen = []  # ((newest, middle, oldest) echoes, each (distance, strength, its list))
    if pace > _PACE_MIN_MPS:
        pools = [sorted([(d, s, e) for d, s in e] + [(d, s, l[0]) for d, s in (l[0] if l else ())], key=lambda x: x[0])
                 for e, l in ((e0, l0), (e1, l1), (e2, l2))]
        if all(pools):
            ds = [np.fromiter((x[0] for x in p), float, len(p)) for p in pools]
            found = lines(*ds, middle, -(pace + _PACE_BAND_MPS) * span, -(pace - _PACE_BAND_MPS) * span, _PACE_TOLERANCE_M)
            chosen = [(pools[0][a], pools[1][b], pools[2][c]) for a, b, c in found]
            _remove(chosen)
    if e0 and e1 and e2:  # then lines at any pace through the echoes no track took, those left
        d0, d1, d2 = (np.fromiter((d for d, _ in e), float, len(e)) for e in (e0, e1, e2))
        found = lines(d0, d1, d2, middle, -approach_mps * span, recede_mps * span, tolerance_m)
        more = [((*e0[a], e0), (*e1[b], e1), (*e2[c], e2)) for a, b, c in found]
        _remove(more)
        chosen += more
    out = []
    for line in chosen:
        tr = Track(lent=any(x[2] is not e for x, e in zip(line, (e0, e1, e2))))
        for t, (d, strength, _), clutter, mean in zip((t2, t1, t0), line[::-1], (c2, c1, c0), (s2, s1, s0)):
            tr.update(t, d, strength, clutter_per_m=clutter, clutter_strength=mean, pace=pace)
        out.append(tr)
    return out


def _remove(chosen) -> None:
    """Take the lines' echoes out of the lists they came from (a newest echo may be in two lines)."""
    for line in chosen:
        for d, strength, lst in line:
            if (d, strength) in lst:
                lst.remove((d, strength))


def associate(tracks: list, t: float, echoes) -> list[tuple[Track | None, float, float]]:
    """Each echo with a track whose prediction lies within its gate, or None (a new surface): the
    likeliest pairs first (nearest the prediction, among many peaks standing out,
    :func:`amplitude_llr`, and of a track whose echoes speak for it, :func:`pair`), so a stray
    peak beside a surface's echo (another headset's ping) seldom takes its track, nor a young
    track of stray peaks a surface's echo crossing it. The gate is :attr:`Track.gate_m`, or 2.5
    standard deviations of the filter's spread where that is wider (:meth:`Track.spread`: after
    missed pulses while the wearer speeds up, the prediction lags by more than the echoes'
    scatter set). Of the echoes left, those within 3 cm of
    another are one surface (the strongest kept), and none is kept within 3 cm of a track's echo.

    Parameters
    ----------
    tracks : list of Track
        The surfaces followed.
    t : float
        When the echoes' pulse was emitted, in seconds.
    echoes : list of (float, float)
        Each echo's distance in metres and strength (:meth:`EchoFinder.find
        <vrecho.headset.echoes.EchoFinder.find>`).

    Returns
    -------
    list of (Track or None, float, float)
        The track (None: a new surface), distance and strength of each echo kept.
    """
    if not echoes:
        return []
    echoes = sorted(echoes)
    state = np.array([(tr.d_hat, tr.speed or 0.0, tr.times[-1], *tr.cov, tr.gate_m, tr.score) for tr in tracks],
                     float).reshape(-1, 8)
    d, strength = np.array(echoes).T.copy()  # (contiguous, as the compiled kernel was made for)
    to = pair(d, strength, state, t, clutter_strength(echoes), _SIGMA_M, _ACCEL).tolist()
    return [(tracks[i], *e) for e, i in zip(echoes, to) if i >= 0] + [(None, *e) for e, i in zip(echoes, to) if i == -1]


def attach_faint(tracks: list, t: float, faint, lines, clutter_per_m: float, clutter_strength: float,
                 fresh: list, pace: float = 0.0) -> tuple[list, list]:
    """The faint echoes of a pulse (:class:`~vrecho.headset.faint.FaintEchoes`) given to the
    surfaces: a line of faint echoes no track follows starts one, with its history; a faint echo
    near (1.5 cm) a track that heard nothing this pulse, approaching at the track's speed (0.3 m/s),
    is that track's echo; one near no track joins ``fresh`` (:func:`initiate`'s).

    A new track's history is the line's peaks, but its score starts at 0 (undecided): its
    surface is believed only once its echoes keep coming (a line of noise peaks seldom goes on).

    Parameters
    ----------
    tracks : list of Track
        The surfaces followed, those that heard this pulse's echoes already updated.
    t : float
        The pulse's emission, in seconds.
    faint : list of (float, float, float)
        Its faint echoes: distance in metres, strength, and their line's approach speed in m/s.
    lines : list of list of (float, float, float)
        The lines' peaks, oldest first: emission in seconds, distance, strength.
    clutter_per_m, clutter_strength : float
        The pulse's stray peaks per metre and their mean strength (:meth:`Track.update`): a faint
        echo where other peaks crowd the pulse counts for little.
    fresh : list of (float, float)
        The pulse's echoes no track took, sorted by distance: added to in place, kept sorted.
    pace : float
        The wearer's pace in m/s (0: not known): a faint echo's track weighs it (:meth:`Track.update`).

    Returns
    -------
    born, updated : list of Track
        The tracks started, and those a faint echo updated.
    """
    born, updated = [], []
    for line in lines:
        if len(line) < _LINE_PEAKS or line[-1][0] != t:
            continue  # (a line needs five peaks of its own, the last of this pulse)
        d = line[-1][1]
        if any(abs(tr.predict(t) - d) < 0.03 for tr in tracks) or any(abs(tr.d_hat - d) < 0.03 for tr in born):
            continue
        tr = Track()
        for tj, dj, strength in line:
            tr.update(tj, dj, strength, clutter_per_m=clutter_per_m)
        tr.score = 0.0
        born.append(tr)
    for d, strength, speed in faint:
        if any(abs(tr.d_hat - d) < 0.03 for tr in born):
            continue
        best, gap = None, 0.015
        for tr in tracks:
            if tr.times[-1] != t and tr.speed is not None and abs(tr.speed + speed) < 0.3:
                g = abs(tr.predict(t) - d)
                if g < min(gap, tr.gate_m):
                    best, gap = tr, g
        if best is not None:
            best.update(t, d, strength, clutter_per_m=clutter_per_m, clutter_strength=clutter_strength, pace=pace)
            updated.append(best)
        elif all(abs(d - e) >= 0.03 for e, _ in fresh) and all(abs(tr.predict(t) - d) >= 0.03 for tr in tracks):
            bisect.insort(fresh, (d, strength))
    return born, updated

