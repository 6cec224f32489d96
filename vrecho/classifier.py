"""The classifier the rest of vrecho asks: EchoCNN with weights shipped inside the package.

``load_classifier()`` loads ``vrecho/assets/echocnn.pt`` (no download, ever); ``predict`` picks
the model for what it is given:

============================  ==============================================================
given                         model
============================  ==============================================================
audio                         EchoCNN-A (the paper's protocol: the emitted sound unknown)
audio, image                  EchoCNN-AV (concatenation)
audio, emitted                EchoCNN-E (echo features: the impulse response by deconvolution)
audio, emitted, image         EchoCNN-EV
============================  ==============================================================

Bad input never reaches torch: a frame of the wrong length, NaN or infinite samples, a silent
frame or a malformed image or emitted sound is a :class:`~vrecho.errors.VrechoError`; another
sample rate is resampled. A frame valid in form that carries no trustworthy answer is answered,
flagged, marked low-confidence and its ``confidence`` held at most :data:`FLAGGED_CONFIDENCE`
(0.5, a coin's): ``clipped`` (tested on the samples as given, before resampling),
``low_rate`` (recorded below :data:`~vrecho.features.BAND_FS`, 40 kHz: the probe's band does
not fit), ``no_pulse`` (the frame does not begin with a pulse: see :meth:`Classifier.predict_batch`)
and ``narrowband_emitted``. ``vrecho capture`` flags its frames by the same rules.
"""

from __future__ import annotations

import contextlib
import functools
import os
import threading
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path

import numpy as np
import scipy.fft
import torch
from torch.nn.utils.fusion import fuse_conv_bn_eval
from scipy.special import expit
from threadpoolctl import ThreadpoolController

from .errors import VrechoError, check_number
from .features import (SILENCE_RMS, BAND_FS, check_emitted, check_frames,  # noqa: F401 (SILENCE_RMS)
                       check_sounding, deconvolve, logmel, response_features, self_features)
from .planes import (PLANE_TOLERANCE_M, SURFACE_BIAS, SURFACE_WEIGHTS, check_mic_toward, check_surface,  # noqa: F401
                     fuse_open, plane_echo_from_responses)  # (fuse_open: its name here before vrecho.planes)
from .models import DEPTH_BINS_M, build
from .signals import FS, MIN_COHERENCE, PULSE_S, analytic_envelope, analytic_filter, check_fs, clipped, coherence

CONFIDENCE_FLOOR = 0.7
"""Below this open/closed probability an answer is marked low-confidence."""
FLAGGED_CONFIDENCE = 0.5
"""The most ``confidence`` a flagged answer gets: nothing vouches for it."""
PULSE_LAG_S = 0.01
"""How late a frame's direct sound may begin, in seconds (the loudspeaker up to 3 m away)."""
PULSE_ABOVE_TAIL_DB = 6.0
"""A frame's sound (its first 100 ms, or the emitted sound's length) must be this much louder
than the 20 ms that begin 40 ms after it ends (the room's decay by then: 9 dB and more in
EchoCNN's training frames, 20 dB in the median): steady noise, a tone or speech that goes on
is not a pulse."""
TAIL_RISE_DB = 18.0
"""After the sound and its first 40 ms of echoes, no 20 ms may rise this much above the
quietest before it, counted from :data:`TAIL_FLOOR_DB` below the sound (15 dB at most in
EchoCNN's training frames): a room's decay falls into its noise floor, and speech or music
that goes on (syllables after gaps) rises again. Sounds fainter than the floor (a door or a
voice far off) are not counted."""
TAIL_FLOOR_DB = 35.0
FLAGS = ("clipped", "low_rate", "no_pulse", "narrowband_emitted")
"""The flags an answer may carry (:class:`Prediction`)."""


