"""Training informed separation's mask network (:mod:`localization.masknet`) on simulated walks.

Each training example is one source of a capture of a random shoebox walk
(:func:`vrecho.sim.ambient.random_walk`, seeds from :data:`SEED`): the network's features with
the positions jittered by 12 cm (what :func:`localization.locate` gets wrong) and each source's
image scaled by up to 5 dB either way, and the target, the phase-sensitive share of microphone
0's bin. The shipped weights took 16 epochs::

    python3 -m vrecho.learn.masknet --rooms 1200 --epochs 16 --jobs 16 --data /tmp/masknet --out masknet.pt

(6 minutes simulating on 16 cores, 9 minutes training in batches of 32 on one H100 GPU shared
with two other training runs; the same command runs on a CPU, in batches of 8, where an epoch
takes over an hour.)
"""

from __future__ import annotations

import argparse
import functools
import json
import os
import tempfile
import time
from multiprocessing import get_context
from pathlib import Path

import numpy as np
import torch  # this module trains: torch is what it is for
from tqdm import tqdm

from localization.capture import FS
from localization.masknet import NFFT, features, masknet_class
from localization.separate import analysis, steering

from ..errors import VrechoError, read_json
from ..io import ensure_writable_dir
from ..sim.ambient import random_walk, simulate_walk_capture
from ..sim.arrays import TRAINING, envelope_walk
from . import cluster

SEED = 20_000
"""Training rooms' first seed."""


WALKS = ("shoebox", "envelope")
"""The training walks :func:`make_examples` draws: ``"shoebox"`` (the headset's, on
:func:`~vrecho.sim.ambient.random_walk`'s arcs; the positions jittered by 12 cm) or
``"envelope"`` (:data:`vrecho.sim.arrays.TRAINING`: any array, the head turning, 2 to 4
sources 0 to 20 dB apart; a quarter of the positions missed by 0.3 to 1.5 m, as
:func:`localization.locate` misses them on other arrays, so that the network learns to doubt a
geometry the audio does not bear out)."""


def _examples(args):
    """Training examples from the rooms ``share::jobs`` (one augmentation stream per share),
    saved as ``data_dir/share<share>.npz`` (features, microphone 0's magnitudes, targets)."""
    share, jobs, n_rooms, seed, data_dir, walks = args

    rng_aug = np.random.default_rng(share)
    freqs = np.fft.rfftfreq(NFFT, 1 / FS)
    feats, mags, targets = [], [], []
    for i in range(share, n_rooms, jobs):
        rng = np.random.default_rng(seed + i)
        if walks == "envelope":
            sim = envelope_walk(rng, TRAINING).sim
        else:
            n_src = int(rng.integers(2, 4))
            room, sources, poses = random_walk(rng, n_src, rng.uniform(0.2, 0.8))
            sim = simulate_walk_capture(room, sources, poses, rng, segment_s=1.5)
        true = np.array([s.position for s in sim.sources])
        n_src = len(true)
        for p, cap in enumerate(sim.captures):
            images = sim.images[p].astype(np.float32).astype(np.float64)
            noise = cap.audio.astype(np.float32) - images.sum(axis=0)
            images = images * 10 ** (rng_aug.uniform(-5, 5, n_src) / 20)[:, None, None]
            mix = images.sum(axis=0) + noise
            positions = true + rng_aug.normal(0, 0.12, true.shape)
            if walks == "envelope":
                miss = rng_aug.random(n_src) < 0.25
                away = rng_aug.normal(size=true.shape)
                away *= rng_aug.uniform(0.3, 1.5, (n_src, 1)) / np.linalg.norm(away, axis=1, keepdims=True)
                positions[miss] = true[miss] + away[miss]
            X = analysis(mix, NFFT)
            f = features(X, steering(cap, positions, freqs))  # the steering reads the microphones only
            S = np.stack([analysis(im[:1], NFFT)[..., 0] for im in images])
            X0 = X[..., 0]
            psa = np.clip((S * np.conj(X0)[None]).real / (np.abs(X0)[None] + 1e-12), 0, np.abs(X0)[None])
            mag = np.abs(X0).T.astype(np.float16)
            for k in range(n_src):
                feats.append(f[k].astype(np.float16))
                mags.append(mag)
                targets.append(psa[k].T.astype(np.float16))
    path = Path(data_dir) / f"share{share}.npz"
    np.savez(path, f=np.array(feats), m=np.array(mags), t=np.array(targets))
    return path


