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
import torch  # this module trains models: torch is what it is for
from torch.nn import functional as F
from tqdm import tqdm

from ..errors import VrechoError
from ..models import CLASS_HEADS, DEPTH_BINS_M, DEPTH_FT_M, IGNORE, SRC_CELL_M, SRC_CELLS, SRC_GRID_M, EchoCNN


def targets(labels: dict[str, np.ndarray], rows: np.ndarray) -> dict[str, torch.Tensor]:
    """Training targets of the given frames.

    The targets are those of the module's docstring, plus the source's position; heads that do
    not apply to a frame's kind hold IGNORE (classes) or NaN (metres).

    Parameters
    ----------
    labels : dict of str to numpy.ndarray
        A dataset's label columns (:func:`vrecho.learn.datasets.read_labels`), each of shape
        (n_frames,).
    rows : numpy.ndarray, shape (N,), int
        The frames to take.

    Returns
    -------
    dict of str to torch.Tensor
        ``open``, ``material``, ``depth_bin``, ``depth_ft`` (N,) int64 classes (IGNORE where the
        head does not apply); ``depth_m`` (N,) float32, metres (NaN for source frames);
        ``src_cell`` (N, 3) int64, the source's 0.5 m grid cell per axis (IGNORE for echo frames);
        ``src_m`` (N, 3) float32, the source's position in metres in the device frame (NaN for
        echo frames).
    """
    rows = np.asarray(rows)
    echo = labels["kind"][rows] == "echo"
    depth = np.where(echo, labels["depth_m"][rows], np.nan)
    is_open = np.where(echo, labels["is_open"][rows], IGNORE)
    material = np.where(is_open == 0, (labels["material"][rows] == "mirror").astype(int), IGNORE)
    d = np.nan_to_num(depth)
    depth_bin = np.clip(np.round((d - DEPTH_BINS_M[0]) / 0.5), 0, len(DEPTH_BINS_M) - 1).astype(int)
    ft = np.argmin(np.abs(d[:, None] - np.array(DEPTH_FT_M)[None]), axis=1)
    near = echo & (np.abs(d - np.array(DEPTH_FT_M)[ft]) <= 0.1524)
    src = np.stack([labels[c][rows] for c in ("src_x", "src_y", "src_z")], axis=1)
    src[echo] = np.nan
    cells = np.stack([np.clip(np.floor((np.nan_to_num(src[:, i]) - lo) / SRC_CELL_M), 0, n - 1)
                      for i, ((lo, _), n) in enumerate(zip(SRC_GRID_M, SRC_CELLS))], axis=1).astype(int)
    cells[echo] = IGNORE
    return {"open": torch.as_tensor(is_open, dtype=torch.long),
            "material": torch.as_tensor(material, dtype=torch.long),
            "depth_bin": torch.as_tensor(np.where(echo, depth_bin, IGNORE), dtype=torch.long),
            "depth_ft": torch.as_tensor(np.where(near, ft, IGNORE), dtype=torch.long),
            "depth_m": torch.as_tensor(depth, dtype=torch.float32),
            "src_cell": torch.as_tensor(cells, dtype=torch.long),
            "src_m": torch.as_tensor(src, dtype=torch.float32)}


def _axis_logits(scores: torch.Tensor) -> list[torch.Tensor]:
    """The source-cell head's concatenated logits, one tensor per axis."""
    return list(torch.split(scores, SRC_CELLS, dim=1))