@dataclass
class Prediction:
    """What EchoCNN says about the surface in front of the device.

    Parameters
    ----------
    is_open : bool
        Whether the surface is an opening (open probability above 0.5).
    material : str
        "glass" or "mirror": what a closed surface is (given for openings too).
    depth_m : float
        Emitter to the surface's plane, in metres; meaningful for closed surfaces.
    probabilities : dict of str to float
        ``open``, ``closed``, ``glass``, ``mirror``, and ``depth_<m>`` per 0.5 m class
        (``depth_0.5`` to ``depth_3``).
    confidence : float
        Probability of the open/closed answer; at most :data:`FLAGGED_CONFIDENCE` (0.5) when a
        flag is set.
    low_confidence : bool
        True when ``confidence`` is below :data:`CONFIDENCE_FLOOR` or any flag is set.
    model : str
        Which variant answered, e.g. "EchoCNN-A".
    flags : tuple of str
        Why, beyond the probability: names of :data:`FLAGS` (see the module's notes); empty by
        default.
    source_m : tuple of 3 float or None
        Where a source heard in the frame sits, forward/left/up from the device in metres, for
        frames of an ambient source; None when the emitted sound is given: the frame is then the
        device's own pulse.
    """

    is_open: bool
    material: str
    depth_m: float
    probabilities: dict[str, float]
    confidence: float
    low_confidence: bool
    model: str
    flags: tuple[str, ...] = field(default_factory=tuple)
    source_m: tuple[float, float, float] | None = None