def make_examples(data_dir: Path, *, rooms: int = 1200, jobs: int = 2, seed: int = SEED, ray: str | None = None,
                  walks: str = "shoebox") -> list[Path]:
    """Simulate ``rooms`` training walks on ``jobs`` processes into ``data_dir`` (reused when
    its shards were made for the same rooms, processes, seed and FFT size).

    Parameters
    ----------
    data_dir : path
        The shards' folder; created if missing.
    rooms : int
        Random shoebox walks (default 1200); room ``i`` is drawn from seed ``seed + i``.
    jobs : int
        Processes, one shard each (default 2).
    seed : int
        The first room's seed (default :data:`SEED`).
    ray : str, optional
        Make the shards as Ray tasks, one each (:func:`.cluster.run_rooms`): ``"auto"`` (a
        local cluster) or a cluster's address, ``data_dir`` a folder every node sees; the same
        shards as the processes' for the same ``jobs``.
    walks : str
        One of :data:`WALKS` (default ``"shoebox"``).

    Returns
    -------
    list of pathlib.Path
        The shards, ``data_dir/share<k>.npz`` for k below ``jobs``: float16 features ``f``,
        microphone 0's magnitudes ``m`` and phase-sensitive targets ``t``, one row per source.

    Raises
    ------
    VrechoError
        When ``data_dir`` cannot be written.
    """
    if walks not in WALKS:
        raise VrechoError(f"walks: expected one of {WALKS}, got {walks!r}")
    data_dir = Path(data_dir)
    ensure_writable_dir(data_dir)
    stamp = data_dir / "made.json"
    want = {"rooms": rooms, "jobs": jobs, "seed": seed, "nfft": NFFT, **({"walks": walks} if walks != "shoebox" else {})}
    if stamp.exists() and _stamp(stamp) == want:
        return [data_dir / f"share{s}.npz" for s in range(jobs)]
    if ray is not None:
        cluster.run_rooms(ray, _examples, list(range(jobs)), lambda s: ((s, jobs, rooms, seed, data_dir, walks),),
                          lambda s: None, what="shares of the rooms")
        paths = [data_dir / f"share{s}.npz" for s in range(jobs)]
    else:
        with get_context("spawn").Pool(jobs) as pool:
            paths = pool.map(_examples, [(s, jobs, rooms, seed, data_dir, walks) for s in range(jobs)])
    stamp.write_text(json.dumps(want))
    return paths


def _stamp(path: Path):
    """What made the shards, or None where the stamp is damaged (they are made again)."""
    try:
        return read_json(path, "mask network data stamp")
    except VrechoError:
        return None


