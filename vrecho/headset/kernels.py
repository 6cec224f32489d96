"""The headset call's per-pulse work, compiled (numba, cached on disk): the block's read
(:func:`take`), the envelope of a pulse's window (:func:`correlate`: its FFTs rocket-fft's, ducc0's
inside numba), a pulse's echoes in its envelope (:func:`echo_peaks`, their distances
:func:`echo_distance`, the inverse of :func:`echo_path`), their pairing with the tracks (:func:`pair`, strengths weighed by
:func:`amplitude_llr`, gates widened by the tracks' filters' :func:`predicted_cov`), the lines that start tracks (:func:`lines`), and the tracks' fits
(:func:`closest_approach`, :func:`passing`, :func:`theil_sen`). Plain loops over a few hundred lags or a few
dozen echoes, where a score of array calls cost more than the work; :mod:`.boundary`, :mod:`.echoes`
and :mod:`.tracks` call them and say what each means. :func:`compile_kernels` makes them (or
loads them from numba's cache) before any audio callback needs them.
"""

from __future__ import annotations

import numpy as np
from numba import njit
from scipy import fft  # (in compiled code: rocket-fft's, registered with numba when installed)

_COMPILED = False


def compile_kernels() -> None:
    """Compile the monitor's compiled kernels (numba), or load them from numba's cache, once per
    process: the audio callback must never wait for a compiler. Some 8 s the first time after an
    install (``install.sh`` does it), 0.2 s after; :class:`~vrecho.headset.BoundaryMonitor` calls it."""
    global _COMPILED
    if _COMPILED:
        return
    out = np.zeros(8, np.float32)
    for x in (np.zeros(8), np.zeros(8, np.float32), np.zeros((8, 2))[:, 0], np.zeros((8, 2), np.float32)[:, 0]):
        take(x, out, 0)  # (sounddevice's blocks: float32 or float64, channel 0 of several or one)
    correlate(np.zeros(8, np.float32), np.ones(9, np.complex64), 16, 2, 4)
    echo_peaks(np.ones(16, np.float32), 2, 3.5, 1.0, np.zeros(16), np.ones(2), 0.0, 0.007, 0.07, 0.0, 0.12, 4.0)
    closest_approach(np.arange(10.0), np.ones(10), np.array([0.6, 0.45]), 0.4)
    passing(np.arange(10.0), np.ones(10), np.array([0.5]), 0.6)
    predicted_cov(0.0, 0.0, 0.0, 0.04, 3.0)
    pair(np.ones(2), np.ones(2), np.ones((1, 8)), 1.0, 1.0, 0.01, 3.0)
    echo_path(1.0, 0.07, 0.0)  # (scalars, as the monitor calls it too)
    lines(np.ones(1), np.ones(1), np.ones(1), 0.5, -0.1, 0.1, 0.006)
    theil_sen(np.arange(3.0), np.ones(3), 0.0)
    _COMPILED = True


@njit(cache=True, nogil=True)
def take(x, out, at):  # pragma: no cover (compiled)
    """Write the samples ``x`` into ``out`` from ``at`` on as float32 (beyond its range: infinite,
    without a warning), and read all of ``out[:at + len(x)]`` in one pass.

    Parameters
    ----------
    x : numpy.ndarray [shape=(n,)]
        A block's samples, float32 or float64 (a channel of several: any stride).
    out : numpy.ndarray [shape=(>= at + n,), dtype=float32]
        Where they go.
    at : int
        Where in ``out`` they start (samples gathered before them lie before).

    Returns
    -------
    top : float
        The largest finite magnitude of ``out[:at + n]``.
    nonfinite, zeros, near : int
        How many of its samples are not finite, exactly 0, and within 1e-6 of ``top`` (a clipped
        block holds its rail).
    """
    n = at + len(x)
    for i in range(len(x)):
        out[at + i] = x[i]
    top = 0.0
    nonfinite = zeros = 0
    for i in range(n):
        v = abs(np.float64(out[i]))
        if not np.isfinite(v):
            nonfinite += 1
        elif v == 0.0:
            zeros += 1
        elif v > top:
            top = v
    near = 0
    least = top * (1 - 1e-6)
    for i in range(n):
        v = abs(np.float64(out[i]))
        if least <= v < np.inf:
            near += 1
    return top, nonfinite, zeros, near