def loss_fn(out: dict[str, torch.Tensor], y: dict[str, torch.Tensor], *, depth_weight: float = 2.0) -> torch.Tensor:
    """Sum of the heads' losses over the frames each applies to.

    Cross-entropy for classes, smooth L1 on depth (closed surfaces) and on source position, in
    metres. An echo model's delay attention (``delay_scores``) also takes a cross-entropy toward
    the true echo's delay on closed surfaces, and the source-cell head one cross-entropy per axis
    (a third each).

    Parameters
    ----------
    out : dict of str to torch.Tensor
        EchoCNN's outputs for B frames (:class:`vrecho.models.EchoCNN`).
    y : dict of str to torch.Tensor
        The frames' targets (:func:`targets`).
    depth_weight : float
        Weight of the depth loss (default 2.0).

    Returns
    -------
    torch.Tensor, shape ()
        The summed loss (differentiable).
    """
    loss = out["open"].sum() * 0.0
    d = torch.isfinite(y["depth_m"]) & (y["open"] == 0)  # an opening sends no echo from its plane
    if d.any():
        loss = loss + F.smooth_l1_loss(out["depth_m"][d], y["depth_m"][d], beta=0.05) * depth_weight
    if "delay_scores" in out and d.any():  # the echo branch points at the true echo's delay
        target = (out["depth_at"][None] - y["depth_m"][d, None]).abs().argmin(1)
        loss = loss + F.cross_entropy(out["delay_scores"][d], target, label_smoothing=0.05)
    s = torch.isfinite(y["src_m"]).all(dim=1)
    if s.any():
        loss = loss + F.smooth_l1_loss(out["src_m"][s], y["src_m"][s], beta=0.25)
        for axis, logits in enumerate(_axis_logits(out["src_cell"])):
            loss = loss + F.cross_entropy(logits[s], y["src_cell"][s, axis]) / 3
    for head in CLASS_HEADS:
        if (y[head] != IGNORE).any():
            loss = loss + F.cross_entropy(out[head], y[head], ignore_index=IGNORE)
    return loss


@dataclass
class History:
    """What :func:`fit` did.

    Attributes
    ----------
    epochs : int
        Epochs run (a resumed run's included).
    best_epoch : int
        The epoch (from 0) of the best validation loss; -1 if none ran.
    best_val_loss : float
        That loss (inf if no epoch ran).
    seconds : float
        Training time in seconds, over every run of a resumed training.
    val_losses : tuple of float
        Each epoch's validation loss, from the first (a resumed run's included).
    """

    epochs: int
    best_epoch: int
    best_val_loss: float
    seconds: float
    val_losses: tuple = ()


def _subset(x: dict[str, torch.Tensor], idx, device=None) -> dict[str, torch.Tensor]:
    return {k: v[idx].to(device) if device is not None else v[idx] for k, v in x.items()}


def predict_batches(model: EchoCNN, x: dict[str, torch.Tensor], *, batch_size: int = 256) -> dict[str, torch.Tensor]:
    """The model's outputs for many frames, in evaluation mode, a batch at a time.

    Parameters
    ----------
    model : EchoCNN
        Put in evaluation mode (``model.eval()``) and left so.
    x : dict of str to torch.Tensor
        The model's inputs, each with N frames on its first axis.
    batch_size : int
        Frames per forward pass (default 256).

    Returns
    -------
    dict of str to torch.Tensor
        Each output head concatenated over the N frames; ``depth_at`` (an echo model's delay
        grid, in metres) as the first batch gave it.
    """
    model.eval()
    n = len(next(iter(x.values())))
    device = next(model.parameters()).device
    parts = []
    with torch.no_grad():
        for i in range(0, n, batch_size):
            parts.append({k: v.cpu() for k, v in model(_subset(x, slice(i, i + batch_size), device)).items()})
    return {k: parts[0][k] if k == "depth_at" else torch.cat([p[k] for p in parts]) for k in parts[0]}


