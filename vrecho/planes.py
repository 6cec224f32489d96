"""The echo of a plane whose distance is known: open or closed by physics.

A scan (or a depth camera) gives the distance from the device's loudspeaker to a surface's plane,
a few centimetres off. With the emitted sound known, the frame's impulse response
(:func:`vrecho.features.echo_response`'s deconvolution) holds the plane's echo at that distance's
delay where the surface is closed, and none where it is open: :func:`plane_echo` reads one frame
there (its features weighed by :data:`SURFACE_WEIGHTS`; :meth:`vrecho.classifier.Classifier.predict`
asks it with ``surface_m``), :func:`fuse_open` fuses such answers, and :func:`plane_walk` and
:func:`plane_open` read several frames of one plane at once: the scan's plane is off by the same
few centimetres from every pose, the poses by millimetres from each other, so the echo is where
one offset of the plane puts it in all of them.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np
import scipy.fft
import scipy.ndimage
from scipy.special import expit

from .errors import VrechoError, check_number
from .errors import check_per_frame
from .features import band_weights, check_emitted, check_frames, check_sounding, deconvolve
from .signals import FS, SPEED_OF_SOUND, hilbert_envelope, parabolic_peaks

PLANE_TOLERANCE_M = 0.05
"""How far the given distance to a surface's plane may be off (a scan's or a depth camera's
plane: a few centimetres)."""


MAX_SURFACE_M = 10.0
"""The farthest a surface's plane may be given (:func:`check_surface`)."""


def check_surface(surface_m, n: int) -> np.ndarray:
    """Distances to a surface's plane checked: finite, positive, at most 10 m; one per frame.

    Parameters
    ----------
    surface_m : float or array_like, shape (n,)
        Metres.
    n : int
        Frames.

    Returns
    -------
    numpy.ndarray, shape (n,), float64

    Raises
    ------
    VrechoError
        Naming what is wrong.
    """
    d = check_per_frame(surface_m, n, "surface_m", "distance")
    if not np.all(np.isfinite(d)) or np.any(d <= 0) or np.any(d > MAX_SURFACE_M):
        raise VrechoError(f"surface_m: expected finite distances above 0 and at most {MAX_SURFACE_M:g} m, "
                          f"got {d.tolist()}")
    return d


def check_mic_toward(mic_toward_m, n: int) -> np.ndarray:
    """The microphone's offsets toward a surface's plane checked: finite, within 0.5 m.

    Parameters
    ----------
    mic_toward_m : float or array_like, shape (n,)
        Metres, along the plane's normal (negative: behind the loudspeaker); one for every
        frame, or one per frame.
    n : int
        How many frames they are for.

    Returns
    -------
    numpy.ndarray, shape (n,), float64
        One offset per frame.

    Raises
    ------
    VrechoError
        Naming ``mic_toward_surface_m`` and what is wrong with it.
    """
    a = check_per_frame(mic_toward_m, n, "mic_toward_surface_m", "offset")
    if not np.all(np.isfinite(a)) or np.any(np.abs(a) > 0.5):
        raise VrechoError(f"mic_toward_surface_m: expected finite offsets within 0.5 m, got {a.tolist()}")
    return a


RING_M = 1.0
"""The echoes around a plane's delay that :func:`plane_echo` holds its echo against: this much
path on either side."""


@dataclass
class PlaneEcho:
    """The echo of a plane whose distance is known, per frame (:func:`plane_echo`).

    Attributes
    ----------
    features : numpy.ndarray, shape (B, 6), float
        In each band of :data:`PLANE_BANDS_HZ`: the strongest echo at the plane's delay (each
        weighed by how likely the plane's echo is there, :func:`_window_prior`) over the
        median of the echoes around it (:data:`RING_M` of path on either side), over the
        strongest of them, and over the direct sound with spherical spreading undone (as if
        the microphone sat on the loudspeaker), in dB of the envelope.
    depth_m : numpy.ndarray, shape (B,), float
        The distance that echo says, from the loudspeaker to the plane.
    """

    features: np.ndarray
    depth_m: np.ndarray