@njit(cache=True, nogil=True)
def correlate(x, kernel, n, skip, count):  # pragma: no cover (compiled)
    """:func:`vrecho.signals.analytic_envelope` of ``x`` through ``kernel`` at lags ``skip`` to
    ``skip + count``, in one call (a pulse's window: its two FFTs cost less than the dozen array
    calls around them did).

    Parameters
    ----------
    x : numpy.ndarray [shape=(k,), dtype=float32]
        The samples, k <= ``n``.
    kernel : numpy.ndarray [shape=(n // 2 + 1,), dtype=complex64]
        :func:`vrecho.signals.analytic_filter` of the sound for ``n``.
    n : int
        FFT length.
    skip, count : int
        The lags returned.

    Returns
    -------
    numpy.ndarray [shape=(count,), dtype=float32]

    Examples
    --------
    >>> from vrecho.signals import analytic_envelope, analytic_filter
    >>> x, p = np.random.default_rng(0).standard_normal((2, 64)).astype(np.float32)
    >>> k = analytic_filter(p[:16], 128).astype(np.complex64)
    >>> bool(np.allclose(correlate(x, k, 128, 3, 40), analytic_envelope(x, k, 128)[3:43], atol=1e-5))
    True
    """
    half = fft.rfft(x, n) * kernel
    spec = np.zeros(n, half.dtype)
    spec[:half.size] = half
    z = fft.ifft(spec, overwrite_x=True)
    out = np.empty(count, np.float32)
    for i in range(count):
        out[i] = abs(z[skip + i])
    return out


@njit(cache=True, nogil=True)
def echo_path(d, spacing, forward):  # pragma: no cover (compiled)
    """The echo path's excess over the direct path, for a surface ``d`` straight ahead.

    The image of the loudspeaker lies ``2 d`` ahead; the microphone ``forward`` ahead of the
    loudspeaker and ``spacing`` from it: the path is sqrt(4 d^2 - 4 d forward + spacing^2).

    Parameters
    ----------
    d : float
        Distance to the surface's plane, metres.
    spacing, forward : float
        :func:`~vrecho.headset.echoes.mic_geometry`'s.

    Returns
    -------
    float
        Metres, the path less the direct path (``spacing``).

    Examples
    --------
    Inverted by :func:`echo_distance`:

    >>> round(float(echo_distance(echo_path(1.2, 0.05, 0.03), 0.05, 0.03)), 9)
    1.2
    """
    return np.sqrt(4 * d * d - 4 * d * forward + spacing * spacing) - spacing


@njit(cache=True, nogil=True)
def echo_distance(excess, spacing, forward):  # pragma: no cover (compiled)
    """:func:`echo_path` inverted: the distance to the surface ahead whose
    echo came ``excess`` metres of path after the direct sound (:func:`echo_peaks` uses it).

    Parameters
    ----------
    excess : float
        Metres of path after the direct sound.
    spacing, forward : float
        :func:`~vrecho.headset.echoes.mic_geometry`'s.

    Returns
    -------
    float
        Metres.
    """
    path = excess + spacing
    return 0.5 * (forward + np.sqrt(max(forward * forward - spacing * spacing + path * path, 0.0)))