def _load_examples(paths: list[Path], dev: str = "cpu", rank: int = 0, world: int = 1):
    """The shards' examples: a worker's share of the training rows and the validation rows.

    The last 5 % of the examples (at least 8) are the validation set; of the others, worker
    ``rank`` of ``world`` takes every ``world``-th from ``rank`` (cut to the same count for every
    worker). Each array is one float16 tensor on ``dev``, filled shard by shard (no second copy
    of the whole set).

    Returns
    -------
    train, val : tuple of torch.Tensor
        Features, microphone 0's magnitudes and targets, examples on the first axis.
    """
    shapes, counts = {}, []
    for p in paths:
        with np.load(p) as z:
            for k in "fmt":
                count, *shapes[k] = z[k].shape
            counts.append(count)
    n = sum(counts)
    nv = max(8, n // 20)
    rows = {"train": np.arange(rank, n - nv, world)[:(n - nv) // world], "val": np.arange(n - nv, n)}
    out = {(part, k): torch.empty((len(r), *shapes[k]), dtype=torch.float16, device=dev)
           for part, r in rows.items() for k in "fmt"}
    at = 0
    for p, count in zip(paths, counts):
        with np.load(p) as z:
            for k in "fmt":
                a = z[k]
                for part, r in rows.items():
                    here = r[(r >= at) & (r < at + count)]
                    out[part, k][np.searchsorted(r, here)] = torch.as_tensor(a[here - at]).to(dev)
        at += count
    return tuple(out["train", k] for k in "fmt"), tuple(out["val", k] for k in "fmt")


CROP = 126
"""Frames of a training example's random crop."""


def _fit(model, train_set, val_set, *, epochs: int, lr: float, batch: int, seed: int = 0, net=None,
         checkpoint: Path | None = None, on_epoch=None, progress: bool = True) -> list[float]:
    """The mask network's training: Adam on a one-cycle schedule peaking at ``lr``, ``batch``
    examples a step (each epoch's order and crops seeded by ``(seed, epoch)``), the last epoch's
    weights kept. With ``checkpoint``, each epoch's state is written there (as
    :func:`vrecho.learn.train.fit` writes it, for :func:`.cluster.fit_on_ray`) and a run resumes
    from it. ``net``: what the steps call (``model`` wrapped for distributed data parallel).
    Returns each epoch's validation loss (dB)."""
    from .train import atomic_torch_save  # the one atomic checkpoint writer

    dev = next(model.parameters()).device
    f, m, t = (a.to(dev) for a in train_set)
    fv, mv, tv = (a.to(dev) for a in val_set)
    net = model if net is None else net
    n = len(f)
    opt = torch.optim.Adam(model.parameters(), lr=lr)
    steps = max(1, epochs * (n // batch))
    # a warm-up of 10 % of the steps; never of exactly one step, where OneCycleLR divides by zero
    sched = torch.optim.lr_scheduler.OneCycleLR(opt, lr, total_steps=steps, pct_start=0.1 if steps != 10 else 0.2)
    state = {"epoch": 0, "losses": [], "seconds": 0.0}
    config = {"epochs": epochs, "batch": batch, "examples": n, "lr": lr}
    if checkpoint is not None and Path(checkpoint).exists():
        saved = torch.load(checkpoint, map_location=dev, weights_only=False)
        if saved.get("config") != config:
            raise VrechoError(f"checkpoint {checkpoint} is another run's ({saved.get('config')}); remove it or choose another folder")
        model.load_state_dict(saved["state"])
        opt.load_state_dict(saved["opt"])
        sched.load_state_dict(saved["sched"])
        state = {k: saved[k] for k in state}

    def loss_of(call, F, M, T):
        F, M, T = F.float(), M.float(), T.float()
        floor = 1e-3 * (M ** 2).sum((1, 2))
        return (10 * torch.log10((((call(F) * M - T) ** 2).sum((1, 2)) + floor) / ((T ** 2).sum((1, 2)) + floor))).mean()

    start = time.time() - state["seconds"]
    while state["epoch"] < epochs:
        ep = state["epoch"]
        rng = np.random.default_rng([seed, ep])
        order = rng.permutation(n)
        model.train()
        bar = tqdm(range(n // batch), desc=f"epoch {ep + 1}/{epochs}", disable=not progress)
        for b in bar:
            idx = torch.as_tensor(np.sort(order[b * batch:(b + 1) * batch]), device=dev)
            c0 = int(rng.integers(0, f.shape[-1] - CROP + 1))
            loss = loss_of(net, *(a[idx][..., c0:c0 + CROP] for a in (f, m, t)))
            opt.zero_grad()
            loss.backward()
            opt.step()
            sched.step()
            bar.set_postfix(loss=f"{loss.item():.2f}")
        model.eval()
        with torch.no_grad():
            val = float(np.mean([loss_of(model, *(a[i:i + 8][..., 31:31 + CROP] for a in (fv, mv, tv))).item()
                                 for i in range(0, len(fv), 8)]))
        state = {"epoch": ep + 1, "losses": [*state["losses"], val], "seconds": time.time() - start}
        if checkpoint is not None:
            best = int(np.argmin(state["losses"]))
            atomic_torch_save({**state, "config": config, "state": model.state_dict(), "opt": opt.state_dict(),
                               "sched": sched.state_dict(), "stopped": state["epoch"] >= epochs, "best_state": None,
                               "best_epoch": best, "best": state["losses"][best]}, Path(checkpoint))
        if on_epoch is not None:
            on_epoch({"epoch": ep + 1, "val_loss": val, "stopped": ep + 1 >= epochs})
    return state["losses"]


def train(out: Path, *, rooms: int = 1200, epochs: int = 16, lr: float = 2e-3, init: Path | None = None,
          jobs: int = 2, seed: int = SEED, width: int = 32, data_dir: Path | None = None,
          progress: bool = True, ray: str | None = None, workers: int = 1, gpus_per_worker: float = 0.0,
          checkpoints: Path | None = None, walks: str = "shoebox") -> list[float]:
    """Train the mask network on simulated walks and save its weights.

    Simulate ``rooms`` training walks (into ``data_dir``, a temporary folder if None), train a
    network ``width`` channels wide (from ``init`` if given) for ``epochs`` with a one-cycle
    schedule peaking at ``lr`` (on GPUs, in batches of 32; on CPUs, in batches of 8), and save
    the weights to ``out`` (float16; after every epoch in one process, at the end on Ray).

    Parameters
    ----------
    out : path
        The weights' file; its folder must be writable.
    rooms : int
        Training walks (default 1200).
    epochs : int
        Default 16.
    lr : float
        The one-cycle schedule's peak learning rate (default 2e-3).
    init : path, optional
        Weights to start from.
    jobs : int
        Processes (or Ray tasks) simulating the walks, one shard each (default 2).
    seed : int
        The first room's seed (default :data:`SEED`).
    width : int
        The network's channels (default 32).
    data_dir : path, optional
        Where the simulated examples are kept and reused (:func:`make_examples`); with ``ray``
        at a cluster's address, a folder every node sees (required).
    progress : bool
        Show a progress bar per epoch.
    ray : str, optional
        Simulate the walks as Ray tasks (:func:`make_examples`) and train with Ray Train on
        ``workers`` workers (:func:`.cluster.fit_on_ray`; each reads its share of the examples
        from ``data_dir``, the batch shared out among them): ``"auto"`` (a local cluster) or a
        cluster's address.
    workers, gpus_per_worker : int, float
        Ray Train workers and GPUs per worker (:func:`.cluster.scaling`; with ``ray`` only).
    checkpoints : path, optional
        Ray Train's checkpoints, and a rerun's resume (with ``ray``; a folder every node sees);
        default ``masknet-ray`` in the working folder.
    walks : str
        The training walks, one of :data:`WALKS` (default ``"shoebox"``).

    Returns
    -------
    list of float
        Each epoch's validation loss (the last 5 % of examples, at least 8): the masked
        magnitude's error against the phase-sensitive target, in dB of the target's energy.

    Raises
    ------
    VrechoError
        When the folder of ``out`` or ``data_dir`` cannot be written, ``workers`` or
        ``gpus_per_worker`` is out of range or given without ``ray``, or ``ray`` names a
        cluster's address without ``data_dir``.
    """
    ensure_writable_dir(Path(out).parent)
    workers, gpus_per_worker = cluster.scaling(ray, workers, gpus_per_worker)
    if ray not in (None, "auto") and data_dir is None:
        raise VrechoError("masknet: --ray at a cluster's address needs --data, a folder every node sees")
    init_state = torch.load(init, map_location="cpu", weights_only=True) if init is not None else None
    with tempfile.TemporaryDirectory() as tmp:
        paths = make_examples(Path(data_dir or tmp), rooms=rooms, jobs=jobs, seed=seed, ray=ray, walks=walks)
        if ray is not None:
            batch = 32 if gpus_per_worker else 8
            model, history = cluster.fit_on_ray(
                ray, name="masknet", model=functools.partial(_model, width, init_state),
                load=functools.partial(_load_examples, paths, "cpu"), seed=0, epochs=epochs, patience=epochs,
                workers=workers, gpus_per_worker=gpus_per_worker, storage_path=Path(checkpoints or "masknet-ray"),
                fit=functools.partial(_fit_on_worker, lr=lr, batch=batch))
            _save(model, out)
            return list(history.val_losses)
        dev = "cuda" if torch.cuda.is_available() else "cpu"
        train_set, val_set = _load_examples(paths, dev)
    torch.manual_seed(0)
    model = _model(width, init_state).to(dev)

    def report(record):
        print(f"epoch {record['epoch']}: validation loss {record['val_loss']:.2f} dB", flush=True)
        _save(model, out)

    return _fit(model, train_set, val_set, epochs=epochs, lr=lr, batch=32 if dev == "cuda" else 8, on_epoch=report,
                progress=progress)


def _model(width: int, init_state: dict | None = None):
    """The untrained network (or ``init_state``'s weights), ``width`` channels wide."""
    model = masknet_class()(width)
    if init_state is not None:
        model.load_state_dict(init_state)
    return model


def _save(model, out: Path) -> None:
    torch.save({k: v.half().cpu() for k, v in model.state_dict().items()}, out)  # as shipped


def _fit_on_worker(model, net, data, *, world: int, seed: int, epochs: int, patience: int, checkpoint: Path,
                   on_epoch, lr: float, batch: int) -> None:
    """:func:`_fit` as one of ``world`` Ray Train workers (:func:`.cluster.fit_on_ray`'s ``fit``):
    ``batch`` examples a step shared out among them."""
    _fit(model, *data, epochs=epochs, lr=lr, batch=max(1, batch // world), seed=seed, net=net, checkpoint=checkpoint,
         on_epoch=on_epoch, progress=False)


def main():
    """``python3 -m vrecho.learn.masknet``: :func:`train` with the command line's arguments
    (``--out`` required), then the time it took."""
    ap = argparse.ArgumentParser(prog="python3 -m vrecho.learn.masknet", description="Train informed separation's mask network on simulated walks.")
    ap.add_argument("--rooms", type=int, default=1200)
    ap.add_argument("--epochs", type=int, default=16)
    ap.add_argument("--lr", type=float, default=2e-3)
    ap.add_argument("--init", type=Path, default=None, help="weights to start from")
    ap.add_argument("--jobs", type=int, default=os.cpu_count() or 1)
    ap.add_argument("--seed", type=int, default=SEED)
    ap.add_argument("--width", type=int, default=32, help="the network's channels")
    ap.add_argument("--data", type=Path, default=None, help="keep the simulated examples here (and reuse them)")
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--walks", choices=WALKS, default="shoebox", help="the training walks (default: shoebox)")
    cluster.add_argument(ap, "simulate the walks as Ray tasks (--jobs shares) and train with Ray Train")
    ap.add_argument("--workers", type=int, default=1, help="Ray Train workers (with --ray)")
    ap.add_argument("--gpus-per-worker", type=float, default=0.0, help="GPUs per Ray Train worker (with --ray)")
    ap.add_argument("--checkpoints", type=Path, default=None,
                    help="Ray Train's checkpoints, and a rerun's resume (default: ./masknet-ray)")
    a = ap.parse_args()
    t0 = time.time()
    train(a.out, rooms=a.rooms, epochs=a.epochs, lr=a.lr, init=a.init, jobs=a.jobs, seed=a.seed, width=a.width, data_dir=a.data,
          ray=a.ray, workers=a.workers, gpus_per_worker=a.gpus_per_worker, checkpoints=a.checkpoints, walks=a.walks)
    print(f"{a.out} written in {time.time() - t0:.0f} s")


if __name__ == "__main__":
    main()