PLANE_BANDS_HZ = ((300.0, 15000.0), (2000.0, 15000.0))
"""The bands :func:`plane_echo` reads: what every probe and loudspeaker holds (AAC keeps to 15
kHz and 16), and where the direct sound rings least."""


def plane_echo(audio, emitted, surface_m, fs: int = FS, *, tolerance_m: float = PLANE_TOLERANCE_M,
               mic_toward_m=None) -> PlaneEcho:
    """What the impulse response holds where a plane ``surface_m`` in front of the device
    must echo.

    The direct sound's delay gives the microphone's distance from the loudspeaker, r (in any
    direction: the echo's path, loudspeaker to the plane's mirror image of it to the
    microphone, lies between 2 d - r and 2 d + r), and d is ``surface_m`` within
    ``tolerance_m``. The echo there is held against the room's other echoes at nearby delays
    in the same frame, and against the direct sound (:class:`PlaneEcho`).

    Parameters
    ----------
    audio : array_like, shape (n,) or (B, n), float
        1 s frames starting at the pulse onset, n = round(``fs``) samples.
    emitted : array_like, shape (k,) or (B, k), float
        The emitted sound at the same rate.
    surface_m : float or array_like, shape (B,)
        Distance from the loudspeaker to the plane, in metres, per frame or for all.
    fs : int
        Sample rate in Hz (resampled to 44.1 kHz).
    tolerance_m : float
        How far ``surface_m`` may be off (default :data:`PLANE_TOLERANCE_M`).
    mic_toward_m : float or array_like, shape (B,), optional
        How far the microphone sits from the loudspeaker toward the plane (along its normal,
        negative behind), per frame or for all, where the device's geometry and pose are
        known: the echo's path is then sqrt(4 d^2 - 4 d a + r^2), and the window only
        ``tolerance_m`` wide on either side of d (not also r on either side of 2 d).

    Returns
    -------
    PlaneEcho
        One row per frame.

    Raises
    ------
    VrechoError
        For frames :func:`check_frames` refuses, sounds :func:`check_emitted` refuses, or a
        ``surface_m`` :func:`check_surface` refuses.

    Examples
    --------
    The probe and a plane's echo 600 samples later (2.33 m away), asked about 2.3 m and 1.5 m:

    >>> from vrecho.signals import probe
    >>> frame = np.zeros(44_100, np.float32)
    >>> frame[:4410] += probe()
    >>> frame[600:5010] += 0.3 * probe()
    >>> e = plane_echo(np.stack([frame, frame]), probe(), [2.3, 1.5])
    >>> (e.features[:, 0] > 20).tolist(), round(float(e.depth_m[0]), 2)
    ([True, False], 2.33)
    """
    x = check_frames(audio, fs)
    x = x.reshape(-1, x.shape[-1])
    d = check_surface(surface_m, len(x))
    toward = None if mic_toward_m is None else check_mic_toward(mic_toward_m, len(x))
    return plane_echo_from_responses(deconvolve(x, check_emitted(emitted, fs, len(x))), d, tolerance_m, toward)


def plane_echo_from_responses(h: np.ndarray, d: np.ndarray, tolerance_m: float, toward: np.ndarray | None
                              ) -> PlaneEcho:
    """:func:`plane_echo` of impulse responses: for a caller that reads more of one deconvolution.

    Parameters
    ----------
    h : numpy.ndarray, shape (B, n), float
        :func:`vrecho.features.deconvolve` of checked frames: their whole responses.
    d : numpy.ndarray, shape (B,)
        Their distances to the plane, :func:`check_surface` took.
    tolerance_m : float
        How far the plane may be off.
    toward : numpy.ndarray, shape (B,), or None
        The microphone's offsets toward the plane, :func:`check_mic_toward` took.

    Returns
    -------
    PlaneEcho
    """
    c = SPEED_OF_SOUND
    features, depth = np.empty((len(d), 3 * len(PLANE_BANDS_HZ))), np.empty(len(d))
    rows = np.arange(len(d))[:, None]
    for b, env, gap, ring in _plane_envelopes(h, tolerance_m):  # every frame at once: plane_echo's loop, in arrays
        t0, r = _direct(env)
        a = None if toward is None else np.clip(toward, -r, r)
        near, far = plane_window_m(d, r, tolerance_m, a)
        centre = 2 * d if a is None else _image_path(d, a, r)
        a = np.zeros(len(d)) if a is None else a
        lo = np.maximum(np.floor(near / c * FS).astype(int), t0 + gap)
        hi = np.maximum(np.ceil(far / c * FS).astype(int), lo + 1)
        at = lo[:, None] + np.arange(int((hi - lo).max()) + 1)  # each frame's window, padded past its end
        inside = at <= hi[:, None]
        at = np.minimum(at, hi[:, None])
        weighed = np.where(inside, env[rows, at] * _window_prior(at, near, far, centre), -np.inf)
        k = np.argmax(weighed, axis=1)
        p = lo + k
        peak = weighed[rows[:, 0], k]
        path = c * parabolic_peaks(env, p) / FS
        features[:, 3 * b:3 * b + 3] = _db_over(peak, *_ring(env, lo, hi, t0, gap, ring), env[rows[:, 0], t0], path, r)
        if b == 0:
            depth[:] = _image_depth(path, a, r)
    return PlaneEcho(features, depth)


