"""Echo frames of the operating envelope's devices, for training EchoCNN-E off the reference device.

The product protocol's dataset (:mod:`.datasets`) hears every room with the reference device (a
loudspeaker firing forward, the microphone 7 cm above it, at the surface's height). Frames of
:mod:`vrecho.sim.devices` are recorded by other devices: omnidirectional or bottom-firing
loudspeakers, microphones 10 to 15 cm off, phones' transducers and limiters, near the floor or
the ceiling, tilted. A folder of them (:func:`generate_devices`) is added to the product
protocol's training and validation frames by ``vrecho train --devices`` (EchoCNN-E only: these
frames have no camera image).

A devices folder holds::

    manifest.json       format, seed, frames, conditions; "complete": true once every chunk is in
    chunk_0000.npz ...  CHUNK frames each: audio (n, 44100) float16 at 44.1 kHz from the
                        emission, emitted (n, 4410) float32, is_open, material, depth_m, condition

Frame ``i`` is drawn by ``numpy.random.default_rng([seed, i])`` under the ``i``-th condition in
turn: the same folder whatever the workers, and a rerun does only the chunks not yet written.
A folder of every condition (``conditions="all"``, another seed) is a test set:
``vrecho evaluate --devices`` judges EchoCNN-E on it per condition (:func:`judge_devices`), with
and without the surface's distance, and EchoCNN-A (the probe unknown).
"""

from __future__ import annotations

import json
import multiprocessing
import os
from concurrent.futures import ProcessPoolExecutor, as_completed
from pathlib import Path

import numpy as np
from scipy.optimize import minimize_scalar
from tqdm import tqdm

from ..errors import VrechoError, check_count, read_json
from ..features import check_emitted, check_frames, echo_features
from ..io import atomic_write_text, ensure_writable_dir
from ..sim.devices import CONDITIONS, TUNING, echo_frame
from .datasets import worker_init

CHUNK = 50
"""Frames per file: what an interrupted run loses at most, per worker."""
FORMAT = "vrecho-devices"
DRAWS = {"tuning": TUNING, "all": CONDITIONS}
"""The conditions a folder draws in turn, by name (:func:`generate_devices`)."""
SURFACE_ERROR_M = 0.02
"""How far off the scan's plane is taken to be when :func:`judge_devices` asks with ``surface_m``."""


