"""Training EchoCNN on a dataset: labels to targets, a seeded loop with early stopping on the
validation rooms, checkpoints.

Targets per echo frame: ``open`` (0 closed, 1 open), ``material`` (0 glass, 1 mirror; ignored
for openings), ``depth_bin`` (the synthetic table's 0.5 m classes), ``depth_ft`` (1, 2 or 3 ft,
only for frames within half a foot of one; ignored otherwise) and ``depth_m``.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch
from torch.nn import functional as F

from .models import DEPTH_BINS_M, DEPTH_FT_M, EchoCNN

IGNORE = -100


def targets(labels: dict[str, np.ndarray], rows: np.ndarray) -> dict[str, torch.Tensor]:
    """Training targets of the given echo frames (see the module's docstring)."""
    depth = labels["depth_m"][rows]
    is_open = labels["is_open"][rows]
    material = np.where(is_open == 1, IGNORE, (labels["material"][rows] == "mirror").astype(int))
    depth_bin = np.clip(np.round((depth - DEPTH_BINS_M[0]) / 0.5), 0, len(DEPTH_BINS_M) - 1).astype(int)
    ft = np.argmin(np.abs(depth[:, None] - np.array(DEPTH_FT_M)[None]), axis=1)
    near = np.abs(depth - np.array(DEPTH_FT_M)[ft]) <= 0.1524
    return {"open": torch.as_tensor(is_open, dtype=torch.long),
            "material": torch.as_tensor(material, dtype=torch.long),
            "depth_bin": torch.as_tensor(depth_bin, dtype=torch.long),
            "depth_ft": torch.as_tensor(np.where(near, ft, IGNORE), dtype=torch.long),
            "depth_m": torch.as_tensor(depth, dtype=torch.float32)}


def loss_fn(out: dict[str, torch.Tensor], y: dict[str, torch.Tensor], depth_weight: float = 2.0) -> torch.Tensor:
    """Sum of the heads' losses: cross-entropy for classes (ignoring what does not apply) and a
    smooth L1 on depth in metres."""
    loss = F.smooth_l1_loss(out["depth_m"], y["depth_m"], beta=0.05) * depth_weight
    for head in ("open", "material", "depth_bin", "depth_ft"):
        if (y[head] != IGNORE).any():
            loss = loss + F.cross_entropy(out[head], y[head], ignore_index=IGNORE)
    return loss


@dataclass
class History:
    epochs: int
    best_epoch: int
    best_val_loss: float
    seconds: float


def _subset(x: dict[str, torch.Tensor], idx) -> dict[str, torch.Tensor]:
    return {k: v[idx] for k, v in x.items()}


def fit(model: EchoCNN, x_train: dict, y_train: dict, x_val: dict, y_val: dict, epochs: int = 40,
        batch_size: int = 64, lr: float = 1e-3, patience: int = 6, seed: int = 0,
        checkpoint: str | Path | None = None, progress: bool = True) -> History:
    """Train with Adam, keep the weights of the best validation loss, stop after ``patience``
    epochs without improvement. Writes the best weights to ``checkpoint`` when given."""
    from tqdm import tqdm

    torch.manual_seed(seed)
    rng = np.random.default_rng(seed)
    opt = torch.optim.Adam(model.parameters(), lr=lr)
    n = len(next(iter(y_train.values())))
    best, best_state, best_epoch, since = np.inf, None, -1, 0
    start = time.time()
    bar = tqdm(range(epochs), desc="train", unit="epoch", disable=not progress)
    for epoch in bar:
        model.train()
        order = rng.permutation(n)
        for i in range(0, n, batch_size):
            b = order[i:i + batch_size]
            if len(b) < 2:
                continue
            loss = loss_fn(model(_subset(x_train, b)), _subset(y_train, b))
            opt.zero_grad()
            loss.backward()
            opt.step()
        model.eval()
        with torch.no_grad():
            val = float(loss_fn(model(x_val), y_val))
        bar.set_postfix(val_loss=f"{val:.3f}")
        if val < best - 1e-4:
            best, best_epoch, since = val, epoch, 0
            best_state = {k: v.detach().clone() for k, v in model.state_dict().items()}
            if checkpoint is not None:
                torch.save({"state": best_state, "inputs": model.inputs, "fusion": model.fusion}, checkpoint)
        else:
            since += 1
            if since >= patience:
                break
    bar.close()
    if best_state is not None:
        model.load_state_dict(best_state)
    return History(epoch + 1, best_epoch, best, time.time() - start)


def metrics(out: dict[str, torch.Tensor], y: dict[str, torch.Tensor]) -> dict[str, float]:
    """Accuracy of each class head (on the frames it applies to) and depth errors in cm."""
    res = {}
    for head in ("open", "material", "depth_bin", "depth_ft"):
        keep = y[head] != IGNORE
        res[head] = float((out[head].argmax(1)[keep] == y[head][keep]).float().mean()) if keep.any() else float("nan")
        res[f"n_{head}"] = int(keep.sum())
    err = (out["depth_m"] - y["depth_m"]).abs()
    res["depth_median_cm"] = 100 * float(err.median())
    res["depth_p90_cm"] = 100 * float(err.quantile(0.9))
    return res
