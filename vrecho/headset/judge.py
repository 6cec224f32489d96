"""The alert from the tracks (:class:`Judge`, :class:`~.boundary.BoundaryMonitor`'s base): which
surfaces are in the way, the level the gravest of them calls for, with hysteresis, and when to
judge again (step 3 of :mod:`.boundary`'s notes).

A surface is in the way when its track's fit says so (:meth:`~.tracks.Track.in_the_way`), or,
before the fit can (it needs a third of a second), when it is near, nearing fast and steadily
beyond doubt and not passing by: nearing at ``c`` as the walls behind recede at ``v``, it lies
``d sqrt(1 - (c/v)^2)`` off the way (the looming test). ``v``, the walls behind's recession, is
a lower bound of the wearer's pace (walls behind met at an angle recede slower): the pace is
*sure* (:meth:`Judge._pace_sure`) while nothing nears more than :data:`PACE_SURE` times faster.
"""

from __future__ import annotations

import numpy as np

from ..signals import SPEED_OF_SOUND
from .alert import Alert
from .kernels import echo_path
from .tracks import associate

PACE_MAX_MPS = 2.0
"""The fastest a wearer walks (the envelope's), m/s."""
PACE_SURE = 1.1
"""The pace sure: nothing nears over this many times faster than the walls behind recede
(lending, :func:`~.tracks.initiate`; a lent track's looming)."""