@njit(cache=True, nogil=True)
def echo_peaks(span, lo, threshold, peak_direct, sidelobe, lobes, offset, metres_per_sample, spacing, forward,
            min_range_m, max_range_m):  # pragma: no cover (compiled)
    """:meth:`EchoFinder.find <vrecho.headset.echoes.EchoFinder.find>`'s core: a pulse's echoes in its
    envelope, in one pass over its few hundred lags.

    The floor is the median of every 4th lag from ``lo``; an echo is a local maximum above
    ``threshold`` times it and above the direct sound's sidelobes, and not a stronger peak's own
    sidelobe (within reach of it and no stronger, relative to it, than the codes'
    autocorrelation there); each is timed by a parabola through three lags.

    Parameters
    ----------
    span : numpy.ndarray [shape=(n,), dtype=float32]
        The envelope from the direct sound's lag on.
    lo : int
        The first lag looked at (the nearest range), in samples after the direct sound.
    threshold : float
        How far above the floor an echo rises (a factor).
    peak_direct : float
        The direct sound's envelope peak.
    sidelobe : numpy.ndarray [shape=(>= n,)]
        The direct sound's sidelobes by lag, a share of its peak.
    lobes : numpy.ndarray [shape=(reach,)]
        An echo's own sidelobes by lag, a share of its peak (``lobes[0]`` = 1).
    offset : float
        The direct sound's arrival less its lag 0, in samples.
    metres_per_sample : float
        The speed of sound over the sample rate.
    spacing, forward : float
        Loudspeaker to microphone, and its part along the wearer's way, in metres.
    min_range_m, max_range_m : float
        The distances kept.

    Returns
    -------
    d, strength : numpy.ndarray [shape=(k,)]
        Each echo's distance in metres and its peak as a share of ``peak_direct``.
    median : float
        The floor over ``threshold``: the envelope's median.
    """
    n = len(span)
    quarter = span[lo::4].astype(np.float64)
    floor = threshold * (np.partition(quarter, len(quarter) // 2)[len(quarter) // 2] + 1e-12)  # (the median: its upper one)
    at = np.empty(n, np.int64)
    count = 0
    for i in range(lo + 1, n - 1):
        v = span[i]
        if v > floor and v > span[i - 1] and v >= span[i + 1] and v > peak_direct * sidelobe[i]:
            at[count] = i
            count += 1
    reach = len(lobes)
    d = np.empty(count)
    strength = np.empty(count)
    kept = 0
    for a in range(count):
        p = at[a]
        v = np.float64(span[p])
        lobe = False
        b = a - 1
        while b >= 0 and p - at[b] < reach and not lobe:
            u = np.float64(span[at[b]])
            lobe = v < u and v <= u * lobes[p - at[b]]
            b -= 1
        b = a + 1
        while b < count and at[b] - p < reach and not lobe:
            u = np.float64(span[at[b]])
            lobe = v < u and v <= u * lobes[at[b] - p]
            b += 1
        if lobe:
            continue
        y0, y1, y2 = np.float64(span[p - 1]), v, np.float64(span[p + 1])
        den = y0 - 2.0 * y1 + y2
        x = p + 0.5 * (y0 - y2) / den if den < 0 else np.float64(p)
        excess = metres_per_sample * (x + offset)
        dist = echo_distance(excess, spacing, forward)
        if excess > 0 and min_range_m <= dist <= max_range_m:
            d[kept] = dist
            strength[kept] = v / peak_direct
            kept += 1
    return d[:kept], strength[:kept], floor / threshold


@njit(cache=True, nogil=True)
def _solve(n, s1, s2, s3, s4, b0, b1, b2):  # pragma: no cover (compiled)
    """Least squares of y on (u^2, u, 1) from its sums: (ok, p2, p1, p0, the normal matrix's
    inverse), ok False when they do not determine a parabola."""
    # The normal equations' matrix ((s4, s3, s2), (s3, s2, s1), (s2, s1, n)) is symmetric: its
    # cofactors over its determinant are its inverse.
    c00, c01, c02 = s2 * n - s1 * s1, -(s3 * n - s1 * s2), s3 * s1 - s2 * s2
    c11, c12, c22 = s4 * n - s2 * s2, -(s4 * s1 - s3 * s2), s4 * s2 - s3 * s3
    det = s4 * c00 + s3 * c01 + s2 * c02
    inv = np.empty((3, 3))
    if abs(det) < 1e-18:
        return False, 0.0, 0.0, 0.0, inv
    inv[0, 0], inv[0, 1], inv[0, 2] = c00 / det, c01 / det, c02 / det
    inv[1, 0], inv[1, 1], inv[1, 2] = inv[0, 1], c11 / det, c12 / det
    inv[2, 0], inv[2, 1], inv[2, 2] = inv[0, 2], inv[1, 2], c22 / det
    return (True, inv[0, 0] * b2 + inv[0, 1] * b1 + inv[0, 2] * b0, inv[1, 0] * b2 + inv[1, 1] * b1 + inv[1, 2] * b0,
            inv[2, 0] * b2 + inv[2, 1] * b1 + inv[2, 2] * b0, inv)


@njit(cache=True, nogil=True)
def _fit(us, ys, keep):  # pragma: no cover (compiled)
    """Least squares of y on (u^2, u, 1) over the points ``keep`` says: (ok, p2, p1, p0, inverse,
    the residuals' sum of squares, the residuals of all points)."""
    s1 = s2 = s3 = s4 = b0 = b1 = b2 = 0.0
    n = 0
    for i in range(len(us)):
        if keep[i]:
            u, y = us[i], ys[i]
            u2 = u * u
            s1 += u
            s2 += u2
            s3 += u2 * u
            s4 += u2 * u2
            b0 += y
            b1 += u * y
            b2 += u2 * y
            n += 1
    ok, p2, p1, p0, inv = _solve(float(n), s1, s2, s3, s4, b0, b1, b2)
    resid = ys - (p2 * us * us + p1 * us + p0)
    rss = 0.0
    for i in range(len(us)):
        if keep[i]:
            rss += resid[i] * resid[i]
    return ok, p2, p1, p0, inv, rss, resid


@njit(cache=True, nogil=True)
def theil_sen(t, d, accel=0.0):  # pragma: no cover (compiled)
    """How far the points (t, d) stray from the line of their median pairwise slope (Theil-Sen),
    or, with ``accel``, from the curve of a steady approach speeding up by at most that much.

    A wearer who sets off near a surface speeds up from standing to 2 m/s within half a second or
    so: over eight pulses the echoes then bend up to a centimetre off any straight line, while
    about the curve of that acceleration (d - a (t - mean t)^2 / 2 straight, a < 0: closing
    faster) they scatter a millimetre. With ``accel``, where the line leaves a millimetre or more,
    the accelerations 0 to -``accel`` in steps of :data:`ACCEL_STEP` are tried, and the curve that
    leaves the least is kept where it leaves under :data:`CURVE_M` (on seed 53000's walks, a
    curve either way and at any fit let two lines of stray peaks alert: another headset's pings
    and all at once's).

    Parameters
    ----------
    t, d : numpy.ndarray [shape=(n,)]
        Times in seconds and distances in metres, n >= 2.
    accel : float
        The largest acceleration to allow for, in m/s^2 (0: a straight line).

    Returns
    -------
    median, newest, slope : float
        The median absolute residual about that line or curve (its offset the residuals'
        median), in metres, the last point's own, and the line's slope in m/s (at the mean time).
    """
    n = len(t)
    slopes = np.empty(n * (n - 1) // 2)
    mean_t = np.mean(t)
    best_median, best_newest, best_slope = np.inf, 0.0, 0.0
    steps = int(accel / ACCEL_STEP + 1e-9)
    for s in range(steps + 1):
        a = -ACCEL_STEP * s  # (closing faster: the wearer speeding up toward the surface)
        y = d - 0.5 * a * (t - mean_t) ** 2
        k = 0
        for i in range(n):
            for j in range(i + 1, n):
                slopes[k] = (y[j] - y[i]) / max(t[j] - t[i], 1e-6)
                k += 1
        slope = np.median(slopes)
        r = y - slope * t
        r = np.abs(r - np.median(r))
        median = np.median(r)
        # (a curve only where it fits as a surface's echoes do)
        if median < best_median and (s == 0 or median < CURVE_M):
            best_median, best_newest, best_slope = median, r[-1], slope
        if s == 0 and median < 0.001:  # (on a line within a millimetre: no curve asked)
            break
    return best_median, best_newest, best_slope


CURVE_M = 0.0015
"""The most a curve :func:`theil_sen` tries may leave (its median absolute residual, metres) and
count: a surface's echoes lie within a millimetre of their curve; a line of stray peaks that one
more freedom bends toward them, at a few millimetres, is left to the straight line's reading."""

ACCEL_STEP = 0.5
"""The accelerations :func:`theil_sen` tries are this far apart, m/s^2 (over 8 pulses of some 0.3 s,
a step's curve parts from its neighbour's by under 3 mm at the ends)."""


@njit(cache=True, nogil=True)
def passing(t, d, offsets, span_s):  # pragma: no cover (compiled)
    """:meth:`Track.explained_by <vrecho.headset.tracks.Track.explained_by>`'s test: whether some
    offset's sqrt(d^2 - a^2) falls along a straight line in time with an rms residual under 0.7
    of that of d itself, over the last ``span_s``.

    Parameters
    ----------
    t, d : numpy.ndarray [shape=(n,)]
        The track's times (seconds, rising) and distances (metres).
    offsets : numpy.ndarray [shape=(k,)]
        Distances of surfaces that stay put, metres (those 2 cm nearer than the nearest echo tried).
    span_s : float
        The stretch fitted, in seconds (fewer than 8 echoes in it: False).

    Returns
    -------
    bool
    """
    first = np.searchsorted(t, t[-1] - span_s)
    if len(t) - first < 8:
        return False
    t, d = t[first:], d[first:]
    tc = t - t.mean()
    tt = (tc * tc).mean()

    def residual(x):  # mean square about its straight line in time
        xc = x - x.mean()
        return max((xc * xc).mean() - ((xc * tc).mean()) ** 2 / tt, 0.0)

    frontal = residual(d)
    nearest = d.min() - 0.02
    for a in offsets:
        if a < nearest and residual(np.sqrt(d * d - a * a)) < 0.49 * frontal:  # rms below 0.7 of it
            return True
    return False


@njit(cache=True, nogil=True)
def closest_approach(times, dists, spans, miss_m):  # pragma: no cover (compiled)
    """:meth:`Track.in_the_way <vrecho.headset.tracks.Track.in_the_way>`'s fits: d^2 as a
    quadratic in time over each span, its minimum a^2 against ``miss_m``^2 by two standard errors.

    Parameters
    ----------
    times, dists : numpy.ndarray [shape=(n,)]
        The track's times (seconds, rising) and distances (metres).
    spans : numpy.ndarray [shape=(k,)]
        The stretches of history tried in order, in seconds.
    miss_m : float
        The closest approach beyond which a surface is not in the way, in metres.

    Returns
    -------
    int
        1 in the way, 0 not, -1 cannot tell.
    """
    t_last = times[-1]
    for span_s in spans:
        first = len(times)
        while first > 0 and times[first - 1] >= t_last - span_s:
            first -= 1
        n = len(times) - first
        if n < 8 or t_last - times[first] < 0.9 * span_s:
            continue
        us = times[first:][::-1] - t_last  # (newest first)
        d = dists[first:][::-1]
        ys = d * d
        keep = np.ones(n, np.bool_)
        ok, p2, p1, p0, inv, rss, resid = _fit(us, ys, keep)
        if not ok:
            continue
        # An echo of another surface taken where two crossed in range strays from the others:
        # when the fit's residual says one may (over 4 mm rms, a residual of d^2 being some 2 d
        # times one of d), refit without the points beyond four times the residuals' median
        # spread (and 5 mm).
        if rss > 6.4e-5 * ys.sum():
            spread = 4.0 * 1.4826 * np.sort(np.abs(resid))[n // 2]
            for i in range(n):
                keep[i] = abs(resid[i]) <= max(spread, 0.01 * d[i])
            kept = keep.sum()
            if 8 <= kept < n:
                ok, p2, p1, p0, inv, rss, resid = _fit(us, ys, keep)
                if not ok:
                    continue
                n = kept
        if p2 <= 1e-3:  # not nearing at a steady pace (starting, stopping): cannot tell yet
            continue
        g0, g1 = p1 ** 2 / (4 * p2 ** 2), -p1 / (2 * p2)
        var = 0.0
        for r, gr in enumerate((g0, g1, 1.0)):
            for c, gc in enumerate((g0, g1, 1.0)):
                var += gr * inv[r, c] * gc
        var *= rss / max(n - 3, 1)
        a2 = p0 - p1 ** 2 / (4 * p2)
        sigma = max(var, 0.0) ** 0.5
        if -miss_m ** 2 < a2 - 2 * sigma and a2 + 2 * sigma < miss_m ** 2:  # far below 0 is a misfit
            return 1
        if a2 - 2 * sigma > miss_m ** 2:
            return 0
    return -1


@njit(cache=True, nogil=True)
def lines(d0, d1, d2, middle_at, least, most, tolerance_m):  # pragma: no cover (compiled)
    """:func:`~vrecho.headset.tracks.initiate`'s search: echoes of three pulses in a line.

    Parameters
    ----------
    d0, d1, d2 : numpy.ndarray
        The newest, middle and oldest pulse's echo distances, metres, sorted.
    middle_at : float
        How far along from the oldest pulse to the newest the middle one was, 0 to 1.
    least, most : float
        The newest echo's distance less the oldest's, at least and at most, metres.
    tolerance_m : float
        How far the middle echo may lie from where the other two put it, metres.

    Returns
    -------
    list of (int, int, int)
        The lines' echo indices (newest, middle, oldest), the nearest to a line first; each older
        echo in one line at most, the newest in two.
    """
    found, misses = [], []
    for a in range(len(d0)):
        for c in range(len(d2)):
            step = d0[a] - d2[c]
            if step < least or step > most:
                continue
            middle = d2[c] + step * middle_at
            b = np.searchsorted(d1, middle)
            if b == len(d1) or (b > 0 and abs(d1[b - 1] - middle) < abs(d1[b] - middle)):
                b -= 1
            miss = abs(d1[b] - middle)
            if miss < tolerance_m:
                found.append((a, b, c))
                misses.append(miss)
    out = []
    if not found:
        return out
    used0 = np.zeros(len(d0), np.int64)
    used1 = np.zeros(len(d1), np.bool_)
    used2 = np.zeros(len(d2), np.bool_)
    for k in np.argsort(np.array(misses), kind="mergesort"):
        a, b, c = found[k]
        if used0[a] >= 2 or used1[b] or used2[c]:
            continue
        used0[a] += 1
        used1[b] = True
        used2[c] = True
        out.append((a, b, c))
    return out


@njit(cache=True, nogil=True)
def amplitude_llr(strength, clutter_strength):  # pragma: no cover (compiled)
    """The evidence an echo's strength gives that it is a surface's and not a stray peak.

    Stray peaks' strengths fall off as an exponential from their mean ``m``; a surface's echo is
    as likely at any strength up to a few times that: the log-likelihood ratio is ``a / m - 1``
    (0 on average for stray peaks), bounded to [-1, 3] (one echo never decides alone).

    Parameters
    ----------
    strength : float
        The echo's peak as a share of the direct sound's.
    clutter_strength : float
        The mean of its pulse's peaks' strengths (> 0).

    Returns
    -------
    float
        Nats.

    Examples
    --------
    >>> amplitude_llr(0.02, 0.02), amplitude_llr(0.08, 0.02), amplitude_llr(0.001, 0.02)
    (0.0, 3.0, -0.95)
    """
    x = strength / clutter_strength - 1.0
    return -1.0 if x < -1.0 else 3.0 if x > 3.0 else x


@njit(cache=True, nogil=True)
def predicted_cov(pdd, pdv, pvv, dt, accel):  # pragma: no cover (compiled)
    """A track's Kalman filter of distance and speed: its covariance ``dt`` seconds after the last
    echo, the wearer's pace changing meanwhile (white acceleration ``accel``).
    :meth:`~vrecho.headset.tracks.Track.update` and :func:`pair` both reckon with it.

    Parameters
    ----------
    pdd, pdv, pvv : float
        The covariance at the last echo: m^2, m^2/s, m^2/s^2.
    dt : float
        Seconds since the last echo.
    accel : float
        The white acceleration, m/s^2.

    Returns
    -------
    pdd, pdv, pvv : float
        The covariance ``dt`` later.

    Examples
    --------
    >>> [round(v, 6) for v in predicted_cov(1e-4, 0.0, 0.01, 0.04, 3.0)]
    [0.000122, 0.000688, 0.0244]
    """
    q = accel * accel * dt * dt
    return pdd + dt * (2 * pdv + dt * pvv) + q * dt * dt / 4, pdv + dt * pvv + q * dt / 2, pvv + q


@njit(cache=True, nogil=True)
def pair(d, strength, state, t, mean, sigma_m, accel):  # pragma: no cover (compiled)
    """:func:`~vrecho.headset.tracks.associate`'s pairing: the likeliest pairs of echo and track
    within the tracks' gates first (the score's terms, :meth:`~vrecho.headset.tracks.Track.update`:
    nearness to the prediction, strength against the pulse's mean; and the track's own doubt);
    then, of the echoes left (sorted by distance), those within 3 cm of another are one surface
    (the strongest kept), and none is kept within 3 cm of a track's echo.

    Parameters
    ----------
    d, strength : numpy.ndarray [shape=(n,)]
        The echoes' distances (metres, ascending) and strengths.
    state : numpy.ndarray [shape=(k, 8)]
        Each track's filtered distance (metres), speed (m/s, 0 while unknown), last echo's time
        (seconds), filter covariance (dd, dv, vv), gate (metres) and score
        (:attr:`~vrecho.headset.tracks.Track.score`, the log odds that it is a surface's: a
        pair's cost adds the track's doubt, -log P(surface) = log(1 + exp(-score)), some 0 for a
        confirmed track and about minus its score for one its echoes speak against (a young
        track of stray peaks whose prediction a surface's echo crosses yields it)). Its gate is
        widened to 2.5 standard deviations of the filter's spread at ``t``
        (:meth:`~vrecho.headset.tracks.Track.spread`) where that is wider.
    t : float
        The echoes' pulse's emission, seconds.
    mean : float
        The pulse's peaks' mean strength (0: not weighed).
    sigma_m : float
        How far a surface's echo strays from its prediction, metres.
    accel : float
        The filter's white acceleration, m/s^2.

    Returns
    -------
    numpy.ndarray [shape=(n,), dtype=int64]
        For each echo, the track it joins, or -1 (a new surface's, kept), or -2 (left out).
    """
    k = state.shape[0]
    predicted = np.empty(k)
    gates = np.empty(k)
    doubt = np.empty(k)
    for i in range(k):
        since = t - state[i, 2]
        predicted[i] = state[i, 0] + state[i, 1] * since
        spread = predicted_cov(state[i, 3], state[i, 4], state[i, 5], max(since, 1e-3), accel)[0] + sigma_m * sigma_m
        gates[i] = max(state[i, 6], 2.5 * spread ** 0.5)
        doubt[i] = np.log1p(np.exp(-state[i, 7]))
    js, iis, costs = [], [], []
    for j in range(len(d)):
        llr = amplitude_llr(strength[j], mean) if mean > 0.0 else 0.0
        for i in range(k):
            gap = abs(d[j] - predicted[i])
            if gap < gates[i]:
                js.append(j)
                iis.append(i)
                costs.append(0.5 * (gap / sigma_m) ** 2 - llr + doubt[i])
    track_of = np.full(len(d), -1, np.int64)
    taken = np.zeros(k, np.bool_)
    for c in np.argsort(np.array(costs), kind="mergesort"):
        j, i = js[c], iis[c]
        if track_of[j] < 0 and not taken[i]:
            track_of[j] = i
            taken[i] = True
    claimed = np.sort(d[track_of >= 0])
    last = -1  # the last echo kept as a new surface's
    for j in range(len(d)):
        if track_of[j] >= 0:
            continue
        track_of[j] = -2
        c = np.searchsorted(claimed, d[j])
        if (c < len(claimed) and claimed[c] - d[j] < 0.03) or (c > 0 and d[j] - claimed[c - 1] < 0.03):
            continue
        if last >= 0 and d[j] - d[last] < 0.03:
            if strength[j] > strength[last]:
                track_of[last], track_of[j], last = -2, -1, j
            continue
        track_of[j], last = -1, j
    return track_of