def fit(model: EchoCNN, x_train: dict, y_train: dict, x_val: dict, y_val: dict, *, epochs: int = 40,
        batch_size: int = 64, lr: float = 1e-3, patience: int = 6, seed: int = 0,
        checkpoint: str | Path | None = None, progress: bool = True, desc: str = "train", net=None,
        on_epoch=None) -> History:
    """Train with Adam, keep the weights of the best validation loss, stop after ``patience``
    epochs without improvement.

    With ``checkpoint``, the state after every epoch is written there (atomically), and a run
    interrupted at any point resumes from its last finished epoch with the same result: each
    epoch's shuffling and dropout are seeded by ``(seed, epoch)``. A checkpoint that stopped early
    just loads its best weights; one that ran out of epochs goes on if given more.

    Parameters
    ----------
    model : EchoCNN
        Trained in place; it ends with the best weights, in evaluation mode.
    x_train, x_val : dict of str to torch.Tensor
        The model's inputs, frames on the first axis.
    y_train, y_val : dict of str to torch.Tensor
        Their targets (:func:`targets`).
    epochs : int
        Most epochs (default 40).
    batch_size : int
        Frames per step (default 64; a last batch of one frame is skipped).
    lr : float
        Adam's learning rate (default 1e-3).
    patience : int
        Epochs without an improvement of the validation loss (by more than 1e-4) before stopping
        (default 6).
    seed : int
        Seeds each epoch's shuffling and dropout with the epoch.
    checkpoint : str or path, optional
        The file to write each epoch's state to, and to resume from.
    progress : bool
        Show a progress bar.
    desc : str
        The progress bar's label.
    net : torch.nn.Module, optional
        What the training steps call instead of ``model``: ``model`` wrapped for distributed
        data parallel (:mod:`.cluster`), whose backward pass averages the gradients of every
        worker's share of the batch. Validation calls ``model`` itself.
    on_epoch : callable, optional
        Called with the epoch's record (``epoch``, counted from 1, ``val_loss``, ``stopped``)
        after each epoch, once the checkpoint is written.

    Returns
    -------
    History
        Epochs run, best epoch, its validation loss, seconds.

    Raises
    ------
    VrechoError
        When ``checkpoint`` holds another model (another config).
    """
    n = len(next(iter(y_train.values())))
    opt = torch.optim.Adam(model.parameters(), lr=lr)
    state = {"epoch": 0, "best": float("inf"), "best_epoch": -1, "since": 0, "seconds": 0.0, "stopped": False,
             "best_state": None, "losses": []}
    checkpoint = Path(checkpoint) if checkpoint is not None else None
    if checkpoint is not None and checkpoint.exists():
        saved = torch.load(checkpoint, weights_only=False)
        if saved.get("config") != model.config:
            raise VrechoError(f"checkpoint {checkpoint} holds another model ({saved.get('config')}); "
                              "remove it or choose another folder")
        model.load_state_dict(saved["state"])
        opt.load_state_dict(saved["opt"])
        state = {k: saved.get(k, v) for k, v in state.items()}
    net = model if net is None else net
    device = next(model.parameters()).device
    start = time.time() - state["seconds"]
    done = state["stopped"] or state["epoch"] >= epochs
    bar = tqdm(total=epochs, initial=state["epoch"], desc=desc, unit="epoch", disable=not progress or done)
    while not state["stopped"] and state["epoch"] < epochs:
        epoch = state["epoch"]
        torch.manual_seed(seed * 100_003 + epoch)
        order = np.random.default_rng([seed, epoch]).permutation(n)
        model.train()
        for i in range(0, n, batch_size):
            b = order[i:i + batch_size]
            if len(b) < 2:
                continue
            loss = loss_fn(net(_subset(x_train, b, device)), _subset(y_train, b, device))
            opt.zero_grad()
            loss.backward()
            opt.step()
        model.eval()
        with torch.no_grad():
            val = float(loss_fn(predict_batches(model, x_val), y_val))
        bar.set_postfix(val_loss=f"{val:.3f}")
        bar.update()
        state["epoch"] = epoch + 1
        state["losses"] = [*state["losses"], val]
        if val < state["best"] - 1e-4:
            state.update(best=val, best_epoch=epoch, since=0,
                         best_state={k: v.detach().clone() for k, v in model.state_dict().items()})
        else:
            state["since"] += 1
        state["stopped"] = state["since"] >= patience
        state["seconds"] = time.time() - start
        if checkpoint is not None:
            atomic_torch_save({**state, "config": model.config, "state": model.state_dict(),
                               "opt": opt.state_dict()}, checkpoint)
        if on_epoch is not None:
            on_epoch({"epoch": state["epoch"], "val_loss": val, "stopped": state["stopped"]})
    bar.close()
    if state["best_state"] is not None:
        model.load_state_dict(state["best_state"])
    model.eval()
    return History(state["epoch"], state["best_epoch"], state["best"], state["seconds"], tuple(state["losses"]))