class Judge:
    """The alert-judging half of :class:`~.boundary.BoundaryMonitor`: its methods read the
    monitor's tracks (``_tracks``), thresholds and pace, and set its level and verdict."""

    def _pace_sure(self, behind: float) -> bool:
        """Whether nothing nears more than :data:`PACE_SURE` times faster than the walls behind
        recede, at ``behind`` m/s."""
        return self._pace <= PACE_SURE * behind

    def _echo_ends(self, k: int) -> list[float]:
        """For each surface in the way (or not yet known not to be: near the stop only) whose echo of
        pulse ``k`` may take the alert across a threshold (its distance, by the time the echo is in,
        within a pulse's walk and 5 cm of one; or its time to contact within a pulse and 50 ms of
        a caution's, ahead or aside): the lag of that echo, in samples after the direct sound."""
        out = []
        t = self.schedule.emission(k) / self.fs
        due = self._lock.due(k)
        h = self.hysteresis_m
        period_s = self.period / self.fs
        ttc_thresholds = [f * self._caution_ttc(aside) for aside in (False, True) for f in (1.0, 1.1)]
        for tr in self._tracks:
            if t - tr.approached_at <= 1.0 and (tr.ahead or (tr.ahead is None and len(tr.times) >= 7
                                                             and tr.confirmed)):
                d = tr.predict(t)  # (an undecided track: one echo more may decide it)
                closing = max(-(tr.speed or 0.0), 0.0)
                lag = echo_path(max(d, 0.0), *self._mic) / SPEED_OF_SOUND * self.fs
                d_now = d - closing * max((due + lag + self._env.m) / self.fs - t, 0.0)
                reach = closing * period_s + 0.05
                thresholds = (self.stop_m, self.stop_m + h) + ((self.caution_m, self.caution_m + h) if tr.ahead else ())
                near = any(abs(d_now - thr) < reach for thr in thresholds)
                if tr.ahead and closing > 0.05:
                    near = near or any(abs(d_now / closing - thr) < period_s + 0.05 for thr in ttc_thresholds)
                if near:
                    out.append(lag)
        return out

    def _caution_ttc(self, aside: bool) -> float:
        """The time to contact under which a surface cautions (an ``aside`` one: :data:`_ASIDE_TTC` of it)."""
        return self.caution_ttc_s * (_ASIDE_TTC if aside else 1.0)

    def _level_for(self, d: float, ttc: float, aside: bool = False) -> str:
        """The alert a surface at ``d`` m, ``ttc`` s from contact calls for, with hysteresis
        (an alert ends only ``hysteresis_m`` beyond its threshold); one ``aside`` (far off the
        wearer's way: it closes at under half the pace of the surfaces ahead) cautions by its
        time to contact only (:meth:`_caution_ttc`), not by its distance."""
        h = self.hysteresis_m
        if d < self.stop_m + (h if self._level == "stop" else 0.0):
            return "stop"
        if ((d < self.caution_m + (h if self._level != "clear" else 0.0) and not aside)
                or ttc < self._caution_ttc(aside) * (1.1 if self._level != "clear" else 1.0)):
            return "caution"
        return "clear"

    def _judge(self, partial, t_pulse: float) -> None:
        """The alert: the gravest level any surface in the way calls for (see the module's notes),
        ``partial`` the echoes so far of the pulse emitted at ``t_pulse`` (seconds)."""
        t_now = self._now / self.fs
        best = None
        provisional = {}
        if partial:  # echoes of the pulse still arriving: the alert may not wait for the window's end
            for tr, d, _ in associate(self._tracks, t_pulse, partial):
                if tr is not None and tr.confirmed:  # (a surface, not stray peaks: see _commit)
                    provisional[id(tr)] = d
        self._oldest_approach = self._judge_at = np.inf
        # The wearer's pace, at least: the fastest any surface heard for a while nears or recedes (the wall behind recedes
        # as the wall ahead nears; `behind`: receding only). A wall met at 10 degrees: aside. At most 2 m/s: a track read
        # faster took other peaks (a pitch glide, a passer-by crossing), and gives its last echoes' line (steady_speed).
        heard = [tr.steady_speed() if abs(tr.speed) > PACE_MAX_MPS else tr.speed for tr in self._tracks
                 if tr.speed is not None and tr.confirmed and len(tr.times) >= 8 and t_pulse - tr.times[-1] < 0.4]
        forgot, self._paced_at = t_now - self._paced_at, t_now  # (forgotten at 1 m/s a second; pulse times: round trip ago)
        self._pace = pace = min(max(max(map(abs, heard), default=0.0), self._pace - forgot), PACE_MAX_MPS)
        self._behind = max(max(heard, default=0.0), self._behind - forgot)
        behind = min(self._behind, PACE_MAX_MPS)
        for tr in self._tracks:
            if tr.ahead is False or (not tr.ahead and id(tr) not in provisional and (tr.speed or 0.0) > -0.5) \
                    or (self._level == "clear" and (tr.speed or 0.0) > _RECEDING_MPS) or not tr.alerting:
                continue  # (not in the way, nor asked again, nor nearing fast; not receding; beyond doubt, Track.alerting)
            v = tr.speed
            d = provisional.get(id(tr), tr.dists[-1])
            at = t_pulse if id(tr) in provisional else tr.times[-1]
            closing = -v if v is not None else 0.0
            # Where the wearer may be by now: the pulse reckoned to have left when it was written (the round trip wholly
            # on the microphone's side, the sooner of its two ends), the wearer having moved on since.
            d_now = d - max(closing, 0.0) * max(t_now - at, 0.0)
            ttc = d_now / closing if closing > 0.05 else np.inf
            aside = closing < 0.5 * pace
            if t_now - tr.approached_at <= 1.0 and (tr.ahead or (
                    id(tr) in provisional and tr.ahead_with(t_pulse, provisional[id(tr)], self.miss_m, self._still))):
                self._oldest_approach = min(self._oldest_approach, tr.approached_at)
                level = self._level_for(d_now, ttc, aside)
            elif (len(tr.times) >= (_LOOMING_LENT if tr.lent else 5) and closing >= 0.5 and at - tr.times[-5] < 0.45
                  and tr.score >= _LOOMING and (d_rt := d - closing * (self.latency_s or 0.0)) < self.caution_m and d_rt / closing < 0.75
                  and (bend := tr.straight(8))[0] < 0.005 and bend[1] < 0.03
                  and ((abs(closing - behind) <= 0.1 * behind and self._pace_sure(behind)) if tr.lent
                       else behind <= closing or d * d * (1.0 - (closing / behind) ** 2) < self.miss_m ** 2)):
                # Not yet in the way by the fit (it needs a third of a second), but near (nearer by the round trip's walk),
                # nearing fast and steadily beyond doubt (the score; the last eight echoes on a line within 5 mm, where a still
                # wall's track that took other headsets' pings bends, the newest within 3 cm: no stray peak just taken; five in
                # 0.45 s), and not passing by: nearing at c as walls behind recede at v, it lies d sqrt(1 - (c/v)^2) off the way.
                # But v may be under the pace (walls behind met at an angle): a track started on lent echoes (the stray lines and
                # passers-by those may start) needs eight echoes, c within 10 % of v, and the pace sure (PACE_SURE).
                level = "caution"
            else:
                continue  # not known to be in the way (asked again with the echo still arriving, if any)
            if closing > 0.05:  # when, walking on, it reaches a threshold it has not reached
                soon = [(d_now - thr) / closing for thr in (self.stop_m, self.caution_m) if d_now > thr]
                ttc_caution = self._caution_ttc(aside)
                soon.append(ttc - ttc_caution if ttc > ttc_caution else np.inf)
                self._judge_at = min(self._judge_at, t_now + max(min(soon), 0.0))
            if best is None or (-_RANK[level], ttc, d) < (-_RANK[best[5]], best[2], best[0]):  # gravest, then soonest
                best = (d, closing, ttc, tr, at, level)
        self._verdict_track = None if best is None else best[3]
        if best is None:
            self._level = "clear"
            moving = any(abs(tr.closed_in(0.8)) >= self.approach_m for tr in self._tracks)
            self._verdict = Alert("clear", None, "opening" if moving else None, 0.0, None, None,
                                  () if any(tr.confirmed for tr in self._tracks) else ("no_echo",))
        else:
            d, closing, ttc, tr, at, level = best
            self._level = level
            conf = min(len(tr.dists), 10) / 10 * min(1.0, sum(tr.strengths) / len(tr.strengths) * 200)
            self._verdict = Alert(level, float(d), "closed", conf, float(closing), None if np.isinf(ttc) else float(ttc),
                                  (), float(at))


_RANK = {"clear": 0, "caution": 1, "stop": 2}
_ASIDE_TTC = 0.75  # (of caution_ttc_s, for a surface aside: a wall met at under 30 degrees, grazed)
_RECEDING_MPS = 0.1  # receding faster starts no alert
_LOOMING, _LOOMING_LENT = 12.0, 8  # the score to caution before the fit (near, nearing fast); the echoes a lent track needs
