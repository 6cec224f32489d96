"""``vrecho generate``, ``vrecho train`` and ``vrecho evaluate``: a simulated dataset, every method
of the benchmark trained on it, and the paper's tables (:mod:`vrecho.learn`)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import VrechoError
from ..learn.datasets import generate as generate_dataset
from ..learn.datasets import open_dataset
from ..learn.devices import generate_devices, load_devices


def generate(out: str | Path, *, preset: str = "tiny", seed: int = 0, workers: int | None = None, cache=None,
             force: bool = False, progress: bool = True, ray: str | None = None, frames: int = 2000,
             conditions: str = "tuning") -> Path:
    """``vrecho generate``: :func:`vrecho.learn.datasets.generate` (resumable), then what was made.

    Parameters
    ----------
    out : str or path
        Dataset folder; created if missing, and it must be empty or this dataset.
    preset : {"tiny", "small", "default", "devices"}
        Dataset size (default ``tiny``); ``devices``: other devices' echo frames
        (:func:`vrecho.learn.devices.generate_devices`), for ``vrecho train --devices``.
    seed : int
        Everything follows from it (default 0).
    workers : int, optional
        Processes (default: one per core).
    cache : path, optional
        Impulse-response cache folder (default ``~/.cache/vrecho/ir``).
    force : bool
        Generate into a folder holding other files (not a dataset), beside them.
    progress : bool
        Show a progress bar.
    ray : str, optional
        Rooms as Ray tasks: ``"auto"`` (a local cluster) or a cluster's address
        (:mod:`vrecho.learn.cluster`); not with ``devices``.
    frames : int
        Frames of the ``devices`` preset (default 2000).
    conditions : {"tuning", "all"}
        The conditions the ``devices`` preset draws (:func:`vrecho.learn.devices.generate_devices`).

    Returns
    -------
    pathlib.Path
        The dataset folder.

    Raises
    ------
    VrechoError
        For an unknown preset, a negative seed, fewer than 1 worker, or an ``out`` that cannot be
        written or holds something else.
    """
    if preset == "devices":
        if ray is not None or force:
            raise VrechoError(f"{'--ray' if ray is not None else '--force'}: not with the devices preset")
        out = generate_devices(out, n_frames=frames, seed=seed, conditions=conditions, workers=workers, cache=cache,
                               progress=progress)
        d = load_devices(out, fields=("is_open", "condition"))
        conditions, counts = np.unique(d["condition"], return_counts=True)
        print(f"{out}: {len(d['condition'])} device echo frames, {int(d['is_open'].sum())} open; "
              + ", ".join(f"{c} {n}" for c, n in zip(conditions, counts)))
        return out
    out = generate_dataset(out, preset=preset, seed=seed, workers=workers, cache=cache, progress=progress, force=force,
                           ray=ray)
    ds = open_dataset(out)
    m = ds.manifest
    print(f"{out}: {len(ds)} frames ({int(ds.mask(kind='echo').sum())} echo, {int(ds.mask(kind='source').sum())} "
          f"source) from {m['n_irs']} impulse responses in {m['preset_settings']['n_scenes']} rooms")
    for split in ("train", "val", "test"):
        print(f"  {split:5s}: {int(ds.mask(split).sum()):6d} echo frames, paper protocol {int(ds.paper_split(split).sum()):6d}")
    return out


def train(data: str | Path, out: str | Path, *, methods=None, seed: int = 0, epochs: int = 40, patience: int = 6,
          force: bool = False, progress: bool = True, ray: str | None = None, workers: int = 1,
          gpus_per_worker: float = 0.0, devices=None, base=None) -> dict[str, dict]:
    """``vrecho train``: :func:`vrecho.learn.evaluate.train_methods` (resumable), then each
    method's record; ``out/classifier.pt`` once the shipped methods are trained.

    Parameters
    ----------
    data : str or path
        The dataset folder.
    out : str or path
        The run folder for checkpoints and models.
    methods : list of str, optional
        Train only these methods (default: all).
    seed : int
        Random seed (default 0).
    epochs : int
        Most epochs per model (default 40).
    patience : int
        Epochs without improvement before stopping (default 6).
    force : bool
        Train into a folder holding other files (not a run), beside them.
    progress : bool
        Show progress bars.
    ray : str, optional
        Train the CNNs with Ray Train: ``"auto"`` (a local cluster) or a cluster's address.
    workers : int
        Ray Train workers (with ``ray``; default 1).
    gpus_per_worker : float
        GPUs per Ray Train worker (with ``ray``; default 0).
    devices : str or path, optional
        Other devices' echo frames (``vrecho generate --preset devices``) for EchoCNN-E.
    base : str or path, optional
        A classifier bundle whose models ``out/classifier.pt`` keeps where a shipped method
        is not trained in ``out``.

    Returns
    -------
    dict of str to dict
        Each method's training record (:func:`vrecho.learn.evaluate.train_methods`).

    Raises
    ------
    VrechoError
        As :func:`vrecho.learn.evaluate.train_methods` does.
    """
    from ..learn.evaluate import train_methods  # torch-bound (1.7 s): only when training

    records = train_methods(data, out, methods=methods, seed=seed, epochs=epochs, patience=patience, progress=progress,
                            force=force, ray=ray, workers=workers, gpus_per_worker=gpus_per_worker,
                            devices=devices, base=base)
    for name, r in records.items():
        extra = f", {r['epochs']} epochs (best {r['best_epoch'] + 1})" if "epochs" in r else ""
        extra += f", with {r['device_frames'][0]} device frames" if "device_frames" in r else ""
        print(f"{name:18s} {r['protocol']:7s} {r['n_train']:6d} train frames, {r['seconds']:7.1f} s{extra}")
    if (Path(out) / "classifier.pt").exists():
        print(f"classifier: {Path(out) / 'classifier.pt'} (vrecho.load_classifier(path) loads it)")
    return records


def evaluate(data: str | Path, run: str | Path, out: str | Path | None = None, *, methods=None, seed: int = 0,
             force: bool = False, progress: bool = True, devices=None) -> dict[str, dict]:
    """``vrecho evaluate``: :func:`vrecho.learn.evaluate.evaluate` into ``out`` (``run/evaluation``
    by default), then its tables.

    Parameters
    ----------
    data : str or path
        The dataset folder.
    run : str or path
        The run folder written by ``vrecho train``.
    out : str or path, optional
        Output folder (default ``run/evaluation``).
    methods : list of str, optional
        Evaluate only these methods (default: every trained one).
    seed : int
        Seed of the product protocol's probes (default 0).
    force : bool
        Write into an ``out`` holding files evaluation did not write.
    progress : bool
        Show progress bars.
    devices : str or path, optional
        A devices folder of every condition: EchoCNN-E judged on it per condition too.

    Returns
    -------
    dict of str to dict
        Each method's metrics (:func:`vrecho.learn.evaluate.evaluate`).

    Raises
    ------
    VrechoError
        As :func:`vrecho.learn.evaluate.evaluate` does.
    """
    from ..learn.evaluate import evaluate as evaluate_methods  # torch-bound (1.7 s): only when judging

    out = Path(run) / "evaluation" if out is None else Path(out)
    results = evaluate_methods(data, run, out, seed=seed, progress=progress, methods=methods, force=force,
                               devices=devices)
    print((out / "tables.md").read_text())
    print(f"written to {out}: tables.md, results.csv, metrics.json, confusion_*.png, "
          "activation_maximisation_depth.png")
    return results
