"""The mask network of informed separation (:func:`localization.separate`, ``method="informed"``).

For each located source, every time-frequency bin of a capture (512-point STFT at 16 kHz, 8 ms
hop) gets a share from 0 to 1: how much of microphone 0's bin is that source. The network sees,
per bin, what the geometry says and what the spectrum looks like:

- microphone 0's log power (normalised per capture);
- the bin's coherence with the source's near-field steering vector (from its located position),
  and the largest coherence with any other source's;
- the log power of a linearly constrained beam that passes the source and nulls the other
  sources' direct paths (with the capture's own covariance), and the largest of the others';
- the bin's frequency.

A small U-shaped convolutional network (full frequency resolution at its ends, a quarter of it
in its dilated middle, whose receptive field spans about a second; 32 channels, 333 000
weights) turns them into the share. Its weights ship in ``localization/assets/masknet.pt``
(half precision, 0.7 MB); they were trained on 1 200 simulated walks
(:func:`localization.capture.random_walk`, seeds from 20 000: never the benchmark's 7 000 and
7 300 or the tuning rooms' 7 700; 2 or 3 sources, RT60 0.2-0.8 s, 8 captures each: 24 000
examples), each source's image scaled by up to 5 dB either way and the positions jittered by
12 cm (what :func:`localization.locate` gets wrong), to reproduce the phase-sensitive share of
microphone 0's bin. The loss is the masked magnitude's error in dB of the source's own energy
(with a floor 30 dB under the mixture), so a quiet source counts as much as a loud one. The
shipped weights took 16 epochs::

    python3 -m localization.masknet --rooms 1200 --epochs 16 --jobs 16 --data /tmp/masknet --out masknet.pt

(6 minutes simulating on 16 cores, 9 minutes training in batches of 32 on one H100 GPU shared
with two other training runs; the same command runs on a CPU, in batches of 8, where an epoch
takes over an hour.)
"""

from __future__ import annotations

import argparse
import functools
import os
import time
from pathlib import Path

import numpy as np

from .capture import FS  # the network's sample rate: captures at other rates are resampled to it

NFFT = 512
WEIGHTS = Path(__file__).resolve().parent / "assets" / "masknet.pt"
SEED = 20_000
"""Training rooms' first seed."""


def features(X: np.ndarray, A: np.ndarray) -> np.ndarray:
    """X (T, F, M) a capture's STFT, A (F, M, K) the steering vectors of K >= 2 sources: the
    network's input for each source as the target, (K, 5, F, T) float32 (see the module's
    docstring; one source owns every bin, :func:`source_masks` needs no network for it)."""
    T, F, M = X.shape
    K = A.shape[-1]
    An = A / np.linalg.norm(A, axis=1, keepdims=True)
    Xn = X / (np.linalg.norm(X, axis=-1, keepdims=True) + 1e-12)
    coherence = np.abs(np.einsum("fmk,tfm->kft", np.conj(An), Xn)) ** 2
    Rx = np.einsum("tfm,tfn->fmn", X, np.conj(X)) / T
    Rx = Rx + 1e-3 * np.trace(Rx, axis1=-2, axis2=-1).real[:, None, None] / M * np.eye(M)
    iRA = np.linalg.solve(Rx, A)
    W = iRA @ np.linalg.inv(np.einsum("fmk,fml->fkl", np.conj(A), iRA) + 1e-6 * np.eye(K))  # LCMV
    beams = np.log(np.abs(np.einsum("fmk,tfm->kft", np.conj(W), X)) ** 2 + 1e-10)
    power = np.log(np.abs(X[..., 0].T) ** 2 + 1e-10)
    mu, sd = power.mean(), power.std() + 1e-5
    power, beams = (power - mu) / sd, (beams - mu) / sd
    out = np.zeros((K, 5, F, T), np.float32)
    for k in range(K):
        others = [j for j in range(K) if j != k]
        out[k, 0] = power
        out[k, 1] = coherence[k]
        out[k, 2] = coherence[others].max(axis=0)
        out[k, 3] = beams[k]
        out[k, 4] = beams[others].max(axis=0)
    return out


def _net():
    import torch
    from torch import nn

    class Block(nn.Module):
        def __init__(self, ch: int, dt: int, df: int):
            super().__init__()
            self.conv = nn.Conv2d(ch, ch, 3, padding=(df, dt), dilation=(df, dt))
            self.act = nn.PReLU(ch)

        def forward(self, x):
            return x + self.act(self.conv(x))

    class MaskNet(nn.Module):
        DILATIONS = ((1, 1), (2, 1), (4, 2), (8, 1), (16, 4), (32, 1), (1, 2), (2, 1))  # (time, frequency)

        def __init__(self, ch: int = 32):
            super().__init__()
            self.inp = nn.Sequential(nn.Conv2d(6, ch, 3, padding=1), nn.PReLU(ch))
            self.down = nn.Sequential(nn.Conv2d(ch, 2 * ch, (4, 1), stride=(4, 1)), nn.PReLU(2 * ch))
            self.blocks = nn.Sequential(*[Block(2 * ch, dt, df) for dt, df in self.DILATIONS])
            self.up = nn.ConvTranspose2d(2 * ch, ch, (4, 1), stride=(4, 1))
            self.fuse = nn.Sequential(nn.Conv2d(2 * ch, ch, 3, padding=1), nn.PReLU(ch))
            self.out = nn.Conv2d(ch, 1, 1)

        def forward(self, f):  # (B, 5, F, T) -> (B, F, T)
            B, _, F, T = f.shape
            freq = torch.linspace(-1, 1, F, dtype=f.dtype, device=f.device)[None, None, :, None].expand(B, 1, F, T)
            x = torch.cat([f, freq], 1).contiguous(memory_format=torch.channels_last)
            a = self.inp(x)
            u = self.up(self.blocks(self.down(a)))
            u = nn.functional.pad(u, (0, 0, 0, F - u.shape[2]))
            return torch.sigmoid(self.out(self.fuse(torch.cat([a, u], 1))))[:, 0]

    return MaskNet