def atomic_torch_save(obj, path: Path) -> None:
    """``torch.save(obj, path)`` by way of a temporary file beside it: an interrupt leaves the old
    file or the new, never half of one.

    Parameters
    ----------
    obj : object
        What to save (a checkpoint's dict).
    path : pathlib.Path
        The file.
    """
    tmp = path.with_name(path.name + ".tmp")
    torch.save(obj, tmp)
    tmp.replace(path)


def src_cell_of(scores: torch.Tensor) -> torch.Tensor:
    """(B, 3) grid cell chosen by the source-cell head's scores.

    Parameters
    ----------
    scores : torch.Tensor, shape (B, 60)
        The ``src_cell`` head's logits, the three axes' concatenated (24, 24 and 12 cells).

    Returns
    -------
    torch.Tensor, shape (B, 3), int64
        The cell chosen on each axis.
    """
    return torch.stack([logits.argmax(1) for logits in _axis_logits(scores)], dim=1)


def metrics(out: dict[str, torch.Tensor], y: dict[str, torch.Tensor]) -> dict[str, float]:
    """Accuracy of each class head on the frames it applies to, with their counts; depth errors
    in cm, and depth-class accuracy (``*_closed``), on closed surfaces (an opening sends no echo
    from its own plane: its depth is reported apart, as ``depth_all_*``, over every echo frame);
    source cell accuracy (all three axes right) and position errors in metres.

    Parameters
    ----------
    out : dict of str to torch.Tensor
        A model's outputs for N frames (EchoCNN's heads, or a baseline's scores shaped alike).
    y : dict of str to torch.Tensor
        Their targets (:func:`targets`).

    Returns
    -------
    dict of str to float
        ``open``, ``material``, ``depth_bin``, ``depth_ft`` (accuracy, 0 to 1) and ``n_<head>``;
        ``depth_bin_closed``, ``depth_ft_closed``; ``depth_median_cm``, ``depth_p90_cm``,
        ``n_depth`` and the same for ``depth_all``; ``src_cell`` (0 to 1), ``src_median_m``,
        ``src_p90_m``, ``n_src``. NaN where no frame applies.
    """
    def accuracy(head, keep):
        return float((out[head].argmax(1)[keep] == y[head][keep]).float().mean()) if keep.any() else float("nan")

    res = {}
    for head in CLASS_HEADS:
        keep = y[head] != IGNORE
        res[head], res[f"n_{head}"] = accuracy(head, keep), int(keep.sum())
    for head in ("depth_bin", "depth_ft"):  # the depth classes of closed surfaces alone
        res[f"{head}_closed"] = accuracy(head, (y["open"] == 0) & (y[head] != IGNORE))
    err = (out["depth_m"] - y["depth_m"]).abs()
    for name, keep in (("depth", (y["open"] == 0) & torch.isfinite(err)), ("depth_all", torch.isfinite(err))):
        e = err[keep]
        res[f"{name}_median_cm"] = 100 * float(e.median()) if len(e) else float("nan")
        res[f"{name}_p90_cm"] = 100 * float(e.quantile(0.9)) if len(e) else float("nan")
        res[f"n_{name}"] = int(keep.sum())
    s = torch.isfinite(y["src_m"]).all(dim=1)
    res["n_src"] = int(s.sum())
    if s.any():
        res["src_cell"] = float((src_cell_of(out["src_cell"][s]) == y["src_cell"][s]).all(dim=1).float().mean())
        e = (out["src_m"][s] - y["src_m"][s]).norm(dim=1)
        res["src_median_m"], res["src_p90_m"] = float(e.median()), float(e.quantile(0.9))
    else:
        res["src_cell"] = res["src_median_m"] = res["src_p90_m"] = float("nan")
    return res
