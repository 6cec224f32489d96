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
from . import cluster

SEED = 20_000
"""Training rooms' first seed."""


def _examples(args):
    """Training examples from the rooms ``share::jobs`` (one augmentation stream per share),
    saved as ``data_dir/share<share>.npz`` (features, microphone 0's magnitudes, targets)."""
    share, jobs, n_rooms, seed, data_dir = args

    rng_aug = np.random.default_rng(share)
    freqs = np.fft.rfftfreq(NFFT, 1 / FS)
    feats, mags, targets = [], [], []
    for i in range(share, n_rooms, jobs):
        rng = np.random.default_rng(seed + i)
        n_src = int(rng.integers(2, 4))
        rt60 = rng.uniform(0.2, 0.8)
        room, sources, poses = random_walk(rng, n_src, rt60)
        sim = simulate_walk_capture(room, sources, poses, rng, segment_s=1.5)
        true = np.array([s.position for s in sources])
        for p, cap in enumerate(sim.captures):
            images = sim.images[p].astype(np.float32).astype(np.float64)
            noise = cap.audio.astype(np.float32) - images.sum(axis=0)
            images = images * 10 ** (rng_aug.uniform(-5, 5, n_src) / 20)[:, None, None]
            mix = images.sum(axis=0) + noise
            positions = true + rng_aug.normal(0, 0.12, true.shape)
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


def make_examples(data_dir: Path, *, rooms: int = 1200, jobs: int = 2, seed: int = SEED, ray: str | None = None) -> list[Path]:
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
    data_dir = Path(data_dir)
    ensure_writable_dir(data_dir)
    stamp = data_dir / "made.json"
    want = {"rooms": rooms, "jobs": jobs, "seed": seed, "nfft": NFFT}
    if stamp.exists() and _stamp(stamp) == want:
        return [data_dir / f"share{s}.npz" for s in range(jobs)]
    if ray is not None:
        cluster.run_rooms(ray, _examples, list(range(jobs)), lambda s: ((s, jobs, rooms, seed, data_dir),),
                          lambda s: None, what="shares of the rooms")
        paths = [data_dir / f"share{s}.npz" for s in range(jobs)]
    else:
        with get_context("spawn").Pool(jobs) as pool:
            paths = pool.map(_examples, [(s, jobs, rooms, seed, data_dir) for s in range(jobs)])
    stamp.write_text(json.dumps(want))
    return paths


def _stamp(path: Path):
    """What made the shards, or None where the stamp is damaged (they are made again)."""
    try:
        return read_json(path, "mask network data stamp")
    except VrechoError:
        return None


def _load_examples(paths: list[Path], dev: str):
    """The shards' features, magnitudes and targets, each one float16 tensor on ``dev`` (filled
    shard by shard: no second copy of the whole set)."""
    shapes = {}
    for p in paths:
        with np.load(p) as z:
            for k in "fmt":
                n, *rest = z[k].shape
                shapes[k] = (shapes.get(k, (0,))[0] + n, *rest)
    out = {k: torch.empty(shape, dtype=torch.float16, device=dev) for k, shape in shapes.items()}
    at = 0
    for p in paths:
        with np.load(p) as z:
            for k in "fmt":
                a = z[k]
                out[k][at:at + len(a)] = torch.as_tensor(a).to(dev)
            at += len(a)
    return out["f"], out["m"], out["t"]


def train(out: Path, *, rooms: int = 1200, epochs: int = 16, lr: float = 2e-3, init: Path | None = None,
          jobs: int = 2, seed: int = SEED, width: int = 32, data_dir: Path | None = None,
          progress: bool = True, ray: str | None = None) -> list[float]:
    """Train the mask network on simulated walks and save its weights.

    Simulate ``rooms`` training walks (into ``data_dir``, a temporary folder if None), train a
    network ``width`` channels wide (from ``init`` if given) for ``epochs`` with a one-cycle
    schedule peaking at ``lr`` (on the GPU if there is one, in batches of 32; on the CPU in
    batches of 8), and save the weights to ``out`` (float16, after every epoch).

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
        Processes simulating the walks (default 2).
    seed : int
        The first room's seed (default :data:`SEED`).
    width : int
        The network's channels (default 32).
    data_dir : path, optional
        Where the simulated examples are kept and reused (:func:`make_examples`).
    progress : bool
        Show a progress bar per epoch.
    ray : str, optional
        Simulate the walks as Ray tasks (:func:`make_examples`); the training itself runs here.

    Returns
    -------
    list of float
        Each epoch's validation loss (the last 5 % of examples, at least 8): the masked
        magnitude's error against the phase-sensitive target, in dB of the target's energy.

    Raises
    ------
    VrechoError
        When the folder of ``out`` or ``data_dir`` cannot be written.
    """
    ensure_writable_dir(Path(out).parent)
    dev = "cuda" if torch.cuda.is_available() else "cpu"
    with tempfile.TemporaryDirectory() as tmp:
        f, m, t = _load_examples(make_examples(Path(data_dir or tmp), rooms=rooms, jobs=jobs, seed=seed, ray=ray), dev)
    torch.manual_seed(0)
    model = masknet_class()(width).to(dev)
    if init is not None:
        model.load_state_dict(torch.load(init, map_location=dev, weights_only=True))
    n, crop = len(f), 126
    bs = 32 if dev == "cuda" else 8
    nv = max(8, n // 20)
    opt = torch.optim.Adam(model.parameters(), lr=lr)
    sched = torch.optim.lr_scheduler.OneCycleLR(opt, lr, total_steps=max(1, epochs * ((n - nv) // bs)), pct_start=0.1)

    def loss_of(idx, c0):
        F, M, T = (a[idx][..., c0:c0 + crop].float() for a in (f, m, t))
        floor = 1e-3 * (M ** 2).sum((1, 2))
        return (10 * torch.log10((((model(F) * M - T) ** 2).sum((1, 2)) + floor) / ((T ** 2).sum((1, 2)) + floor))).mean()

    rng = np.random.default_rng(0)
    history = []
    for ep in range(epochs):
        model.train()
        order = rng.permutation(n - nv)
        bar = tqdm(range(len(order) // bs), desc=f"epoch {ep + 1}/{epochs}", disable=not progress)
        for b in bar:
            idx = torch.as_tensor(np.sort(order[b * bs:(b + 1) * bs]), device=dev)
            loss = loss_of(idx, int(rng.integers(0, f.shape[-1] - crop + 1)))
            opt.zero_grad()
            loss.backward()
            opt.step()
            sched.step()
            bar.set_postfix(loss=f"{loss.item():.2f}")
        model.eval()
        with torch.no_grad():
            history.append(float(np.mean([loss_of(torch.arange(i, min(n, i + 8), device=dev), 31).item()
                                          for i in range(n - nv, n, 8)])))
        print(f"epoch {ep + 1}: validation loss {history[-1]:.2f} dB", flush=True)
        torch.save({k: v.half().cpu() for k, v in model.state_dict().items()}, out)  # as shipped
    return history


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
    cluster.add_argument(ap, "simulate the walks as Ray tasks (--jobs shares)")
    a = ap.parse_args()
    t0 = time.time()
    train(a.out, rooms=a.rooms, epochs=a.epochs, lr=a.lr, init=a.init, jobs=a.jobs, seed=a.seed, width=a.width, data_dir=a.data,
          ray=a.ray)
    print(f"{a.out} written in {time.time() - t0:.0f} s")


if __name__ == "__main__":
    main()
