"""Faint echoes (:class:`FaintEchoes`): a surface's echo too weak to stand out of one pulse's
envelope, found by summing the envelope along the line a surface walked toward draws over the
last pulses (track-before-detect, as radar finds dim targets).

One pulse cannot tell a wall's echo 2 to 4 times the envelope's median from the noise's own
peaks: over the 1 000 lags of 4 m some noise peak reaches that. But the wall's echo is there in
every pulse, moving at the wearer's pace; noise peaks land anywhere. Summed over eight pulses
along each approach speed, the wall's line stands some 6 standard deviations above what noise
sums to, where one pulse gave 2 or 3. Coarse first (2 cm cells, speeds 0.1 m/s apart; only
cells where the newest pulse holds a peak twice the median, which a line's echo must be), then
exactly (each pulse's own lag, interpolated, half-lag steps, speeds 0.025 m/s apart) for the
few best cells; a line five standard deviations up is a surface's (a walk's eight pulses,
relocks and damage aside: a pulse not heard within 0.6 s counts as the median, and six of eight
make a sum). A line through an echo the pulse's own finder has is left to the tracks.

What the monitor gets: the line's echo in this pulse, where it is a peak of its own (a faint
echo: it keeps a track that missed it alive, :func:`~vrecho.headset.tracks.attach_faint`), and
the line's peaks over the last pulses (a new track from them, with its history: the fits that
tell whether a surface is in the way need some eight echoes). Only approaching surfaces are
looked for (0.3 to 2.6 m/s), within 3 m; a still surface's echo (the floor, the ceiling, a wall
alongside: strong, and crossed by slow lines) is set to the median first, as are the direct
sound's sidelobes.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ..signals import SPEED_OF_SOUND
from .kernels import echo_distance, echo_path

PULSES = 8
"""Pulses summed (0.32 s at the default period)."""
_CELL_M = 0.02
_SPEEDS = np.arange(0.3, 2.6 + 1e-9, 0.1)  # approach speeds looked for, m/s
_CAP = 5.0  # no lag counts for more than 5 times the median (a stray ping, a still surface's echo)
_COARSE_K, _FINE_K = 3.0, 5.0  # the sums' thresholds: standard deviations above noise's mean
_CANDIDATES = 6  # cells verified exactly, the strongest first (not through an echo found already)
_LOCAL = 2.0  # a line's echo in one pulse: a peak at least twice the median, within a lag of the line
_MAX_RANGE_M, _MIN_RANGE_M = 3.0, 0.3
_MAX_AGE_S = 0.6  # an older pulse counts as the median everywhere (its noise's mean: no evidence)


@njit(cache=True, nogil=True)
def _line_sum(rows, lens, lags, slope, step):  # pragma: no cover (compiled)
    """The sum over the pulses of each one's envelope at ``lags + slope * step``, interpolated."""
    s = 0.0
    for j in range(rows.shape[0]):
        x = lags[j] + slope[j] * step
        i = int(np.floor(x))
        if 0 <= i and i + 1 < lens[j]:
            f = x - i
            s += (1 - f) * rows[j, i] + f * rows[j, i + 1]
    return s


@njit(cache=True, nogil=True)
def _fine(rows, lens, offsets, ago, newest, l0, l1, v0, v1, mps, spacing, forward):  # pragma: no cover (compiled)
    """The best sum over lags ``l0`` to ``l1`` of the newest pulse (whole lags, then half a lag
    either side of the best) and speeds ``v0`` to ``v1`` (9), each pulse read at its own lag,
    interpolated: (sum, lag, speed)."""
    best, best_l, best_v = -1.0, l0, v0
    pulses = rows.shape[0]
    lags = np.empty(pulses)
    slope = np.empty(pulses)
    d0 = echo_distance(mps * (l0 + offsets[newest]), spacing, forward)
    d1 = echo_distance(mps * (l1 + offsets[newest]), spacing, forward)
    for q in range(9):
        v = v0 + (v1 - v0) * q / 8
        for j in range(pulses):  # (linear in the lag over a cell's few lags)
            lags[j] = echo_path(d0 + v * ago[j], spacing, forward) / mps - offsets[j]
            slope[j] = (echo_path(d1 + v * ago[j], spacing, forward) / mps - offsets[j] - lags[j]) / max(l1 - l0, 1e-9)
        top, at = -1.0, 0.0
        for step in range(int(l1 - l0) + 1):
            s = _line_sum(rows, lens, lags, slope, float(step))
            if s > top:
                top, at = s, float(step)
        centre = at
        for step in (centre - 0.5, centre + 0.5):
            s = _line_sum(rows, lens, lags, slope, step)
            if s > top:
                top, at = s, step
        if top > best:
            best, best_l, best_v = top, l0 + at, v
    return best, best_l, best_v