@functools.lru_cache(maxsize=1)
def load_masknet():
    """The shipped network, in evaluation mode."""
    import torch

    state = {k: v.float() for k, v in torch.load(WEIGHTS, map_location="cpu", weights_only=True).items()}  # shipped in half precision
    model = _net()(state["inp.0.weight"].shape[0])
    model.load_state_dict(state)
    return model.eval()


def source_masks(X: np.ndarray, A: np.ndarray) -> np.ndarray:
    """Each bin's share of each source, (T, F, K), from a 16 kHz capture's STFT ``X`` (T, F, M)
    and the sources' steering vectors ``A`` (F, M, K)."""
    import torch

    if A.shape[-1] == 1:
        return np.ones(X.shape[:2] + (1,))
    with torch.no_grad():
        masks = load_masknet()(torch.as_tensor(features(X, A))).numpy()
    return masks.transpose(2, 1, 0).astype(np.float64)


def _examples(args):
    """Training examples from the rooms ``share::jobs`` (one augmentation stream per share),
    saved as ``data_dir/share<share>.npz`` (features, microphone 0's magnitudes, targets)."""
    share, jobs, n_rooms, seed, data_dir = args
    from .capture import random_walk, simulate_walk_capture
    from .separate import _stft, steering

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
            X = _stft(mix, NFFT)
            f = features(X, steering(cap, positions, freqs))  # the steering reads the microphones only
            S = np.stack([_stft(im[:1], NFFT)[..., 0] for im in images])
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


def make_examples(data_dir: Path, rooms: int = 1200, jobs: int = 2, seed: int = SEED) -> list[Path]:
    """Simulate ``rooms`` training walks on ``jobs`` processes into ``data_dir`` (reused when
    its shards were made for the same rooms and seed)."""
    import json
    from multiprocessing import get_context

    from vrecho.io import ensure_writable_dir

    data_dir = Path(data_dir)
    ensure_writable_dir(data_dir)
    stamp = data_dir / "made.json"
    want = {"rooms": rooms, "jobs": jobs, "seed": seed, "nfft": NFFT}
    if stamp.exists() and json.loads(stamp.read_text()) == want:
        return [data_dir / f"share{s}.npz" for s in range(jobs)]
    with get_context("spawn").Pool(jobs) as pool:
        paths = pool.map(_examples, [(s, jobs, rooms, seed, data_dir) for s in range(jobs)])
    stamp.write_text(json.dumps(want))
    return paths


def _load_examples(paths: list[Path], dev: str):
    """The shards' features, magnitudes and targets, each one float16 tensor on ``dev`` (filled
    shard by shard: no second copy of the whole set)."""
    import torch

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


def train(out: Path, rooms: int = 1200, epochs: int = 16, lr: float = 2e-3, init: Path | None = None,
          jobs: int = 2, seed: int = SEED, width: int = 32, data_dir: Path | None = None,
          progress: bool = True) -> list[float]:
    """Simulate ``rooms`` training walks (into ``data_dir``, a temporary folder if None), train a
    network ``width`` channels wide (from ``init`` if given) for ``epochs`` with a one-cycle
    schedule peaking at ``lr`` (on the GPU if there is one), and save the weights to ``out``.
    Returns each epoch's validation loss (the last 5 % of examples): the masked magnitude's
    error against the phase-sensitive target, in dB of the target's energy."""
    import tempfile

    import torch
    from tqdm import tqdm

    from vrecho.io import ensure_writable_dir

    ensure_writable_dir(Path(out).parent)
    dev = "cuda" if torch.cuda.is_available() else "cpu"
    with tempfile.TemporaryDirectory() as tmp:
        f, m, t = _load_examples(make_examples(Path(data_dir or tmp), rooms, jobs, seed), dev)
    torch.manual_seed(0)
    model = _net()(width).to(dev)
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
    ap = argparse.ArgumentParser(description="Train informed separation's mask network on simulated walks.")
    ap.add_argument("--rooms", type=int, default=1200)
    ap.add_argument("--epochs", type=int, default=16)
    ap.add_argument("--lr", type=float, default=2e-3)
    ap.add_argument("--init", type=Path, default=None, help="weights to start from")
    ap.add_argument("--jobs", type=int, default=os.cpu_count() or 1)
    ap.add_argument("--seed", type=int, default=SEED)
    ap.add_argument("--width", type=int, default=32, help="the network's channels")
    ap.add_argument("--data", type=Path, default=None, help="keep the simulated examples here (and reuse them)")
    ap.add_argument("--out", type=Path, required=True)
    a = ap.parse_args()
    t0 = time.time()
    train(a.out, a.rooms, a.epochs, a.lr, a.init, a.jobs, a.seed, a.width, a.data)
    print(f"{a.out} written in {time.time() - t0:.0f} s")


if __name__ == "__main__":
    main()