def _plane_envelopes(h: np.ndarray, tolerance_m: float):
    """For each band of :data:`PLANE_BANDS_HZ`: its index, the envelopes (B, n) of the whole
    responses ``h`` (B, 1 s) in the band as far as the farthest plane's ring, and the gap and the
    ring (in samples) that :func:`_ring` keeps around a window."""
    c = SPEED_OF_SOUND
    ring = int(np.ceil(RING_M / c * FS))
    gap = int(np.ceil(0.1 / c * FS))  # 10 cm of path kept clear between the window and the ring
    # one length for every frame, the farthest window's and its ring's, the microphone as far as
    # the direct sound's search allows (a frame's envelope must not depend on its batch)
    far = 2 * (MAX_SURFACE_M + tolerance_m) + c * DIRECT_S
    # at a length its FFTs are fast for (the default 5 cm tolerance: 2 880 samples, not 2 823 = 3 x 941) took a band's
    # Hilbert pair 0.20 -> 0.04 ms, the plane's echo of one frame 1.50 -> 1.12 ms (2026-12-07)
    n = min(scipy.fft.next_fast_len(int(np.ceil(far / c * FS)) + gap + ring + 8, real=True), FS)
    half = PLANE_KERNEL_HALF
    m = scipy.fft.next_fast_len(n + 4 * half, real=True)
    # the response's last samples, then its first: a whole second's band response is circular
    ends = np.concatenate([h[:, h.shape[-1] - half:], h[:, :n + half]], axis=-1)
    spectrum = scipy.fft.rfft(ends, m, axis=-1)
    for b in range(len(PLANE_BANDS_HZ)):  # (the responses' own precision: single for frames as predict checks them)
        y = scipy.fft.irfft(spectrum * _plane_kernel(b, m, h.dtype.char), m, axis=-1)[:, 2 * half:2 * half + n]
        yield b, hilbert_envelope(y), gap, ring


PLANE_KERNEL_HALF = 1024
"""Samples on either side of its centre that a band of :data:`PLANE_BANDS_HZ` is filtered with: the
response of :func:`~vrecho.features.band_weights` over a 1 s frame's bins falls as 1 / t^3, every
tap past these under 4.4e-7 of the peak (-127 dB), so a band's response over the first 2 880
samples takes FFTs of 7 200 points, not of the whole second (the plane's envelopes 0.5 to 0.7 -> 0.2 ms a
frame)."""


@functools.lru_cache(maxsize=8)
def _plane_kernel(b: int, m: int, dtype: str) -> np.ndarray:
    """The spectrum (``m`` points, ``dtype``'s precision) of band ``b`` of :data:`PLANE_BANDS_HZ`
    as a 1 s frame's bins weigh it (:func:`~vrecho.features.band_weights`), its taps cut to
    :data:`PLANE_KERNEL_HALF` either side of the centre, kept (read-only)."""
    taps = np.fft.irfft(band_weights(np.fft.rfftfreq(FS, 1 / FS), *PLANE_BANDS_HZ[b]), FS)
    half = PLANE_KERNEL_HALF
    k = scipy.fft.rfft(np.roll(taps, half)[:2 * half + 1].astype(dtype), m)
    k.flags.writeable = False
    return k