@njit(cache=True, nogil=True)
def _peaks(rows, lens, offsets, ago, newest, l, v, mps, spacing, forward, local):  # pragma: no cover (compiled)
    """Along the line (lag ``l`` of the newest pulse, speed ``v``): each pulse's peak within a lag
    of it, at least ``local``: its pulse (-1: none), distance in metres and height."""
    pulses = rows.shape[0]
    which = np.full(pulses, -1, np.int64)
    dist = np.zeros(pulses)
    height = np.zeros(pulses)
    d = echo_distance(mps * (l + offsets[newest]), spacing, forward)
    for j in range(pulses):
        i = int(np.rint(echo_path(d + v * ago[j], spacing, forward) / mps - offsets[j]))
        if i - 2 < 0 or i + 2 >= lens[j]:
            continue
        p = i - 1
        for k in (i, i + 1):
            if rows[j, k] > rows[j, p]:
                p = k
        y0, y1, y2 = rows[j, p - 1], rows[j, p], rows[j, p + 1]
        if y1 < local or y1 < y0 or y1 < y2:
            continue
        den = y0 - 2 * y1 + y2
        x = p + 0.5 * (y0 - y2) / den if den < 0 else np.float64(p)
        which[j] = j
        dist[j] = echo_distance(mps * (x + offsets[j]), spacing, forward)
        height[j] = y1
    return which, dist, height


