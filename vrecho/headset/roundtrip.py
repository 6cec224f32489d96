"""The lock on the headset's own round trip: from a pulse's start in the loudspeaker's stream to
its direct sound's arrival in the microphone's.

The monitor's own direct sound is the strongest arrival that follows the dithered emissions at
one fixed delay; the delay at which the last three pulses all have a strong arrival (the earliest
such, the direct sound before its echoes) is the round trip, once no delay heard after only two
pulses so far stands twice as strong (the direct sound, whose probe's sidelobes would otherwise
be locked on a block before it). Once locked, each pulse's direct sound is looked for near it:
small changes (clock drift) are followed, a jump seen in two pulses running is a step (an
underrun). A pulse whose direct sound is not where it is due has its arrivals within 60 ms
looked at: the same jump in two such pulses is a step of whole blocks, taken at once (some 80 ms
after it). Two pulses without it and without any such arrival (four with), or one after the
stream said it lost samples, unlock the monitor, which then searches again (three pulses and the
round trip itself: slower).
"""

from __future__ import annotations

import numpy as np

from ..signals import parabolic_peaks
from .ranging import GUARD, POOL, Envelope, ProbeSchedule

STEP_S = 0.06  # how far a step of the round trip is looked for, either way (two blocks of 1024 at 44.1 kHz and more)