DIRECT_S = 0.002
"""Where :func:`plane_echo` looks for the direct sound: its envelope's peak in the response's first
2 ms (the microphone within 69 cm of the loudspeaker)."""


def _direct(env: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The direct sound's sample in each envelope of ``env`` (B, n) (its peak in the first
    :data:`DIRECT_S`) and the microphone's distance from the loudspeaker that it gives, in metres."""
    t0 = np.argmax(env[:, :int(DIRECT_S * FS)], axis=1)
    return t0, SPEED_OF_SOUND * t0 / FS


def _ring(env: np.ndarray, lo: np.ndarray, hi: np.ndarray, t0: np.ndarray, gap: int, ring: int) -> tuple:
    """The median and the strongest of the envelopes ``env`` (B, n) around each row's window ``lo``
    to ``hi`` (B,): ``ring`` samples on either side, ``gap`` away from it, none within ``gap`` of
    the direct sound ``t0`` (B,) nor past the envelope's end."""
    rows = np.arange(len(env))[:, None]
    before = np.arange(ring)[None] + np.maximum(lo - gap - ring, t0 + gap)[:, None]
    after = (hi + gap)[:, None] + np.arange(ring)
    around = np.concatenate([np.where(before < np.maximum(lo - gap, t0 + gap)[:, None], env[rows, before], np.inf),
                             np.where(after < env.shape[1], env[rows, np.minimum(after, env.shape[1] - 1)], np.inf)],
                            axis=1)  # (infinity where a row's ring is cut short: left out below)
    ordered = np.sort(around, axis=1)
    count = np.isfinite(around).sum(axis=1)
    rows = rows[:, 0]
    middle = (ordered[rows, (count - 1) // 2] + ordered[rows, count // 2]) / 2  # (numpy's median: their mean)
    return middle, ordered[rows, count - 1]


def _db_over(peak, middle, top, direct, path, r) -> np.ndarray:
    """:class:`PlaneEcho`'s three features of an echo ``peak`` (arrays broadcast together, or
    floats; at the paths ``path``, metres): over the ``middle`` (median) of the echoes around it,
    over their strongest (``top``), and over the ``direct`` sound with spherical spreading undone
    (the microphone ``r`` metres from the loudspeaker), in dB; the last axis the three."""
    peak = np.asarray(peak, float)
    return 20 * np.log10(np.maximum(np.stack(
        [peak / np.maximum(np.asarray(middle, float), 1e-300), peak / np.maximum(np.asarray(top, float), 1e-300),
         peak / np.maximum(np.asarray(direct, float), 1e-300) * np.asarray(path, float) / np.maximum(r, 0.01)],
        axis=-1), 1e-300))


POSE_TOLERANCE_M = 0.005
"""How far one pose's distance to a surface's plane may be off the others' of the same scan
(:func:`plane_walk`): the plane's own error is the scan's, shared by every pose; the poses'
own, relative to each other, a few millimetres."""


@dataclass
class PlaneWalk:
    """The echo of one plane heard from several poses (:func:`plane_walk`).

    Attributes
    ----------
    features : numpy.ndarray, shape (B, D, 6), float
        :class:`PlaneEcho`'s features of each frame (B) with the plane ``offsets_m[j]`` off
        where given (D), the echo sought within ``pose_tolerance_m`` of that plane's path only.
    offsets_m : numpy.ndarray, shape (D,), float
        How far beyond where given the plane may be: ``-tolerance_m`` to ``tolerance_m`` in 1 mm
        steps.
    depth_m : numpy.ndarray, shape (B, D), float
        The distance, loudspeaker to plane, that the broad band's strongest echo within the pose's
        tolerance of each offset's path says (to a fraction of a sample).
    """

    features: np.ndarray
    offsets_m: np.ndarray
    depth_m: np.ndarray


def plane_walk(audio, emitted, surface_m, fs: int = FS, *, tolerance_m: float = PLANE_TOLERANCE_M,
               mic_toward_m=None, pose_tolerance_m: float = POSE_TOLERANCE_M) -> PlaneWalk:
    """What the impulse responses of several frames of one plane hold where it must echo, for
    each offset of the plane from where it was given.

    A scan gives each pose's distance to a plane with the plane's error (a few centimetres, the
    same for every pose) and the pose's (a few millimetres): the plane's echo is where one
    offset of the plane puts it in every frame at once, while the room's other echoes that crowd
    one frame's window (a corner of the plane's wall with the floor or the ceiling, whose path
    nears the plane's as the device steps closer but not at the same rate) seldom line up at one
    offset in all. :func:`plane_echo` looks anywhere in each frame's window alone.

    Parameters
    ----------
    audio : array_like, shape (B, n), float
        Frames of one plane, 1 s each, starting at the pulse onset.
    emitted : array_like, shape (k,) or (B, k), float
        The emitted sound at the same rate.
    surface_m : float or array_like, shape (B,)
        Each frame's distance from the loudspeaker to the plane, in metres.
    fs : int
        Sample rate in Hz (resampled to 44.1 kHz).
    tolerance_m : float
        How far the plane may be off for all the frames (default :data:`PLANE_TOLERANCE_M`).
    mic_toward_m : float or array_like, shape (B,), optional
        The microphone's offset toward the plane, per frame (as for :func:`plane_echo`); without
        it the microphone is taken to sit beside the loudspeaker (the path sqrt(4 d^2 + r^2)).
    pose_tolerance_m : float
        How far each frame's distance may be off the others' (default :data:`POSE_TOLERANCE_M`);
        at least a sample of path is looked at on either side.

    Returns
    -------
    PlaneWalk

    Raises
    ------
    VrechoError
        As :func:`plane_echo`, and for a ``pose_tolerance_m`` not within 0 to ``tolerance_m``.

    Examples
    --------
    Three frames 6 cm apart of a plane the scan puts 2 cm nearer than it is (each echo on the
    nearest whole sample: 1.5205, 1.4583 and 1.4000 m away):

    >>> from vrecho.signals import probe
    >>> frames = np.zeros((3, 44_100), np.float32)
    >>> for i, d in enumerate((1.52, 1.46, 1.40)):
    ...     frames[i, :4410] += probe()
    ...     lag = int(round(2 * d / 343.0 * 44_100))
    ...     frames[i, lag:lag + 4410] += 0.3 * probe()
    >>> w = plane_walk(frames, probe(), [1.50, 1.44, 1.38], mic_toward_m=0.0)
    >>> best = int(np.argmax(w.features[..., 0].mean(axis=0)))
    >>> [round(float(v), 3) for v in w.depth_m[:, best] - [1.50, 1.44, 1.38]]
    [0.021, 0.018, 0.02]
    """
    x = check_frames(audio, fs)
    x = x.reshape(-1, x.shape[-1])
    d = check_surface(surface_m, len(x))
    toward = None if mic_toward_m is None else check_mic_toward(mic_toward_m, len(x))
    tolerance_m, pose_tolerance_m = float(tolerance_m), float(pose_tolerance_m)
    if not (np.isfinite(pose_tolerance_m) and 0 <= pose_tolerance_m <= tolerance_m):
        raise VrechoError(f"pose_tolerance_m: expected 0 to the plane's tolerance ({tolerance_m:g} m), "
                          f"got {pose_tolerance_m!r}")
    h = deconvolve(x, check_emitted(emitted, fs, len(x)))
    c = SPEED_OF_SOUND
    offsets = np.round(np.arange(-tolerance_m, tolerance_m + 5e-4, 0.001), 6)
    w = max(1, int(round(2 * pose_tolerance_m / c * FS)))  # samples of path either side
    features = np.empty((len(x), len(offsets), 3 * len(PLANE_BANDS_HZ)))
    depth = np.empty((len(x), len(offsets)))
    for b, env, gap, ring in _plane_envelopes(h, tolerance_m):
        top = scipy.ndimage.maximum_filter1d(env, 2 * w + 1, axis=-1)
        t0, r = _direct(env)
        lo, hi = np.empty(len(env), int), np.empty(len(env), int)
        peaks, paths = np.empty((len(env), len(offsets)), env.dtype), np.empty((len(env), len(offsets)))
        for i, e in enumerate(env):
            a = 0.0 if toward is None else float(np.clip(toward[i], -r[i], r[i]))
            dd = np.maximum(d[i] + offsets, a / 2)
            paths[i] = _image_path(dd, a, r[i])  # every offset's
            at = np.clip(np.round(paths[i] / c * FS).astype(int), t0[i] + gap + w, env.shape[-1] - 2 - w)
            lo[i], hi[i] = int(at.min()) - w, int(at.max()) + w
            peaks[i] = top[i, at]
            if b == 0:  # where, near each offset's path, the echo peaks
                near = at[:, None] + np.arange(-w, w + 1)
                k = near[np.arange(len(at)), np.argmax(e[near], axis=1)]
                depth[i] = _image_depth(c * parabolic_peaks(e, k) / FS, a, r[i])
        middle, strongest = _ring(env, lo, hi, t0, gap, ring)
        direct = env[np.arange(len(env)), t0]
        features[:, :, 3 * b:3 * b + 3] = _db_over(peaks, middle[:, None], strongest[:, None], direct[:, None], paths,
                                                   r[:, None])
    return PlaneWalk(features, offsets, depth)


def _window_prior(at: np.ndarray, near: np.ndarray, far: np.ndarray, centre: np.ndarray) -> np.ndarray:
    """How likely the plane's echo is at the samples ``at`` (B, k) of each frame's window
    ``near`` to ``far`` (B,; metres of path; peak 1): a normal centred where it falls with the
    plane exactly where given (``centre``: 2 d where the microphone's direction is unknown, for
    a device's microphone sits mostly beside its loudspeaker, not ahead of it), its deviation
    half the window. A room's other echo near the window's edge then counts for less than one
    where the scan puts the plane (on the tuning frames: 83.3 -> 86.0 % in cross-validation of
    the broad band's features alone)."""
    path = SPEED_OF_SOUND * at / FS
    return np.exp(-0.5 * ((path - centre[:, None]) / np.maximum((far - near) / 2, 1e-3)[:, None]) ** 2)


def plane_window_m(d, r, tolerance_m: float = PLANE_TOLERANCE_M, mic_toward_m=None) -> tuple:
    """The nearest and farthest path, loudspeaker to microphone, of the echo of a plane ``d``
    metres away (within ``tolerance_m``), the microphone ``r`` from the loudspeaker: anywhere
    within r of 2 d, or, with the microphone ``mic_toward_m`` toward the plane (at most r
    either way), sqrt(4 d^2 - 4 d a + r^2).

    Parameters
    ----------
    d, r : float or numpy.ndarray
        Metres: one frame's, or arrays of frames' (broadcast together).
    tolerance_m : float
        Metres.
    mic_toward_m : float or numpy.ndarray, optional
        Metres, within -r to r.

    Returns
    -------
    near, far : float or numpy.ndarray
        Metres of path: where :func:`plane_echo` looks for the echo.

    Examples
    --------
    >>> [round(v, 3) for v in plane_window_m(1.0, 0.07)]
    [1.83, 2.17]
    >>> [round(v, 3) for v in plane_window_m(1.0, 0.07, mic_toward_m=0.0)]
    [1.901, 2.101]
    """
    if mic_toward_m is None:  # the microphone anywhere r away: the path lies within 2 d -+ r
        return 2 * (d - tolerance_m) - r, 2 * (d + tolerance_m) + r
    near, far = (_image_path(np.maximum(d + k * tolerance_m, np.divide(mic_toward_m, 2)), mic_toward_m, r) for k in (-1, 1))
    return (near, far) if np.ndim(near) else (float(near), float(far))


def _image_path(d, a: float, r: float):
    """The echo's path off a plane ``d`` from the loudspeaker (metres, or an array of them), the
    microphone ``r`` from it and ``a`` toward the plane: loudspeaker to its mirror image, to the
    microphone."""
    return np.sqrt(np.maximum(4 * d * d - 4 * d * a + r * r, 0.0))


def _image_depth(path, a: float, r: float):
    """:func:`_image_path` solved for the plane's distance: the distance of the plane whose echo's
    path is ``path`` (metres, or an array of them)."""
    return (a + np.sqrt(np.maximum(a * a - r * r + path * path, 0.0))) / 2


SURFACE_WEIGHTS = (-0.3942, 0.0626, 0.5264, 0.4994, -0.1106, 0.0047)
"""How :class:`~vrecho.features.PlaneEcho`'s features weigh toward closed (a logistic, with
:data:`SURFACE_BIAS`), tuned by ``python3 benchmarks/bench_surface.py --fit --frames 100`` on 900
frames of every condition of the envelope but AAC, 48 kHz and all-at-once (seeds 100 000 and up;
never the benchmark's)."""
SURFACE_BIAS = -0.1893


def fuse_open(predictions) -> float:
    """The open probability of one surface heard in several frames, each asked with its own
    ``surface_m`` (:meth:`~vrecho.classifier.Classifier.predict_batch`).

    The mean of the frames' log-odds: the echo of a surface follows the device as it moves,
    while another plane that shares its delay in one frame does not in the next, and a frame
    where the room's other echoes crowd the window is outweighed by the others. Not a sum:
    the frames of one walk share their room and device, so they are not independent
    (``benchmarks/bench_surface.py`` measures the calibration of walks of 3 and 6 frames).

    Parameters
    ----------
    predictions : sequence of Prediction
        At least one.

    Returns
    -------
    float
        Probability that the surface is open.

    Raises
    ------
    VrechoError
        For no predictions, or something that is not one.

    Examples
    --------
    >>> from vrecho.classifier import Prediction
    >>> p = Prediction(True, "glass", 1.0, {"open": 0.9}, 0.9, False, "EchoCNN-E")
    >>> q = Prediction(False, "glass", 1.0, {"open": 0.4}, 0.6, False, "EchoCNN-E")
    >>> round(fuse_open([p, q]), 2)
    0.71
    """
    try:
        p = np.array([q.probabilities["open"] for q in predictions], np.float64)
    except (TypeError, AttributeError, KeyError):
        raise VrechoError("predictions: expected EchoCNN's predictions (Classifier.predict_batch)") from None
    if not len(p):
        raise VrechoError("predictions: expected at least one")
    p = np.clip(p, 1e-9, 1 - 1e-9)
    return float(expit(np.mean(np.log(p) - np.log1p(-p))))


WALK_BIAS = 1.15
"""What :func:`plane_open` adds to a walk's mean log-odds toward closed: the echo is sought
within a few millimetres of one plane's path in each frame, not anywhere in a 5 cm window as
:data:`SURFACE_WEIGHTS` were tuned for, so its peaks read lower. Fitted (the log-odds' scale held
at 1; free, it came out 1.006) by ``python3 benchmarks/bench_surface.py --fit`` on 180 walks of
6 frames of the tuning conditions (seeds 150 000 and up; never the benchmark's), their first 3
and all 6 frames, with the device's geometry known and not."""


@dataclass
class PlaneAnswer:
    """Open or closed, one surface heard from several poses (:func:`plane_open`).

    Parameters
    ----------
    is_open : bool
        Whether the surface is an opening (``p_open`` above 0.5).
    p_open : float
        Probability that it is.
    confidence : float
        Probability of the answer.
    offset_m : float
        How far beyond the plane given its echo puts it (negative: nearer), in metres, the
        same for every frame (the median of the frames' echoes at the offset found, to a
        fraction of a sample); meaningful where the surface is closed.
    depth_m : numpy.ndarray, shape (B,)
        Each frame's distance to the plane so corrected: ``surface_m + offset_m``.
    """

    is_open: bool
    p_open: float
    confidence: float
    offset_m: float
    depth_m: np.ndarray


def plane_open(audio, fs: int, *, emitted, surface_m, mic_toward_surface_m=None,
               surface_tolerance_m: float = PLANE_TOLERANCE_M, pose_tolerance_m: float = POSE_TOLERANCE_M
               ) -> PlaneAnswer:
    """Open or closed, from several frames of one surface whose plane a scan gives: the echo
    where one offset of that plane puts it in every frame at once.

    A scan's plane is off by the same few centimetres from every pose; the poses are off from
    each other by millimetres (:func:`plane_walk`). Each frame's echo at each
    offset of the plane is weighed as :meth:`~vrecho.classifier.Classifier.predict_batch` weighs one frame's
    (:data:`SURFACE_WEIGHTS`), the frames' log-odds are averaged, the offset is taken where that
    mean, less the offset's own unlikeliness (a normal of half the tolerance, as the one frame's
    window is weighed), is highest, and :data:`WALK_BIAS` calibrates it. A corner of the plane's
    own wall with the floor or the ceiling, whose echo crowds one frame's window, nears as the
    device steps closer at another rate than the plane's and lines up in fewer frames. On the
    benchmark's walks (``benchmarks/bench_surface.py``, 240 walks of 6 frames, never tuned on),
    84.6 -> 89.6 % right against :func:`fuse_open` of the frames' answers, 87.9 -> 91.2 % with
    the device's geometry known.

    Parameters
    ----------
    audio : array_like, shape (B, n), float
        B frames of one surface (1 s, starting at the pulse onset) at ``fs`` Hz.
    fs : int
        Sample rate in Hz (resampled to 44.1 kHz).
    emitted : array_like, shape (k,) or (B, k), float
        The emitted sound, for all frames or per frame, at ``fs``.
    surface_m : float or array_like, shape (B,)
        Each frame's distance from the loudspeaker to the surface's plane, as the scan gives it.
    mic_toward_surface_m : float or array_like, shape (B,), optional
        The microphone's offset toward the plane per frame, where the device's geometry and
        pose are known (:meth:`~vrecho.classifier.Classifier.predict_batch`).
    surface_tolerance_m : float
        How far the scan's plane may be off, 1 mm to 0.5 m (default 5 cm).
    pose_tolerance_m : float
        How far a pose's distance may be off the others', 0 to ``surface_tolerance_m`` (default
        :data:`POSE_TOLERANCE_M`, 5 mm).

    Returns
    -------
    PlaneAnswer

    Raises
    ------
    VrechoError
        For no frame, a silent frame, or what :func:`plane_walk` refuses.

    Examples
    --------
    Two frames of a pane whose plane the scan puts 2 cm too near, and of an opening:

    >>> from vrecho.signals import probe
    >>> rng = np.random.default_rng(0)
    >>> pane = 1e-3 * rng.standard_normal((2, 44_100)).astype(np.float32)
    >>> opening = pane.copy()
    >>> for i, d in enumerate((1.52, 1.40)):
    ...     for f in (pane, opening):
    ...         f[i, :4410] += probe()
    ...     lag = int(round(2 * d / 343.0 * 44_100))
    ...     pane[i, lag:lag + 4410] += 0.1 * probe()
    >>> a = plane_open(pane, 44_100, emitted=probe(), surface_m=[1.50, 1.38], mic_toward_surface_m=0.0)
    >>> a.is_open, round(a.offset_m, 2)
    (False, 0.02)
    >>> plane_open(opening, 44_100, emitted=probe(), surface_m=[1.50, 1.38]).is_open
    True
    """
    x = check_frames(audio, fs)
    x = x.reshape(-1, x.shape[-1])
    if not len(x):
        raise VrechoError("audio: expected at least one frame of the surface")
    check_sounding(x)
    check_number(surface_tolerance_m, "surface_tolerance_m", lo=1e-3, hi=0.5)
    walk = plane_walk(x, check_emitted(emitted, fs, len(x)), surface_m, FS, tolerance_m=surface_tolerance_m,
                      mic_toward_m=mic_toward_surface_m, pose_tolerance_m=pose_tolerance_m)  # (both at 44.1 kHz now)
    closed = (walk.features @ np.array(SURFACE_WEIGHTS) + SURFACE_BIAS).mean(axis=0)
    closed = closed - 0.5 * (walk.offsets_m / (surface_tolerance_m / 2)) ** 2
    j = int(np.argmax(closed))
    p_open = float(expit(-(closed[j] + WALK_BIAS)))
    given = check_surface(surface_m, len(x))
    offset = float(np.median(walk.depth_m[:, j] - given))
    return PlaneAnswer(p_open > 0.5, p_open, max(p_open, 1 - p_open), offset, given + offset)