@njit(cache=True, nogil=True)
def _pulse(span, floor, peak_direct, sidelobe, lo, still, rows, cells, lens, offsets, times, stats, scale, live, k, t,
           offset, regular, cell_lo, cell_hi, speeds, mps, spacing, forward):  # pragma: no cover (compiled)
    """:meth:`FaintEchoes.add`'s work in one call: the pulse's row (its envelope over its median,
    capped; the direct sound's sidelobes, the lags before ``lo`` and a still surface's lags at most
    1) and cells, in slot ``k`` (a slot older than :data:`_MAX_AGE_S` made the median's, and not
    ``live``); then, with six live slots of eight, the lines (not through an echo found already,
    ``regular`` times the median: the monitor's tracks take those): (faint echoes found, their
    (distance, strength, speed), lines found, each line's peak count, its peaks' (time, distance,
    strength))."""
    for j in range(PULSES):
        if t - times[j] > _MAX_AGE_S:  # (pulses missed meanwhile: a relock, damage; or none yet)
            rows[j, :] = 1.0
            cells[j, :] = 1.0
            stats[j, 0], stats[j, 1], stats[j, 2], stats[j, 3] = 1.0, 0.0, 1.0, 0.0
            lens[j] = rows.shape[1]
            times[j] = t
            live[j] = False
    live[k] = True
    n = min(len(span), rows.shape[1])
    row = rows[k]
    for i in range(n):
        v = span[i] / floor
        if i < lo or (i < len(sidelobe) and span[i] <= peak_direct * sidelobe[i]):
            v = min(v, 1.0)
        row[i] = _CAP if v > _CAP else v
    for ds in still:
        a = max(int(echo_path(ds - 0.02, spacing, forward) / mps) - 1, 0)
        b = min(int(echo_path(ds + 0.02, spacing, forward) / mps) + 2, n)
        for i in range(a, b):
            row[i] = min(row[i], 1.0)
    s = s2 = 0.0
    m = 0
    for i in range(lo, n, 2):
        s += row[i]
        s2 += row[i] * row[i]
        m += 1
    stats[k, 0] = s / max(m, 1)
    stats[k, 1] = np.sqrt(max(s2 / max(m, 1) - stats[k, 0] ** 2, 0.0))
    count = cells.shape[1]
    s = s2 = 0.0
    for c in range(count):
        top = 0.0
        if cell_hi[c] <= n:
            for i in range(cell_lo[c], cell_hi[c]):
                top = max(top, row[i])
        cells[k, c] = top
        s += top
        s2 += top * top
    stats[k, 2] = s / count
    stats[k, 3] = np.sqrt(max(s2 / count - stats[k, 2] ** 2, 0.0))
    lens[k], offsets[k], times[k], scale[k] = n, offset, t, floor / peak_direct
    found = np.zeros((_CANDIDATES, 3))
    peaks = np.zeros((_CANDIDATES, PULSES, 3))
    lengths = np.zeros(_CANDIDATES, np.int64)
    if live.sum() < PULSES - 2:
        return 0, found, 0, lengths, peaks
    # Coarse: the best sum over the speeds (each pulse's cells shifted by how far the surface was
    # then) of every cell where the newest pulse may hold the line's echo (a peak of _LOCAL).
    ago = t - times
    shifts = np.empty((len(speeds), PULSES), np.int64)
    for v in range(len(speeds)):
        for j in range(PULSES):
            shifts[v, j] = int(np.rint(speeds[v] * ago[j] / _CELL_M))
    best = np.zeros(count)
    arg = np.zeros(count, np.int64)
    for c in range(count):
        if cells[k, c] < _LOCAL:
            continue
        for v in range(len(speeds)):
            total = 0.0
            for j in range(PULSES):
                if c + shifts[v, j] < count:
                    total += cells[j, c + shifts[v, j]]
            if total > best[c]:
                best[c] = total
                arg[c] = v
    mean = var = fine_mean = fine_var = 0.0
    for j in range(PULSES):
        fine_mean += stats[j, 0]
        fine_var += stats[j, 1] ** 2
        mean += stats[j, 2]
        var += stats[j, 3] ** 2
    coarse = mean + _COARSE_K * np.sqrt(var)
    fine = fine_mean + _FINE_K * np.sqrt(fine_var)
    candidates = np.zeros(count, np.int64)
    m = 0
    for c in range(1, count - 1):
        if best[c] > coarse and best[c] >= best[c - 1] and best[c] > best[c + 1]:
            candidates[m] = c
            m += 1
    candidates = candidates[:m][np.argsort(-best[candidates[:m]])]
    order = np.argsort(times)
    echoes = lines = 0
    tried = 0
    for c in candidates:
        if cells[k, c] >= regular:
            continue
        tried += 1
        if tried > _CANDIDATES:
            break
        v = speeds[arg[c]]
        total_s, lag, speed = _fine(rows, lens, offsets, ago, k, float(cell_lo[c] - 1), float(cell_hi[c] + 1),
                                    max(v - 0.1, 0.2), v + 0.1, mps, spacing, forward)
        if total_s < fine:
            continue
        which, dist, height = _peaks(rows, lens, offsets, ago, k, lag, speed, mps, spacing, forward, _LOCAL)
        p = 0
        for j in order:
            if which[j] >= 0:
                peaks[lines, p, 0], peaks[lines, p, 1], peaks[lines, p, 2] = times[j], dist[j], height[j] * scale[j]
                p += 1
        lengths[lines] = p
        lines += 1
        if which[k] >= 0:
            apart = True
            for e in range(echoes):
                apart = apart and abs(found[e, 0] - dist[k]) >= 0.03
            if apart:
                found[echoes, 0], found[echoes, 1], found[echoes, 2] = dist[k], height[k] * scale[k], speed
                echoes += 1
    return echoes, found, lines, lengths, peaks