def generate_devices(out: str | Path, *, n_frames: int = 2000, seed: int = 0, conditions: str = "tuning",
                     workers: int | None = None, cache=None, progress: bool = True) -> Path:
    """Generate (or finish) a folder of device echo frames.

    Parameters
    ----------
    out : str or path
        The folder; created if missing. One holding another seed or count is refused.
    n_frames : int
        Frames, 1 to 1 000 000 (default 2000), the conditions in turn.
    seed : int
        Everything follows from it (default 0; frame ``i`` draws from ``[seed, i]``, a stream
        no benchmark's single-number seeds share).
    conditions : {"tuning", "all"}
        ``tuning``: those of :data:`vrecho.sim.devices.TUNING`, for training (AAC, 48 kHz and
        all at once left out: the benchmarks' held-out rows); ``all``: every one of
        :data:`vrecho.sim.devices.CONDITIONS`, for a test set (``vrecho evaluate --devices``).
    workers : int, optional
        Processes (default: one per core).
    cache : path, optional
        Impulse-response cache folder (:func:`vrecho.sim.acoustics.impulse_responses`).
    progress : bool
        Show a progress bar.

    Returns
    -------
    pathlib.Path
        The folder.

    Raises
    ------
    VrechoError
        For a count, seed or workers out of range, unknown ``conditions``, or an ``out`` that
        cannot be written or holds something else.
    """
    if conditions not in DRAWS:
        raise VrechoError(f"conditions: expected one of {tuple(DRAWS)}, got {conditions!r}")
    n_frames = check_count(n_frames, "n_frames", 1_000_000)
    seed = check_count(seed, "seed", 2**32 - 1, 0)
    workers = check_count((os.cpu_count() or 1) if workers is None else workers, "workers", 256)
    out = ensure_writable_dir(out)
    identity = {"format": FORMAT, "seed": seed, "n_frames": n_frames, "conditions": list(DRAWS[conditions])}
    path = out / "manifest.json"
    if path.exists():
        old = read_json(path, "devices manifest", expect=dict)
        if {k: old.get(k) for k in identity} != identity:
            raise VrechoError(f"out: {out} holds other device frames (seed {old.get('seed')}, "
                              f"{old.get('n_frames')} frames); choose an empty folder")
        if old.get("complete"):
            return out
    elif any(p.name != path.name for p in out.iterdir()):
        raise VrechoError(f"out: {out} is not empty and holds no device frames; choose an empty folder")
    atomic_write_text(path, json.dumps({**identity, "complete": False}, indent=1))
    chunks = [k for k in range(-(-n_frames // CHUNK)) if not (out / f"chunk_{k:04d}.npz").exists()]
    jobs = [(out, seed, k, range(k * CHUNK, min(n_frames, (k + 1) * CHUNK)), DRAWS[conditions], cache) for k in chunks]
    bar = tqdm(total=n_frames, initial=n_frames - sum(len(j[3]) for j in jobs), unit="frame", desc="device frames",
               disable=not progress)
    try:
        if workers == 1 or len(jobs) <= 1:
            for job in jobs:
                bar.update(_chunk(*job))
        else:
            with ProcessPoolExecutor(workers, mp_context=multiprocessing.get_context("spawn"),
                                     initializer=worker_init) as pool:
                try:
                    for f in as_completed([pool.submit(_chunk, *job) for job in jobs]):
                        bar.update(f.result())
                except BaseException:  # Ctrl-C: the running chunks finish and are kept, the rest wait
                    pool.shutdown(wait=True, cancel_futures=True)
                    raise
    finally:
        bar.close()
    atomic_write_text(path, json.dumps({**identity, "complete": True}, indent=1))
    return out


def _chunk(out: Path, seed: int, k: int, frames: range, conditions: tuple, cache) -> int:
    """Record frames ``frames`` and write them as chunk ``k`` (whole or not at all)."""
    rows = [echo_frame(np.random.default_rng([seed, i]), conditions[i % len(conditions)], cache=cache) for i in frames]
    arrays = {"audio": np.stack([check_frames(f.audio, f.device.fs) for f in rows]).astype(np.float16),
              "emitted": np.stack([check_emitted(f.emitted, f.device.fs, 1) for f in rows]).astype(np.float32),
              "is_open": np.array([f.is_open for f in rows]), "material": np.array([f.material for f in rows]),
              "depth_m": np.array([f.depth_m for f in rows]), "condition": np.array([f.condition for f in rows])}
    tmp = out / f".chunk_{k:04d}.tmp.npz"
    np.savez(tmp, **arrays)
    os.replace(tmp, out / f"chunk_{k:04d}.npz")
    return len(rows)


def load_devices_manifest(path: str | Path) -> dict:
    """A finished devices folder's manifest.

    Parameters
    ----------
    path : str or path

    Returns
    -------
    dict
        ``seed``, ``n_frames``, ``conditions``, ``complete``.

    Raises
    ------
    VrechoError
        When ``path`` holds no devices folder, or an unfinished one.
    """
    m = Path(path) / "manifest.json"
    manifest = read_json(m, "devices manifest", expect=dict) if m.exists() else {}
    if manifest.get("format") != FORMAT:
        raise VrechoError(f"devices: {path} holds no device frames; make them with `vrecho generate --preset devices`")
    if not manifest.get("complete"):
        raise VrechoError(f"devices: {path} is unfinished; rerun `vrecho generate --preset devices` to finish it")
    return manifest


def load_devices(path: str | Path, fields=None) -> dict[str, np.ndarray]:
    """A finished devices folder's frames, every chunk in order.

    Parameters
    ----------
    path : str or path
    fields : sequence of str, optional
        The arrays to read (default: all); a chunk's other arrays are not read.

    Returns
    -------
    dict of str to numpy.ndarray
        ``audio`` (N, 44100) float32, ``emitted`` (N, 4410), ``is_open``, ``material``,
        ``depth_m``, ``condition`` (N,), or those of ``fields``.

    Raises
    ------
    VrechoError
        What :func:`load_devices_manifest` refuses.
    """
    n = load_devices_manifest(path)["n_frames"]
    parts = [np.load(Path(path) / f"chunk_{k:04d}.npz") for k in range(-(-n // CHUNK))]
    out = {name: np.concatenate([p[name] for p in parts]) for name in (fields or parts[0].files)}
    if "audio" in out:
        out["audio"] = out["audio"].astype(np.float32)
    return out


def device_inputs(path: str | Path, *, progress: bool = False) -> dict[str, tuple[dict, dict]]:
    """EchoCNN-E's inputs and targets from a devices folder, read once: every tenth frame (from
    the tenth) validates, the rest train.

    Parameters
    ----------
    path : str or path
        A finished devices folder (:func:`generate_devices`).
    progress : bool
        Show a progress bar over the echo features.

    Returns
    -------
    dict of str to (dict, dict)
        For ``"train"`` and ``"val"``: the inputs, ``envelope`` and ``bands``
        (:func:`~vrecho.features.echo_features`) as torch tensors, and their targets
        (:func:`vrecho.learn.train.targets`).

    Raises
    ------
    VrechoError
        What :func:`load_devices` refuses.
    """
    import torch  # training's: not needed to generate the frames

    from .train import targets  # torch-bound, as above

    d = load_devices(path)
    out = {}
    for split in ("train", "val"):
        keep = (np.arange(len(d["audio"])) % 10 == 9) == (split == "val")
        audio, emitted = d["audio"][keep], d["emitted"][keep]
        n = len(audio)
        labels = {"kind": np.full(n, "echo"), "is_open": d["is_open"][keep].astype(int),
                  "material": d["material"][keep], "depth_m": d["depth_m"][keep].astype(float),
                  **{c: np.full(n, np.nan) for c in ("src_x", "src_y", "src_z")}}
        env, bands = [], []
        for i in tqdm(range(0, n, 256), desc=f"device echo features ({split})", disable=not progress, leave=False):
            f = echo_features(audio[i:i + 256], emitted[i:i + 256])
            env.append(f.envelope)
            bands.append(f.bands)
        x = {"envelope": torch.as_tensor(np.concatenate(env)), "bands": torch.as_tensor(np.concatenate(bands))}
        out[split] = (x, targets(labels, np.arange(n)))
    return out


def open_temperature(model, inputs: dict, target: dict) -> float:
    """The temperature of a trained model's open/closed head (:class:`~vrecho.models.EchoCNN`'s
    ``open_temperature``): the one number its logits are divided by that makes the frames'
    open probabilities likeliest (temperature scaling, Guo et al. 2017), fitted on frames no
    weight was fitted to (other devices' validation frames, :func:`device_inputs`).
    Open/closed answers stay as they were; only their confidence moves.

    Parameters
    ----------
    model : EchoCNN
        Trained, in the inputs' form (switched to evaluation for the fit).
    inputs, target : dict
        :func:`device_inputs`' ``"val"`` pair: the model's inputs and their targets (``open``).

    Returns
    -------
    float
        Within 0.2 to 5, rounded to 1e-4.
    """
    import torch  # training's, as above

    was = model.training
    model.eval()
    with torch.no_grad():
        logits = model(inputs)["open"].double()
    model.train(was)
    z = (logits[:, 1] - logits[:, 0]).numpy()
    sign = 2 * np.asarray(target["open"], float) - 1
    fit = minimize_scalar(lambda t: float(np.mean(np.logaddexp(0, -sign * z / t))), bounds=(0.2, 5), method="bounded")
    return round(float(fit.x), 4)


def calibration_error(p, y, bins: int = 10) -> float:
    """Expected calibration error of open probabilities ``p`` against the truth ``y``: the
    answer's confidence against its accuracy, in equal-width bins of confidence.

    Parameters
    ----------
    p : array_like, shape (N,)
        Probabilities of the positive class.
    y : array_like, shape (N,), bool
    bins : int
        Bins over confidences 0.5 to 1 (default 10).

    Returns
    -------
    float
        From 0 (calibrated) to 0.5.

    Examples
    --------
    >>> calibration_error([0.9, 0.9, 0.1, 0.1], [True, False, False, False])  # sure at 0.9, right 3 of 4
    0.15
    """
    p, y = np.asarray(p, float), np.asarray(y, bool)
    conf, right = np.maximum(p, 1 - p), (p > 0.5) == y
    edges = np.linspace(0.5, 1.0, bins + 1)
    total = 0.0
    for lo, hi in zip(edges[:-1], edges[1:]):
        m = (conf >= lo) & ((conf < hi) | (hi == 1.0))
        if m.any():
            total += m.mean() * abs(conf[m].mean() - right[m].mean())
    return round(float(total), 12)


def judge_devices(model, path: str | Path, *, seed: int = 0, emitted: bool = True) -> dict[str, dict]:
    """A model judged on a devices folder, per condition and pooled, as the classifier asks it:
    EchoCNN-E with the probe known (without the surface's distance and with it), or EchoCNN-A
    without it (the paper's protocol).

    Parameters
    ----------
    model : EchoCNN
        An EchoCNN-E (input ``echo``) with ``emitted``, an EchoCNN-A (``mel``) without.
    path : str or path
        A finished devices folder (a test set: ``conditions="all"``, a seed no training used).
    seed : int
        Seeds the scan's error on ``surface_m``: the truth plus a normal of :data:`SURFACE_ERROR_M`.
    emitted : bool
        Ask with the probe each frame emitted (default True); without it, nothing is asked with
        ``surface_m`` (the echo at a distance needs the sound).

    Returns
    -------
    dict of str to dict
        Per condition and ``"all"``: ``frames``, ``open_share``, ``open_acc`` and
        ``calibration_error`` without ``surface_m``, ``depth_median_cm`` and
        ``depth_within_10cm`` on closed surfaces, ``surface_open_acc`` and
        ``surface_calibration_error`` with it (NaN without ``emitted``).

    Raises
    ------
    VrechoError
        What :func:`load_devices` refuses.
    """
    from ..classifier import Classifier  # torch-bound, as above

    d = load_devices(path)
    clf = Classifier({"E" if emitted else "A": model})
    sound = {"emitted": d["emitted"]} if emitted else {}
    y, depth = d["is_open"].astype(bool), d["depth_m"]
    given = depth + np.random.default_rng([seed, 2027]).normal(0, SURFACE_ERROR_M, len(depth))
    without = clf.predict_batch(d["audio"], 44100, **sound)
    p = np.array([q.probabilities["open"] for q in without])
    ps = np.full(len(y), np.nan)
    if emitted:
        with_s = clf.predict_batch(d["audio"], 44100, surface_m=np.maximum(given, 0.05), **sound)
        ps = np.array([q.probabilities["open"] for q in with_s])
    err = np.abs(np.array([q.depth_m for q in without]) - depth) * 100
    out = {}
    for c in (*dict.fromkeys(d["condition"]), "all"):
        m = np.ones(len(y), bool) if c == "all" else d["condition"] == c
        closed = m & ~y
        out[str(c)] = {"frames": int(m.sum()), "open_share": float(y[m].mean()), "open_acc": float(np.mean((p[m] > 0.5) == y[m])),
                       "calibration_error": calibration_error(p[m], y[m]),
                       "depth_median_cm": float(np.median(err[closed])) if closed.any() else float("nan"),
                       "depth_within_10cm": float(np.mean(err[closed] <= 10)) if closed.any() else float("nan"),
                       "surface_open_acc": float(np.mean((ps[m] > 0.5) == y[m])) if emitted else float("nan"),
                       "surface_calibration_error": calibration_error(ps[m], y[m]) if emitted else float("nan")}
    return out