class RoundTrip:
    """The lock on the monitor's own round trip: from a pulse's start in the loudspeaker's
    stream to its direct sound's arrival in the microphone's (see the module's notes).

    Parameters
    ----------
    schedule : ProbeSchedule
        The monitor's pulses.
    max_s : float
        The longest round trip searched, in seconds.
    guard : int
        Once locked, the direct sound is looked for within this many samples of where it is due.

    Attributes
    ----------
    delay : float or None
        The round trip in samples (None while not locked), filtered over the pulses.
    rate : float
        How much it changes a pulse, in samples (the clocks' drift).
    level : float
        The direct sound's envelope peak, a running estimate (0 before the first lock).
    replay : int or None
        The first pulse a step just found had hidden (its direct sound missed where it was due,
        found where the step put it; or a small step's first pulse, not trusted alone): the
        monitor hears it again; None when there is none. Each replay starts later than the one
        before (:meth:`_replay_from`): a stream the lock cannot settle on is never heard in a loop.
    searching_since : int
        The sample from which the monitor has been searching (while not locked).
    """

    def __init__(self, schedule: ProbeSchedule, max_s: float, guard: int):
        self.schedule = schedule
        self.max = int(round(max_s * schedule.fs))
        self.guard = int(guard)
        self.delay: float | None = None
        self.rate = 0.0
        self.level = 0.0
        self.searching_since = 0
        self._misses = 0  # direct sounds missed running
        self._pending: tuple[float, int] | None = None  # a jump seen once near where the direct sound was due, its pulse
        self._suspect = False  # the stream said it lost samples
        self._missed: list[int] = []  # the pulses missed since the last one followed (the last three)
        self._scans: dict[int, tuple[bool, list[float]]] = {}  # theirs: (scanned wholly, arrivals' offsets)
        self.replay: int | None = None
        self._replayed = -1  # the pulse the last replay started from

    def _forget_misses(self) -> None:
        """A fresh start for :meth:`follow`: no pulse missed, no jump pending, no loss reported."""
        self._misses, self._pending, self._suspect, self._missed, self._scans = 0, None, False, [], {}

    def _replay_from(self, j: int) -> None:
        """Pulse ``j`` to be heard again, or the first after the last replay's: replays only go on."""
        self.replay = self._replayed = max(j, self._replayed + 1)

    def _step(self, env: Envelope) -> tuple[bool, bool]:
        """After missed pulses: each one's arrivals within :data:`STEP_S` of where it was due,
        as offsets from there (strong ones: as strong as the direct sound is followed); an offset
        common to two of them, the earliest (the direct sound before its echoes), is a step of
        the round trip, taken at once, and the first of the pulses whose arrival it explains is
        to be heard again (:attr:`replay`). The other pulses' direct sounds fall at offsets that
        change with the dither, and another headset's pings with its own; the search's three
        pulses are not waited for. Returns whether a step was taken and whether any pulse had
        candidates."""
        reach = int(STEP_S * self.schedule.fs)
        for j in self._missed:
            if j in self._scans and self._scans[j][0]:
                continue  # (scanned over its whole reach already)
            due = self.due(j)
            lo, seg = env.scan(int(due) - reach, int(due) + reach, self.schedule.code(j))
            peaks = np.flatnonzero((seg[1:-1] >= 0.3 * self.level) & (seg[1:-1] > seg[:-2]) & (seg[1:-1] >= seg[2:])) + 1
            offsets = (lo + parabolic_peaks(seg, peaks) - due).tolist() if len(peaks) else []
            self._scans[j] = (lo + len(seg) >= int(due) + reach, offsets)
        common = [0.5 * (a + b) for i, j1 in enumerate(self._missed) for j2 in self._missed[i + 1:]
                  for a in self._scans[j1][1] for b in self._scans[j2][1] if abs(a - b) <= 1.5 and abs(a + b) > 3.0]
        candidates = any(self._scans[j][1] for j in self._missed)
        if not common:
            return False, candidates
        step = min(common)
        self._replay_from(min(j for j in self._missed if any(abs(o - step) <= 1.5 for o in self._scans[j][1])))
        self.delay += step
        self._forget_misses()
        return True, candidates

    def unlock(self, now: int) -> None:
        """Search again from sample ``now`` on.

        Parameters
        ----------
        now : int
        """
        if self.delay is not None:
            self.searching_since = now
        self.delay = None
        self._forget_misses()

    def suspect(self) -> None:
        """The stream said it lost samples (an underrun or overrun): one missing direct sound
        unlocks."""
        self._suspect = True

    def search(self, env: Envelope) -> bool:
        """Look for the round trip in what has arrived; lock on it when found.

        Parameters
        ----------
        env : Envelope
            The stream (its envelope computed as far as it can be).

        Returns
        -------
        bool
            Whether the monitor is now locked.
        """
        sch, pool, n_pulses = self.schedule, POOL, 3
        done = env.done
        span = self.max // pool + 2
        first = sch.first_at_or_after(max(done - env.size + 2 * GUARD + pool, 0))
        last = sch.first_at_or_after(done) - 1  # pulses whose direct sound may have arrived
        ks = list(range(max(first, last - (self.max // sch.period) - n_pulses - 1), last + 1))
        if len(ks) < n_pulses:
            return False
        starts = np.array([sch.emission(k) for k in ks])
        rows = np.zeros((len(ks), span + 1), np.float32)
        for i, e in enumerate(starts):  # pulse i's cells: cell c holds delays (e // pool + c) * pool - e on
            g0 = e // pool
            g1 = min(g0 + span + 1, done // pool)
            if g1 > g0:
                rows[i, :g1 - g0] = env.cells(g0, g1)
        coarse = np.maximum(rows[:, :-1], rows[:, 1:])  # a delay's cell is c or c + 1, by the pulse's phase
        # For each delay, the last three pulses whose arrival at that delay is in.
        avail = np.searchsorted(starts, done - (np.arange(span) + 2) * pool, side="right")
        if avail.max() < n_pulses:
            return False
        cols = np.arange(span)
        score = np.full(span, np.inf, np.float32)
        for i in range(1, n_pulses + 1):
            score = np.minimum(score, coarse[np.clip(avail - i, 0, None), cols])
        testable = avail >= n_pulses
        # A delay whose third pulse has not arrived yet, far stronger in the two that have than any
        # testable one: the direct sound, a block from testable. Waited for (the probe's sidelobes,
        # a third of its peak for some 150 samples either side, are testable a block sooner: a
        # delay that put the next pulses' windows in the direct sounds' sidelobes was locked on).
        # (Such a delay's score above is its two pulses' minimum: np.clip repeats row 0 for the third.)
        coming = float(np.where(avail == n_pulses - 1, score, 0.0).max())
        score[~testable] = 0.0
        top = float(score.max())
        if coming > 2.0 * top:
            return False
        # The direct sound stands far above the stream's envelope at the delays that can be told.
        sample = rows[:, ::7]  # (every 7th cell: the median at a fraction of the cost)
        sample = sample[sample > 0]
        floor = float(np.median(sample)) if len(sample) else 0.0
        if top <= 0 or top < 10.0 * float(np.median(score[testable])) or top < 10.0 * floor:
            return False
        j = int(np.argmax(score >= 0.3 * top))  # the earliest strong one: the direct sound, before its echoes
        while j + 1 < span and score[j + 1] > score[j]:
            j += 1
        delays, levels = [], []
        for i in range(1, n_pulses + 1):
            e = int(starts[avail[j] - i])
            a = (e // pool + max(j - 1, 0)) * pool
            seg = env.envelope(a, min((e // pool + j + 3) * pool, done))
            p = int(np.argmax(seg))
            delays.append(a + float(parabolic_peaks(seg, (p,))[0]) - e)
            levels.append(float(seg[p]))
        if max(delays) - min(delays) > 2.0 or max(levels) > 4.0 * min(levels):
            return False
        # Each pulse's own code, where its arrival is put, twice any other's: another pulse's direct
        # sound, its dithers by chance alike, plays the other code half the time (seed 34000's room 6
        # locked two pulses off by the dithers alone).
        for i in range(1, n_pulses + 1) if len(sch.probes) > 1 else ():
            own, at = sch.code(ks[avail[j] - i]), int(starts[avail[j] - i] + delays[i - 1])
            heard = [float(env.scan(at - 4, at + 5, c)[1].max(initial=0.0)) for c in range(len(sch.probes))]
            if heard[own] < 2.0 * max(h for c, h in enumerate(heard) if c != own):
                return False
        self.delay, self.level, self.rate = float(np.median(delays)), float(np.median(levels)), 0.0
        self._forget_misses()
        return True

    def due(self, k: int) -> float:
        """Where pulse ``k``'s direct sound is due, by the lock (locked only).

        Parameters
        ----------
        k : int

        Returns
        -------
        float
            The fractional sample of its arrival.
        """
        return self.schedule.emission(k) + self.delay + self.rate

    def follow(self, env: Envelope, k: int, now: int) -> float | None:
        """Pulse ``k``'s direct sound, where it is due: its arrival, and the lock followed.

        Parameters
        ----------
        env : Envelope
            The stream, its envelope computed past the direct sound's guard.
        k : int
            The pulse.
        now : int
            The samples received (for :meth:`unlock`).

        Returns
        -------
        float or None
            The direct sound's arrival (fractional sample) for the pulse's echoes to be timed
            against; None when it is not where it is due (the pulse is skipped; two such running,
            or one after :meth:`suspect`, unlock).
        """
        e = self.schedule.emission(k)
        due = self.due(k)
        a = int(due) - self.guard
        seg = env.envelope(a, int(due) + self.guard + 2)
        p = int(np.argmax(seg))
        q = int(due) - a + int(np.argmax(seg[int(due) - a - 1:int(due) - a + 3])) - 1  # (the peak where it is due)
        if abs(a + p - due) > 1.5 and abs(a + q - due) <= 1.5 and seg[q] >= 0.3 * self.level:
            p = q  # the direct sound where it is due, before a louder echo (a surface a few cm off, the mic behind)
        peak = float(seg[p])
        if peak < 0.3 * self.level:
            self._misses += 1
            end = int(due) + self.guard + env.m
            if env.sound_until(a, end) == end:  # (not a dropout's: there, nothing tells of a step)
                self._missed = self._missed[-2:] + [k]
            stepped, candidates = self._step(env)  # (the same jump in two of the pulses missed: taken)
            if not stepped and (self._misses >= 4 or (not candidates and (self._misses >= 2 or self._suspect))):
                self.unlock(now)
            return None
        at = a + float(parabolic_peaks(seg, (p,))[0])
        self._misses, self._suspect = 0, False
        self.level += 0.1 * (peak - self.level)
        step = at - due
        if abs(step) <= 1.5:  # the clocks' drift: followed (an alpha-beta filter of delay and its rate)
            self.delay += self.rate + 0.3 * step
            self.rate += 0.02 * step
            self._forget_misses()
            return e + self.delay
        if self._pending is not None and abs(step - self._pending[0]) <= 1.5:  # a step, seen twice: heard
            self.delay += step  # again from the pulse it was first seen in
            self._replay_from(self._pending[1])
            self._forget_misses()
            return at
        # Once: a small step, or another pulse's direct sound (its code the same) that a step of
        # about a period brought here. Not trusted; where this pulse's own arrival went is looked
        # for as a missed pulse's is (a step of 2048 samples at 48 kHz put the next pulse's direct
        # sound here every other pulse, and the lock lost 280 ms finding it).
        self._pending = (step, k)
        self._missed = self._missed[-2:] + [k]
        self._step(env)
        return None