class FaintEchoes:
    """The last :data:`PULSES` pulses' envelopes, and the faint echoes' lines through them.

    Parameters
    ----------
    fs : int
        Sample rate in Hz.
    window : int
        The longest lag after the direct sound a pulse's envelope holds, in samples.
    mic : tuple of float
        Loudspeaker to microphone: :func:`~vrecho.headset.echoes.mic_geometry`'s (spacing, forward).
    threshold : float
        The echo finder's (times the envelope's median): a line through an echo that rises above
        it in the newest pulse is left to the tracks that follow such echoes.
    """

    def __init__(self, fs: int, window: int, mic, threshold: float = 3.5):
        self.mps = SPEED_OF_SOUND / fs
        self.threshold = float(threshold)
        self.mic = mic
        count = int(round((_MAX_RANGE_M - _MIN_RANGE_M) / _CELL_M))
        edges = _MIN_RANGE_M + _CELL_M * np.arange(count + 1)
        lags = np.array([echo_path(d, *mic) / self.mps for d in edges])
        self._lo = (np.floor(lags[:-1]) - 1).astype(np.int64)
        self._hi = (np.ceil(lags[1:]) + 2).astype(np.int64)
        self._rows = np.ones((PULSES, window + 8), np.float32)
        self._cells = np.zeros((PULSES, count), np.float32)
        self._lens = np.zeros(PULSES, np.int64)
        self._offsets = np.zeros(PULSES)
        self._times = np.full(PULSES, -np.inf)
        self._stats = np.zeros((PULSES, 4))  # per pulse: the lags' mean and sd, the cells' mean and sd
        self._scale = np.ones(PULSES)  # per pulse: its floor over its direct sound's peak (heights to strengths)
        self._count = 0
        self._live = np.zeros(PULSES, bool)  # pulses heard within _MAX_AGE_S (six of eight make a sum)
        _warm()

    def add(self, t: float, span: np.ndarray, offset: float, floor: float, peak_direct: float, sidelobe: np.ndarray,
            lo: int, still) -> tuple[list, list]:
        """Take one committed pulse's envelope; the faint echoes in it and the lines through them.

        Parameters
        ----------
        t : float
            The pulse's emission, in seconds.
        span : numpy.ndarray [shape=(n,)]
            Its envelope from the direct sound's lag on.
        offset : float
            The direct sound's lag 0 less its arrival, in samples.
        floor, peak_direct : float
            The envelope's median (the echo finder's floor before its threshold) and the direct
            sound's peak.
        sidelobe : numpy.ndarray
            The direct sound's sidelobes by lag, a share of its peak (nothing there counts).
        lo : int
            The first lag looked at.
        still : list of float
            Distances in metres of surfaces that stay put (their echoes do not count).

        Returns
        -------
        echoes : list of (float, float, float)
            This pulse's faint echoes: distance in metres, strength (a share of the direct
            sound's peak) and the line's approach speed in m/s.
        lines : list of list of (float, float, float)
            Each line's peaks, oldest first: the pulse's emission in seconds, distance, strength.
        """
        k = self._count % PULSES
        self._count += 1
        echoes, found, lines, lengths, peaks = _pulse(
            span, floor, peak_direct, sidelobe, lo, np.asarray(still, float), self._rows, self._cells, self._lens,
            self._offsets, self._times, self._stats, self._scale, self._live, k, t, offset, self.threshold,
            self._lo, self._hi, _SPEEDS, self.mps, *self.mic)
        if not lines:
            return [], []
        return ([tuple(e) for e in found[:echoes].tolist()],
                [[tuple(p) for p in peaks[i, :lengths[i]].tolist()] for i in range(lines)])


_WARM = False


def _warm() -> None:
    """Compile the kernel (or load it from numba's cache) once per process, before a callback."""
    global _WARM
    if not _WARM:
        _WARM = True
        f = FaintEchoes(48000, 1400, (0.07, 0.0))
        rng = np.random.default_rng(0)  # (noise with one faint line: every branch of the kernel runs)
        for i in range(PULSES + 1):
            span = rng.rayleigh(1.0, 1400).astype(np.float32)
            span[int(echo_path(2.0 - 1.2 * 0.04 * i, *f.mic) / f.mps) + np.arange(-1, 2)] += np.float32(8.0)
            f.add(0.04 * i, span, 0.0, 1.2, 100.0, np.zeros(8), 30, [1.0])