class Classifier:
    """EchoCNN variants behind one ``predict``; see the module's docstring.

    Most users get one from :func:`load_classifier`. Each model is put in evaluation mode.

    Parameters
    ----------
    models : dict of str to torch.nn.Module
        The variants by key: "A" (audio), "AV" (audio, image), "E" (audio, emitted) and "EV"
        (audio, emitted, image), each an :class:`~vrecho.models.EchoCNN` or a module with its
        ``inputs`` and heads.
    names : dict of str to str, optional
        Names to report per key, over the defaults "EchoCNN-A" to "EchoCNN-EV".
    """

    def __init__(self, models: dict[str, torch.nn.Module], *, names: dict[str, str] | None = None):
        self.models = models
        self.names = {**_NAMES, **(names or {})}
        for m in models.values():
            m.eval()

    def predict(self, audio, fs: int, *, image=None, emitted=None, surface_m=None,
                surface_tolerance_m: float = PLANE_TOLERANCE_M, mic_toward_surface_m=None) -> Prediction:
        """What the surface in front of the device is, from one frame.

        Parameters
        ----------
        audio : array_like, shape (n,), float
            One 1 s frame (starting at the pulse onset) at ``fs`` Hz, n = round(``fs``).
        fs : int
            Sample rate in Hz (resampled to 44.1 kHz).
        image : array_like, shape (64, 25), optional
            The camera crop, uint8, or float in [0, 1].
        emitted : array_like, shape (k,), float, optional
            The emitted sound, at ``fs``.
        surface_m : float, optional
            The distance from the loudspeaker to the surface's plane, as the scan or a depth
            camera gives it (a few cm off), with ``emitted``: open/closed is then what
            physics says, the echo at that delay or none (:meth:`predict_batch`).
        surface_tolerance_m : float
            How far ``surface_m`` may be off (:meth:`predict_batch`).
        mic_toward_surface_m : float, optional
            The microphone's offset from the loudspeaker toward the surface (:meth:`predict_batch`).

        Returns
        -------
        Prediction
            The answer of the variant for what is given (see the module's docstring).

        Raises
        ------
        VrechoError
            If ``audio`` or ``emitted`` is not 1-D, or for anything :meth:`predict_batch`
            refuses.

        Examples
        --------
        >>> from vrecho.signals import probe
        >>> clf = load_classifier()
        >>> s = probe()
        >>> frame = np.zeros(44_100, np.float32)
        >>> frame[:4410] += s
        >>> frame[300:4710] += 0.5 * s
        >>> p = clf.predict(frame, 44_100, emitted=s)
        >>> p.model, p.source_m
        ('EchoCNN-E', None)
        """
        x = np.asarray(audio)
        if x.ndim != 1:
            raise VrechoError(f"audio: predict takes one 1-D frame, got shape {x.shape}; use predict_batch")
        if image is not None:
            image = np.asarray(image)[None]
        if emitted is not None:
            emitted = np.asarray(emitted)
            if emitted.ndim != 1:
                raise VrechoError(f"emitted: expected a 1-D sound, got shape {emitted.shape}")
        return self.predict_batch(x[None], fs, images=image, emitted=emitted, surface_m=surface_m,
                                  surface_tolerance_m=surface_tolerance_m, mic_toward_surface_m=mic_toward_surface_m)[0]

    def predict_batch(self, audio, fs: int, *, images=None, emitted=None, flags=None, surface_m=None,
                      surface_tolerance_m: float = PLANE_TOLERANCE_M, mic_toward_surface_m=None) -> list[Prediction]:
        """Many frames at once, each answered as by :meth:`predict`.

        Answers that nothing vouches for are flagged (low-confidence, ``confidence`` at most
        :data:`FLAGGED_CONFIDENCE`): ``clipped``, at least :data:`~vrecho.signals.CLIP_SHARE`
        of a frame's samples at full scale as given (before resampling); ``low_rate``, ``fs``
        below :data:`~vrecho.features.BAND_FS` (40 kHz); ``no_pulse``, a frame that does not
        begin with a pulse: with ``emitted``, no window within :data:`PULSE_LAG_S` of its start
        that the emitted sound explains by :data:`~vrecho.signals.MIN_COHERENCE` (its matched
        filter), and, with it or without (a sound of 100 ms then), a frame whose sound does not
        end (:data:`PULSE_ABOVE_TAIL_DB`) or whose tail rises again (:data:`TAIL_RISE_DB`):
        not a pulse and the room's decay; ``narrowband_emitted``, an emitted sound that leaves part of 200 Hz to
        16 kHz more than 40 dB below its strongest octave.

        While it runs, OpenMP (torch's operators) and BLAS are held to one thread each (a frame's arrays are
        too small to share out; two threads per pool on two cores only wait for each other),
        and the caller's settings are restored after; the frames are answered in
        equal chunks of at most :data:`CHUNK` on a thread per CPU, at most 4.

        Parameters
        ----------
        audio : array_like, shape (B, n), float
            1 s frames (starting at the pulse onset) at ``fs`` Hz, n = round(``fs``); one 1-D
            frame is taken as a batch of one.
        fs : int
            Sample rate in Hz (resampled to 44.1 kHz).
        images : array_like, shape (B, 64, 25), optional
            The camera crops, uint8, or float in [0, 1]; or None.
        emitted : array_like, shape (k,) or (B, k), float, optional
            One sound for all frames or one per frame, at ``fs``; or None.
        flags : sequence of B sequences of str, optional
            What the caller knows of each frame's origin, names of :data:`FLAGS` (a frame cut
            from a clipped or low-rate recording and resampled: ``vrecho capture``); flagged as
            those found here.
        surface_m : float or array_like, shape (B,), optional
            The distance from the loudspeaker to the surface's plane, per frame or for all
            (the scan's or a depth camera's, within :data:`~vrecho.planes.PLANE_TOLERANCE_M`),
            with ``emitted``. Open/closed then comes from the echo where that plane must echo
            (:func:`~vrecho.planes.plane_echo`: held against the room's other echoes around
            it and against the direct sound, whatever the loudspeaker's directivity or
            gain), weighed by :data:`~vrecho.planes.SURFACE_WEIGHTS`; a closed surface's depth is that
            echo's. ``model`` then ends in " + echo at surface_m".
        surface_tolerance_m : float
            How far ``surface_m`` may be off, in metres, 1 mm to 0.5 m
            (:data:`~vrecho.planes.PLANE_TOLERANCE_M`, 5 cm, by default; a scan that knows its
            planes better narrows the window, and fewer of the room's other echoes share it).
        mic_toward_surface_m : float or array_like, shape (B,), optional
            How far the microphone sits from the loudspeaker toward the surface (along the
            plane's normal; negative behind), per frame or for all, where the device's geometry
            and pose are known (a scan knows both): the echo is then looked for at its exact
            path (:func:`~vrecho.planes.plane_echo`), not anywhere within the microphone's
            distance of twice ``surface_m``. Within 0.5 m; with ``surface_m`` only.

        Returns
        -------
        list of Prediction
            One per frame, in order (none for an empty batch).

        Raises
        ------
        VrechoError
            For frames :func:`~vrecho.features.check_frames` refuses or a silent frame (RMS
            below 1e-6), emitted sounds :func:`~vrecho.features.check_emitted` refuses,
            images of another shape, or not uint8 or finite floats in [0, 1], or ``flags``
            not B sequences of names of :data:`FLAGS`.
        """
        x = check_frames(audio, fs)
        raw = np.asarray(audio)  # as given, checked: clipping is tested before resampling rings past the rail
        if x.ndim == 1:
            x, raw = x[None], raw[None]
        fs = check_fs(fs)
        given = _check_flags(flags, len(x))
        if not len(x):
            return []
        check_sounding(x)
        key, s, narrow = "A", None, None
        if emitted is not None:
            s = check_emitted(emitted, fs, len(x))
            narrow = np.broadcast_to(_narrowband_once(s.tobytes()) if s.ndim == 1 else _narrowband(s), (len(x),))
            key = "E"
        if images is not None:
            images = _check_images(images, len(x))
            key += "V"
        surface = toward = None
        if surface_m is not None:
            if emitted is None:
                raise VrechoError("surface_m: needs emitted, the sound whose echo is looked for at that distance")
            surface = check_surface(surface_m, len(x))
            check_number(surface_tolerance_m, "surface_tolerance_m", lo=1e-3, hi=0.5)
            toward = None if mic_toward_surface_m is None else check_mic_toward(mic_toward_surface_m, len(x))
        elif mic_toward_surface_m is not None:
            raise VrechoError("mic_toward_surface_m: needs surface_m, the distance it places the echo at")
        model = self.models[key]
        threads = _pool()._max_workers
        n_chunks = min(len(x), threads * -(-len(x) // (threads * CHUNK)))  # a whole number per thread
        edges = np.linspace(0, len(x), n_chunks + 1).round().astype(int)
        chunks = [slice(a, b) for a, b in zip(edges[:-1], edges[1:])]

        def answer(part: slice) -> dict[str, np.ndarray]:
            return _answer(model, x[part], raw[part], None if s is None else s if s.ndim == 1 else s[part],
                           None if images is None else images[part], None if surface is None else surface[part],
                           surface_tolerance_m, None if toward is None else toward[part])

        with _few_threads():
            parts = list(_pool().map(answer, chunks)) if len(chunks) > 1 else [answer(chunks[0])]
        out = {k: np.concatenate([p[k] for p in parts]) for k in parts[0]}
        found = {"clipped": out["clipped"], "low_rate": np.full(len(x), fs < BAND_FS), "no_pulse": out["no_pulse"]}
        if narrow is not None:
            found["narrowband_emitted"] = narrow
        preds = []
        for i in range(len(x)):
            flagged = tuple(name for name in FLAGS if name in given[i] or (name in found and found[name][i]))
            p_open, p_mirror = float(out["open"][i]), float(out["mirror"][i])
            conf = max(p_open, 1 - p_open)
            if flagged:
                conf = min(conf, FLAGGED_CONFIDENCE)
            probs = {"open": p_open, "closed": 1 - p_open, "glass": 1 - p_mirror, "mirror": p_mirror}
            probs.update({f"depth_{d:g}": float(p) for d, p in zip(DEPTH_BINS_M, out["depth_bin"][i])})
            preds.append(Prediction(is_open=p_open > 0.5, material="mirror" if p_mirror > 0.5 else "glass",
                                    depth_m=float(out["depth_m"][i]), probabilities=probs, confidence=conf,
                                    low_confidence=conf < CONFIDENCE_FLOOR or bool(flagged),
                                    model=self.names[key] + ("" if surface is None else " + echo at surface_m"),
                                    flags=flagged,
                                    source_m=None if emitted is not None else tuple(float(v) for v in out["src_m"][i])))
        return preds


CHUNK = 32
"""The most frames :meth:`Classifier.predict_batch` answers at a time: a batch is cut into equal
chunks, as many per thread (:func:`_pool`) and as few as this allows (on this 2-core machine, 64
frames as two chunks of 32 took EchoCNN-E 0.93 ms a frame, as eight of 8 1.12 ms)."""


def _answer(model, x: np.ndarray, raw: np.ndarray, s: np.ndarray | None, images: np.ndarray | None,
            surface: np.ndarray | None = None, tolerance_m: float = PLANE_TOLERANCE_M,
            toward: np.ndarray | None = None) -> dict[str, np.ndarray]:
    """A chunk of checked frames answered: the model's probabilities and what the flags need;
    with ``surface`` (and ``s``), open/closed and a closed surface's depth by the echo there."""
    batch, out = {}, {"clipped": clipped(raw)}
    if s is not None:
        h = deconvolve(x, s)  # one deconvolution for the model's features and the plane's echo
        f = response_features(h)
        batch["envelope"], batch["bands"] = torch.as_tensor(f.envelope), torch.as_tensor(f.bands)
        out["no_pulse"] = ~_begins_with(x, s) | ~_decays(x, s.shape[-1])
    else:
        out["no_pulse"] = ~_decays(x, int(PULSE_S * FS))
    if images is not None:
        batch["image"] = torch.as_tensor(images)
    if "self" in model.inputs:
        f = self_features(x, FS)
        batch["self_envelope"], batch["self_bands"] = torch.as_tensor(f.envelope), torch.as_tensor(f.bands)
    if "mel" in model.inputs:
        batch["mel"] = torch.as_tensor(logmel(x, FS))
    with torch.no_grad():
        y = model(batch)
    out.update(open=torch.softmax(y["open"] / model.config.get("open_temperature", 1.0), 1)[:, 1].numpy(),
               mirror=torch.softmax(y["material"], 1)[:, 1].numpy(),
               depth_bin=torch.softmax(y["depth_bin"], 1).numpy(), depth_m=y["depth_m"].numpy(),
               src_m=y["src_m"].numpy())
    if surface is not None:
        echo = plane_echo_from_responses(h, surface, tolerance_m, toward)
        out["open"] = expit(-(echo.features @ np.array(SURFACE_WEIGHTS) + SURFACE_BIAS))
        out["depth_m"] = np.where(out["open"] < 0.5, echo.depth_m, out["depth_m"])
    return out


_THREADS = {"lock": threading.Lock(), "inside": 0, "saved": None, "pool": None}


@contextlib.contextmanager
def _few_threads():
    """OpenMP's (torch's operators) and BLAS's pools held to one thread each while a prediction
    runs, the caller's settings restored after (the last of concurrent callers restores them).
    A frame's arrays are small: two threads per pool on two cores only wait for each other, and
    wait long while another process keeps a core busy. Through threadpoolctl, never
    ``torch.set_num_threads``: with 2 or more, torch 2.13's MKL batched solver fails after
    (DLASWP) and spins for ever."""
    with _THREADS["lock"]:
        if not _THREADS["inside"]:
            _THREADS["saved"] = _controller().limit(limits=1)
        _THREADS["inside"] += 1
    try:
        yield
    finally:
        with _THREADS["lock"]:
            _THREADS["inside"] -= 1
            if not _THREADS["inside"]:
                _THREADS["saved"].restore_original_limits()


@functools.lru_cache(maxsize=1)
def _controller() -> ThreadpoolController:
    """The thread pools of the libraries loaded by now (scanned once, on first use: 0.3 ms)."""
    return ThreadpoolController()


def _pool() -> ThreadPoolExecutor:
    """Threads that answer a batch's chunks side by side: one per CPU this process may use, at
    most 4 (numpy's FFTs and products and torch release the GIL); made anew in a forked child,
    which inherits none of its parent's threads."""
    if _THREADS["pool"] is None:
        cpus = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1
        _THREADS["pool"] = ThreadPoolExecutor(max_workers=min(4, cpus), thread_name_prefix="vrecho-predict",
                                              initializer=_one_openmp_thread)
    return _THREADS["pool"]


def _one_openmp_thread() -> None:
    """A pool thread's own OpenMP setting (per thread: torch's operators read it), one thread."""
    _controller().limit(limits=1, user_api="openmp")


def _forget_threads() -> None:
    """In a forked child: the parent's pool and lock state are not this process's."""
    _THREADS.update(lock=threading.Lock(), inside=0, saved=None, pool=None)


if hasattr(os, "register_at_fork"):
    os.register_at_fork(after_in_child=_forget_threads)


def _check_flags(flags, n: int) -> list[tuple[str, ...]]:
    if flags is None:
        return [()] * n
    try:
        out = [tuple(f) for f in flags]
    except TypeError:
        raise VrechoError(f"flags: expected one sequence of flag names per frame, got {type(flags).__name__}") from None
    bad = {f for row in out for f in row if not isinstance(f, str) or f not in FLAGS}
    if len(out) != n or bad:
        raise VrechoError(f"flags: expected {n} sequences of names of {FLAGS}, got {len(out)}"
                          + (f" with {sorted(map(repr, bad))}" if bad else ""))
    return out


def _begins_with(x: np.ndarray, s: np.ndarray) -> np.ndarray:
    """Whether each frame (B, n) begins with its emitted sound, ``s`` (k,) or (B, k) at 44.1 kHz:
    a window within :data:`PULSE_LAG_S` of the frame's start that the sound explains by
    :data:`~vrecho.signals.MIN_COHERENCE`."""
    s = np.asarray(s, np.float32)
    k = s.shape[-1]
    m = min(k + int(PULSE_LAG_S * FS), x.shape[1])
    n = scipy.fft.next_fast_len(m + k, real=True)
    frames = np.asarray(x[:, :m], np.float32)  # single precision: a threshold on a ratio, 1e-7 apart at most
    kernel = _pulse_kernel(s.tobytes(), n) if s.ndim == 1 else np.stack([analytic_filter(one, n) for one in s])
    norm = np.broadcast_to(np.linalg.norm(s.astype(np.float64), axis=-1), (len(x),))
    env = analytic_envelope(frames, kernel, n)[:, :m - k + 1]  # one FFT pair for the batch
    return coherence(frames, env / norm[:, None], k).max(axis=-1) >= MIN_COHERENCE


@functools.lru_cache(maxsize=8)
def _pulse_kernel(sound: bytes, n: int) -> np.ndarray:
    """:func:`~vrecho.signals.analytic_filter` of a float32 sound, kept: a device repeats its probe."""
    return analytic_filter(np.frombuffer(sound, np.float32), n)


def _decays(x: np.ndarray, k: int) -> np.ndarray:
    """Whether each frame (B, n) at 44.1 kHz is a sound of ``k`` samples and the room's decay:
    :data:`PULSE_ABOVE_TAIL_DB` and :data:`TAIL_RISE_DB`."""
    hop = int(0.02 * FS)
    start = min(k + int(0.04 * FS), x.shape[1] - 2 * hop)
    bins = (x.shape[1] - start) // hop
    tail = x[:, start:start + bins * hop].reshape(len(x), bins, hop)
    power = np.mean(tail * tail, axis=2).astype(np.float64)  # (pairwise sums in single precision: 1e-7 of a level)
    level = 10 * np.log10(power + 1e-30)
    head = 10 * np.log10(np.mean(x[:, :k].astype(np.float64) ** 2, axis=1) + 1e-30)[:, None]
    level = np.maximum(level, head - TAIL_FLOOR_DB)
    rise = np.max(level[:, 1:] - np.minimum.accumulate(level, axis=1)[:, :-1], axis=1)
    return (level[:, 0] <= head[:, 0] - PULSE_ABOVE_TAIL_DB) & (rise <= TAIL_RISE_DB)


_NAMES = {"A": "EchoCNN-A", "AV": "EchoCNN-AV", "E": "EchoCNN-E", "EV": "EchoCNN-EV"}


def _check_images(images, n: int) -> np.ndarray:
    a = np.asarray(images)
    if a.shape != (n, 64, 25):
        raise VrechoError(f"image: expected a 64 x 25 grayscale crop (64 rows, 25 columns), got shape {a.shape[1:]}")
    if a.dtype == np.uint8:
        return a.astype(np.float32) / 255
    if a.dtype.kind != "f" or not np.all(np.isfinite(a)) or a.min() < 0 or a.max() > 1:
        raise VrechoError("image: expected uint8, or finite floats in [0, 1]")
    return a.astype(np.float32)


@functools.lru_cache(maxsize=8)
def _narrowband_once(sound: bytes) -> bool:
    """:func:`_narrowband` of a float32 sound, kept: a device repeats its probe."""
    return bool(_narrowband(np.frombuffer(sound, np.float32)))


def _narrowband(s: np.ndarray) -> np.ndarray:
    """True where an emitted sound leaves part of 200 Hz to 16 kHz more than 40 dB below its
    strongest octave: the echo features then hold too little timing information."""
    spec = np.abs(np.fft.rfft(s, axis=-1)) ** 2
    f = np.fft.rfftfreq(s.shape[-1], 1 / FS)
    edges = 200 * 2.0 ** np.arange(0, 7)  # 200 Hz ... 12.8 kHz octaves, the last up to 16 kHz
    bands = np.stack([spec[..., (f >= lo) & (f < min(2 * lo, 16000))].mean(axis=-1) for lo in edges], axis=-1)
    db = 10 * np.log10(np.maximum(bands, 1e-30) / bands.max(axis=-1, keepdims=True))
    return db.min(axis=-1) < -40


def load_classifier(path: str | Path | None = None) -> Classifier:
    """EchoCNN with the weights shipped in the package, or those of ``path``.

    Parameters
    ----------
    path : str or pathlib.Path, optional
        A ``classifier.pt`` written by ``vrecho train``; the package's
        ``vrecho/assets/echocnn.pt`` when None.

    Returns
    -------
    Classifier
        The four variants "A", "AV", "E" and "EV", in evaluation mode, float32.

    Raises
    ------
    VrechoError
        If ``path`` does not exist, is not a vrecho classifier, or lacks one of the four
        variants.

    Examples
    --------
    >>> sorted(load_classifier().models)
    ['A', 'AV', 'E', 'EV']
    """
    if path is None:
        with resources.as_file(resources.files("vrecho.assets") / "echocnn.pt") as p:
            return _load(read_bundle(p))
    return _load(read_bundle(path))


def read_bundle(path: str | Path) -> dict:
    """A classifier bundle's contents as stored (``format``, ``version``, ``models``: per
    variant its ``config``, ``state`` in float16 and, where written, ``name``), checked.

    Parameters
    ----------
    path : str or pathlib.Path
        A ``classifier.pt`` (:func:`vrecho.learn.evaluate.export_classifier`).

    Returns
    -------
    dict

    Raises
    ------
    VrechoError
        If ``path`` does not exist, is not a vrecho classifier, or lacks one of the four
        variants.
    """
    path = Path(path)
    if not path.is_file():
        raise VrechoError(f"classifier: no such file {path}")
    try:
        saved = torch.load(path, weights_only=True)
    except Exception as e:  # a foreign or damaged file: say which
        raise VrechoError(f"classifier: {path} is not a vrecho classifier ({type(e).__name__})") from None
    if not isinstance(saved, dict) or saved.get("format") != "vrecho-classifier" or not isinstance(saved.get("models"), dict):
        raise VrechoError(f"classifier: {path} is not a vrecho classifier")
    if set(saved["models"]) != set(_NAMES):
        raise VrechoError(f"classifier: {path} lacks models {sorted(set(_NAMES) - set(saved['models']))}")
    return saved


def _fused(model: torch.nn.Module) -> torch.nn.Module:
    """``model`` (in evaluation mode) made for answering: each convolution and the batch norm
    that follows it folded into one convolution (EchoCNN-E some 8 % less work a frame), the
    echo branch's dilated convolutions :class:`FastConv1d`, and the 2-D convolutions' weights
    in channels-last memory, which oneDNN runs faster for these few channels (one thread, 32
    frames, 2026-12-06: EchoCNN-A's network 0.33 -> 0.17 ms a frame, AV's 0.57 -> 0.27, EV's 0.73
    -> 0.56). The same answers within float32's rounding (4e-6).

    The pairs are a module's ``conv<x>`` and ``norm<x>`` children, or the items of its ``convs``
    and ``norms`` lists: every EchoCNN branch applies such a norm to its convolution's output
    and to nothing else (:mod:`vrecho.models`).
    """
    convs, norms = (torch.nn.Conv1d, torch.nn.Conv2d), (torch.nn.BatchNorm1d, torch.nn.BatchNorm2d)
    for module in model.modules():
        for name, conv in list(module.named_children()):
            norm = getattr(module, "norm" + name[4:], None) if name.startswith("conv") else None
            if isinstance(conv, convs) and isinstance(norm, norms):
                setattr(module, name, fuse_conv_bn_eval(conv, norm))
                setattr(module, "norm" + name[4:], torch.nn.Identity())
            elif isinstance(conv, torch.nn.ModuleList) and isinstance(norm, torch.nn.ModuleList):
                for i, (c, n) in enumerate(zip(conv, norm)):
                    if isinstance(c, convs) and isinstance(n, norms):
                        conv[i], norm[i] = FastConv1d(fuse_conv_bn_eval(c, n)), torch.nn.Identity()
    for module in model.modules():
        if isinstance(module, torch.nn.Conv2d):
            module.to(memory_format=torch.channels_last)
    return model


class FastConv1d(torch.nn.Module):
    """A stride-1 ``Conv1d`` (its output as long as its input) run the faster way torch has for
    the shapes EchoCNN gives it (16 or 24 channels, 661 steps, dilated), the same answers within
    float32's rounding (4e-7 of the largest). One thread, this 2-core machine, the six dilated
    convolutions of EchoCNN-E's echo branch with their residual sums, ms a frame (2026-12-06):

    ============  ===========  ===============================  ===============================
    frames        ``Conv1d``   one matrix product of the        2-D, channels last
                               shifted inputs
    ============  ===========  ===============================  ===============================
    1             1.05         0.58                             0.96
    8             0.58         0.59                             0.49
    32            0.67         0.67                             0.53
    ============  ===========  ===============================  ===============================

    A batch of one frame is one matrix product (torch runs a 1-D convolution of one frame outside
    oneDNN, a dilated one in a loop); larger batches a 2-D convolution over channels-last
    memory (oneDNN's fastest layout for few channels). Its output keeps that layout, so the
    residual sum that adds to it (:class:`vrecho.models.EchoBranch`) hands the next one its
    input without a copy.

    Parameters
    ----------
    conv : torch.nn.Conv1d
        Stride 1, no groups, padding that keeps the length.
    """

    def __init__(self, conv: torch.nn.Conv1d):
        super().__init__()
        self.conv = conv
        w = conv.weight.detach()
        # (out, taps x in), tap-major: the order of the shifted inputs stacked below
        self.register_buffer("taps", w.permute(0, 2, 1).reshape(conv.out_channels, -1).contiguous(), persistent=False)
        self.register_buffer("plane", w[:, :, None, :].contiguous(memory_format=torch.channels_last), persistent=False)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """The convolution of ``x``.

        Parameters
        ----------
        x : torch.Tensor, shape (B, in, n), float32

        Returns
        -------
        torch.Tensor, shape (B, out, n), float32
        """
        c = self.conv
        n, k, pad, d = x.shape[-1], c.kernel_size[0], c.padding[0], c.dilation[0]
        if x.shape[0] == 1:
            shifted = torch.nn.functional.pad(x[0], (pad, pad)).unfold(1, n, d)[:, :k]  # (in, taps, n)
            return torch.addmm(c.bias[:, None], self.taps, shifted.transpose(0, 1).reshape(-1, n))[None]
        x = x.unsqueeze(2).contiguous(memory_format=torch.channels_last)  # (a no-op for this one's output)
        return torch.nn.functional.conv2d(x, self.plane, c.bias, padding=(0, pad), dilation=(1, d)).squeeze(2)


def _load(saved: dict) -> Classifier:
    """The classifier of a bundle's contents (:func:`read_bundle`)."""
    models, names = {}, {}
    for key, entry in saved["models"].items():
        names[key] = entry.get("name", _NAMES.get(key, key))
        model = build(entry["config"])
        model.load_state_dict({k: v.float() if v.is_floating_point() else v for k, v in entry["state"].items()})
        models[key] = _fused(model.eval())
    return Classifier(models, names=names)
