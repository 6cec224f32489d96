"""The benchmark harness: every method of PROTOCOL.md trained and judged on the same data in one
run, the paper's tables, confusion matrices and the activation-maximisation figure.

Two protocols (PROTOCOL.md):

- ``paper``: the emitted sound is unknown to the model. Train and validation frames are the train
  sounds in train and validation rooms; the test frames are the held-out sounds in test rooms.
  Echo frames train the surface heads, source frames the source-position heads.
- ``product``: the model knows what was emitted. Every echo impulse response of the train and
  validation rooms is heard with random broadband probes; the test rooms' responses with
  vrecho's own probe and with a random probe.

A run folder holds one checkpoint per method (``models/``) and, once every method is trained,
the bundle the classifier ships (``classifier.pt``, see :mod:`vrecho.classifier`).
"""

from __future__ import annotations

import csv
import json
import pickle
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch  # this module trains and judges models: torch is what it is for
from scipy.signal import resample_poly

from ..errors import VrechoError
from ..features import echo_features
from ..io import atomic_write_text, ensure_writable_dir
from ..models import CLASS_HEADS, DEPTH_BINS_M, HEADS, EchoCNN, FeatureBaseline, build
from ..scene import MIC_ABOVE_EMITTER_M
from ..signals import FS, SPEED_OF_SOUND
from .datasets import open_dataset
from .train import fit, metrics, predict_batches, targets


@dataclass(frozen=True)
class Method:
    """One row of the tables: a model kind, its inputs and the protocol it is judged under."""

    name: str
    kind: str  # "cnn", "knn" or "svm"
    inputs: tuple[str, ...]
    protocol: str = "paper"
    fusion: str = "concat"
    wave_layers: int = 8
    max_epochs: int | None = None  # a cap below the run's epochs (the slow raw-waveform baselines)

    @property
    def slug(self) -> str:
        return "".join(c if c.isalnum() else "_" for c in self.name.lower()).strip("_")

    def model(self) -> EchoCNN:
        return EchoCNN(self.inputs, fusion=self.fusion, wave_layers=self.wave_layers)

    def path(self, run) -> Path:
        """Where a run folder keeps this method's trained model."""
        return Path(run) / "models" / f"{self.slug}.{'pt' if self.kind == 'cnn' else 'pkl'}"


METHODS = (
    Method("EchoCNN-A", "cnn", ("mel",)),
    Method("EchoCNN-AV concat", "cnn", ("mel", "image")),
    Method("EchoCNN-AV MFB", "cnn", ("mel", "image"), fusion="mfb"),
    Method("kNN", "knn", ("mel",)),
    Method("linear SVM", "svm", ("mel",)),
    Method("SoundNet-5", "cnn", ("wave",), wave_layers=5, max_epochs=8),
    Method("SoundNet-8", "cnn", ("wave",), wave_layers=8, max_epochs=8),
    Method("visual only", "cnn", ("image",)),
    Method("EchoCNN-E", "cnn", ("echo",), protocol="product"),
    Method("EchoCNN-EV", "cnn", ("echo", "image"), protocol="product"),
    Method("kNN (echo)", "knn", ("envelope", "bands"), protocol="product"),
)
SHIPPED = {"A": "EchoCNN-A", "AV": "EchoCNN-AV concat", "E": "EchoCNN-E", "EV": "EchoCNN-EV"}
"""The classifier's models: which method answers for audio alone (A), audio and image (AV), audio
with the emitted sound (E) and all three (EV); see :mod:`vrecho.classifier`. A variant goes in
only where it measures better on the validation rooms."""
PRODUCT_TRAIN_PROBES = ("random",) * 8
PRODUCT_VAL_PROBES = ("random",) * 2
PRODUCT_TEST_PROBES = ("vrecho", "random")


def method(name: str) -> Method:
    for m in METHODS:
        if m.name == name or m.slug == name:
            return m
    raise VrechoError(f"method: expected one of {', '.join(m.name for m in METHODS)}; got {name!r}")


class Frames:
    """The frames of one protocol and split, with every input any method asks for, loaded once."""

    def __init__(self, ds, protocol: str, split: str, *, seed: int = 0, progress: bool = False):
        self.ds, self.protocol, self.split, self.seed, self.progress = ds, protocol, split, seed, progress
        self.audio = self.emitted = None  # read or rendered when an input needs them
        if protocol == "paper":
            self.rows = np.where(ds.paper_split(split, "echo") | ds.paper_split(split, "source"))[0]
            self.group = ds.labels["sound"][self.rows]
        elif protocol == "product":
            self.probes = {"train": PRODUCT_TRAIN_PROBES, "val": PRODUCT_VAL_PROBES}.get(split, PRODUCT_TEST_PROBES)
            ir_rows = ds.echo_ir_rows(split)  # the order Dataset.probe_frames renders them in
            self.rows = np.repeat(ir_rows, len(self.probes))
            self.group = np.char.add(np.tile(np.asarray(self.probes, dtype=str), len(ir_rows)), " probe")
        else:
            raise VrechoError(f"protocol: expected paper or product, got {protocol!r}")
        self.y = targets(ds.labels, self.rows)
        self._x: dict[str, torch.Tensor] = {}

    def __len__(self) -> int:
        return len(self.rows)

    def _audio(self) -> np.ndarray:
        if self.audio is None and self.protocol == "product":
            self.audio, self.emitted, _, _ = self.ds.probe_frames(self.split, self.probes, seed=self.seed, progress=self.progress)
        elif self.audio is None:
            self.audio = _read_rows(self.ds.audio, self.rows).astype(np.float32)
        return self.audio

    def inputs(self, keys) -> dict[str, torch.Tensor]:
        """Tensors for the given input names (``echo`` means ``envelope`` and ``bands``)."""
        names = [k for key in keys for k in (("envelope", "bands") if key == "echo" else (key,))]
        for name in names:
            if name in self._x:
                continue
            if name == "mel":
                self._x[name] = torch.as_tensor(_read_rows(self.ds.logmel, self.rows))
            elif name == "image":
                self._x[name] = torch.as_tensor(_read_rows(self.ds.image, self.rows), dtype=torch.float32) / 255
            elif name == "wave":  # the SoundNet baselines' 11.025 kHz
                self._x[name] = torch.as_tensor(resample_poly(self._audio(), 1, 4, axis=1).astype(np.float32))
            elif name in ("envelope", "bands"):
                if self.protocol != "product":
                    raise VrechoError("echo features need the emitted sound: use the product protocol")
                self._audio()
                env, bands = [], []
                for i in range(0, len(self), 256):
                    f = echo_features(self._audio()[i:i + 256], self.emitted[i:i + 256])
                    env.append(f.envelope)
                    bands.append(f.bands)
                self._x["envelope"] = torch.as_tensor(np.concatenate(env))
                self._x["bands"] = torch.as_tensor(np.concatenate(bands))
            else:
                raise VrechoError(f"unknown input {name!r}")
        return {k: self._x[k] for k in names}


def _read_rows(array, rows: np.ndarray) -> np.ndarray:
    """Rows of a Zarr array, reading each chunk once."""
    rows = np.asarray(rows)
    order = np.argsort(rows)
    out = np.empty((len(rows),) + array.shape[1:], array.dtype)
    if len(rows):
        out[order] = array.get_orthogonal_selection((rows[order],) + (slice(None),) * (array.ndim - 1))
    return out


class Harness:
    """Frames of every protocol and split, loaded on demand and shared by the methods."""

    def __init__(self, data, *, seed: int = 0, progress: bool = True):
        self.ds = open_dataset(data)
        self.seed, self.progress = seed, progress
        self._frames: dict[tuple[str, str], Frames] = {}

    def frames(self, protocol: str, split: str) -> Frames:
        key = (protocol, split)
        if key not in self._frames:
            self._frames[key] = Frames(self.ds, protocol, split, seed=self.seed, progress=self.progress)
        return self._frames[key]


def train_methods(data, out, *, methods=None, seed: int = 0, epochs: int = 40, patience: int = 6,
                  progress: bool = True) -> dict[str, dict]:
    """Train every method (or those named) on a dataset, resumably, into the run folder ``out``.

    Returns, per method, its training record (epochs, best epoch, seconds). When the methods of
    :data:`SHIPPED` are all trained, writes ``classifier.pt`` (the classifier's weights).
    """
    out = ensure_writable_dir(out)
    chosen = [method(m) for m in methods] if methods else list(METHODS)
    harness = Harness(data, seed=seed, progress=progress)
    m = harness.ds.manifest
    identity = {"format": "vrecho-run", "dataset": {k: m[k] for k in ("preset", "seed", "n_frames")}, "seed": seed}
    run_path = out / "run.json"
    if run_path.exists():
        old = json.loads(run_path.read_text())
        if old != identity:
            raise VrechoError(f"out: {out} holds models of another dataset or seed ({old.get('dataset')}, seed "
                              f"{old.get('seed')}); choose another folder")
    elif any(out.iterdir()):
        raise VrechoError(f"out: {out} is not empty and holds no vrecho run; choose an empty folder")
    atomic_write_text(run_path, json.dumps(identity, indent=1))
    (out / "models").mkdir(exist_ok=True)
    records_path = out / "training.json"
    records = json.loads(records_path.read_text()) if records_path.exists() else {}
    for m in chosen:
        path = m.path(out)
        if m.name in records and path.exists():
            continue
        tr, va = harness.frames(m.protocol, "train"), harness.frames(m.protocol, "val")
        start = time.time()
        if m.kind == "cnn":
            torch.manual_seed(seed)
            model = m.model()
            h = fit(model, tr.inputs(m.inputs), tr.y, va.inputs(m.inputs), va.y,
                    epochs=min(epochs, m.max_epochs or epochs), patience=patience,
                    seed=seed, checkpoint=path.with_suffix(".ckpt"), progress=progress, desc=m.name)
            torch.save({"config": model.config, "state": model.state_dict()}, path)
            rec = {"epochs": h.epochs, "best_epoch": h.best_epoch, "val_loss": round(h.best_val_loss, 4),
                   "seconds": round(h.seconds, 1)}
        else:
            est = FeatureBaseline(m.kind, m.inputs).fit(tr.inputs(m.inputs), tr.y)
            path.write_bytes(pickle.dumps(est))
            rec = {"seconds": round(time.time() - start, 1)}
        rec.update(seed=seed, n_train=len(tr), n_val=len(va), protocol=m.protocol)
        records[m.name] = rec
        atomic_write_text(records_path, json.dumps(records, indent=1))
    if all(name in records for name in SHIPPED.values()):
        export_classifier(out, out / "classifier.pt")
    return records


def load_method(run, m: Method):
    path = m.path(run)
    if not path.exists():
        raise VrechoError(f"{run}: {m.name} is not trained (no {path.name}); run `vrecho train` first")
    if m.kind != "cnn":
        return pickle.loads(path.read_bytes())
    saved = torch.load(path, weights_only=True)
    model = build(saved["config"])
    model.load_state_dict(saved["state"])
    return model.eval()


def export_classifier(run, path) -> Path:
    """Bundle the shipped methods' weights (float16, a few MB) into one file for the classifier."""
    bundle = {}
    for key, name in SHIPPED.items():
        model = load_method(run, method(name))
        bundle[key] = {"name": name, "config": model.config,
                       "state": {k: v.half() if v.is_floating_point() else v for k, v in model.state_dict().items()}}
    path = Path(path)
    tmp = path.with_name(path.name + ".tmp")
    torch.save({"format": "vrecho-classifier", "version": 1, "models": bundle}, tmp)
    tmp.replace(path)
    return path


# ----------------------------------------------------------------------------------------------
# Evaluation: tables and figures

COLUMNS = (("open", "open/closed %"), ("material", "material %"), ("depth_ft", "depth 1/2/3 ft %"),
           ("depth_ft_closed", "closed: 1/2/3 ft %"), ("depth_bin", "depth 0.5 m %"),
           ("depth_bin_closed", "closed: 0.5 m %"), ("depth_median_cm", "depth median cm"), ("depth_p90_cm", "depth p90 cm"),
           ("src_cell", "source cell %"), ("src_median_m", "source median m"))


def evaluate(data, run, out, *, seed: int = 0, progress: bool = True, methods=None) -> dict[str, dict]:
    """Judge every trained method on the test frames; write tables (Markdown and CSV), confusion
    matrices and the activation-maximisation figure into ``out``. Returns the metrics."""
    out = ensure_writable_dir(out)
    harness = Harness(data, seed=seed, progress=progress)
    chosen = [method(m) for m in methods] if methods else [m for m in METHODS if _trained(run, m)]
    if not chosen:
        raise VrechoError(f"{run}: no trained methods; run `vrecho train --data {data} --out {run}` first")
    results, outputs = {}, {}
    for m in chosen:
        te = harness.frames(m.protocol, "test")
        model = load_method(run, m)
        x = te.inputs(m.inputs)
        start = time.time()
        o = predict_batches(model, x) if m.kind == "cnn" else model.predict(x)
        o = {k: v for k, v in o.items() if k in HEADS}
        res = metrics(o, te.y)
        res["seconds_per_frame"] = (time.time() - start) / len(te)
        groups = {}
        for g in np.unique(te.group):
            keep = torch.as_tensor(te.group == g)
            groups[str(g)] = metrics({k: v[keep] for k, v in o.items()}, {k: v[keep] for k, v in te.y.items()})
        res["by_group"] = groups
        results[m.name], outputs[m.name] = res, o
    meta = {"seed": seed, "data": str(data), "n": {p: {s: len(harness.frames(p, s)) for s in ("train", "val", "test")}
                                                   for p in sorted({m.protocol for m in chosen})}}
    write_tables(results, chosen, meta, out)
    confusion_figures(outputs, chosen, harness, out)
    shown = {m.name: load_method(run, m) for m in chosen if m.name in ("EchoCNN-A", "EchoCNN-E")}
    if shown:
        activation_maximisation(shown, out / "activation_maximisation_depth.png")
    atomic_write_text(out / "metrics.json", json.dumps({"meta": meta, "results": results}, indent=1))
    return results


def _trained(run, m: Method) -> bool:
    return m.path(run).exists()


def _fmt(key: str, v: float) -> str:
    if v != v:  # NaN: the head does not apply
        return "-"
    if key.endswith("_cm") or key.endswith("_m"):
        return f"{v:.2f}" if key.endswith("_m") else f"{v:.1f}"
    return f"{100 * v:.1f}"


TABLES = {
    "real": ("Real-scene protocol (the paper's Table 1): depth in 1/2/3 ft classes",
             ("open", "material", "depth_ft", "depth_ft_closed", "depth_median_cm", "depth_p90_cm")),
    "synthetic": ("Synthetic protocol (the paper's Table 2): depth in 0.5 m steps (+/- 0.25 m)",
                  ("open", "material", "depth_bin", "depth_bin_closed", "depth_median_cm", "depth_p90_cm", "src_cell",
                   "src_median_m")),
}


def write_tables(results: dict, methods, meta: dict, out: Path) -> None:
    """``tables.md`` (the two paper tables per protocol and the per-sound breakdown) and
    ``results.csv`` (every metric of every method)."""
    names = dict(COLUMNS)
    lines = [f"Seed {meta['seed']}; dataset {meta['data']}. Test: held-out sounds in unseen rooms (paper protocol); "
             "vrecho's probe and random broadband probes in unseen rooms (product protocol). Depth errors on closed "
             "surfaces (an opening returns no echo from its own plane).", ""]
    for protocol in ("paper", "product"):
        ms = [m for m in methods if m.protocol == protocol]
        if not ms:
            continue
        n = meta["n"][protocol]
        lines.append(f"## {protocol.capitalize()} protocol (train {n['train']}, val {n['val']}, test {n['test']} frames)")
        lines.append("")
        for title, keys in TABLES.values():
            lines += [f"### {title}", "", "| method | " + " | ".join(names[k] for k in keys) + " |",
                      "|---|" + "---:|" * len(keys)]
            for m in ms:
                r = results[m.name]
                lines.append(f"| {m.name} | " + " | ".join(_fmt(k, r[k]) for k in keys) + " |")
            lines.append("")
        groups = sorted({g for m in ms for g in results[m.name]["by_group"]})
        keys = ("open", "material", "depth_bin", "depth_median_cm")
        lines += ["### Per test sound: " + ", ".join(names[k] for k in keys), "",
                  "| sound | " + " | ".join(m.name for m in ms) + " |", "|---|" + "---:|" * len(ms)]
        for g in groups:
            cells = [" / ".join(_fmt(k, results[m.name]["by_group"].get(g, {}).get(k, float("nan"))) for k in keys)
                     for m in ms]
            lines.append(f"| {g} | " + " | ".join(cells) + " |")
        lines.append("")
    atomic_write_text(out / "tables.md", "\n".join(lines))
    keys = [k for k in next(iter(results.values())) if k != "by_group"]
    with open(out / "results.csv.tmp", "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["method", "protocol", "group"] + keys)
        for m in methods:
            r = results[m.name]
            w.writerow([m.name, m.protocol, "all"] + [r[k] for k in keys])
            for g, rg in r["by_group"].items():
                w.writerow([m.name, m.protocol, g] + [rg.get(k, "") for k in keys])
    (out / "results.csv.tmp").replace(out / "results.csv")


def confusion_figures(outputs: dict, methods, harness: Harness, out: Path) -> list[Path]:
    """One PNG per class head: a confusion matrix per method (rows true, columns predicted,
    normalised per true class)."""
    import matplotlib  # heavy (0.8 s to import): only figures need it

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # once the Agg backend is chosen: no display needed
    from sklearn.metrics import confusion_matrix  # heavy (1.7 s to import): only this figure needs it

    labels = {"open": ("closed", "open"), "material": ("glass", "mirror"),
              "depth_bin": tuple(f"{d:g}" for d in DEPTH_BINS_M), "depth_ft": ("1 ft", "2 ft", "3 ft")}
    paths = []
    for head in CLASS_HEADS:
        n = len(methods)
        cols = min(n, 4)
        rows = (n + cols - 1) // cols
        fig, axes = plt.subplots(rows, cols, figsize=(3.2 * cols, 3.0 * rows), squeeze=False)
        for ax, m in zip(axes.flat, methods):
            y = harness.frames(m.protocol, "test").y[head]
            keep = y != -100
            k = len(labels[head])
            cm = confusion_matrix(y[keep].numpy(), outputs[m.name][head].argmax(1)[keep].numpy(), labels=range(k))
            cmn = cm / np.maximum(cm.sum(axis=1, keepdims=True), 1)
            ax.imshow(cmn, vmin=0, vmax=1, cmap="Blues")
            for i in range(k):
                for j in range(k):
                    if k <= 3 or cm[i, j]:
                        ax.text(j, i, f"{100 * cmn[i, j]:.0f}", ha="center", va="center", fontsize=7,
                                color="white" if cmn[i, j] > 0.5 else "black")
            ax.set_xticks(range(k), labels[head], fontsize=7, rotation=45 if k > 3 else 0)
            ax.set_yticks(range(k), labels[head], fontsize=7)
            ax.set_title(f"{m.name} ({m.protocol})", fontsize=8)
        for ax in list(axes.flat)[n:]:
            ax.axis("off")
        fig.suptitle(f"Confusion matrices, {head.replace('_', ' ')} (rows: truth, columns: prediction, % of row)",
                     fontsize=9)
        fig.tight_layout()
        path = out / f"confusion_{head}.png"
        fig.savefig(path, dpi=110)
        plt.close(fig)
        paths.append(path)
    return paths


def activation_maximisation(models: dict[str, EchoCNN], path, *, steps: int = 300, seed: int = 0) -> Path:
    """For each depth class of the depth head, the input that excites it most: gradient ascent on
    the class logit with an L2 pull toward a neutral input and a smoothness penalty.

    ``models`` maps a method name to its model: a log-mel model (EchoCNN-A) gets one row of
    spectrograms; an echo model (EchoCNN-E) a panel of recovered impulse-response envelopes,
    with each class's depth range marked where its echo should be.
    """
    import matplotlib  # heavy (0.8 s to import): only figures need it

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # once the Agg backend is chosen: no display needed

    k = len(DEPTH_BINS_M)
    idx = torch.arange(k)
    fig, axes = plt.subplots(len(models), k, figsize=(2.3 * k, 2.8 * len(models)), squeeze=False)
    for row, (name, model) in enumerate(models.items()):
        model.eval()
        for p in model.parameters():
            p.requires_grad_(False)
        g = torch.Generator().manual_seed(seed)
        echo = "echo" in model.inputs
        if echo:  # log10 envelope / 4: a direct sound at 0, a -60 dB floor
            base = torch.full((k, 1323), -0.75)
            base[:, :40] = 0.0
            bands = torch.zeros(k, 7, 20)
        else:
            base = torch.zeros(k, 62, 25)
        x = (base + 0.01 * torch.randn(base.shape, generator=g)).requires_grad_(True)

        def objective(x):
            """Per class: its logit (log-mel); for an echo model, the log share of the delay
            attention that falls within the class's depth range (the unit the depth is read from)."""
            if not echo:
                return model({"mel": x})["depth_bin"][idx, idx]
            out = model({"envelope": 10 ** (4 * x), "bands": bands})
            logp = torch.log_softmax(out["delay_scores"], dim=1)
            centres = torch.tensor(DEPTH_BINS_M)[:, None]
            inside = (out["depth_at"][None] - centres).abs() <= 0.25
            return torch.logsumexp(logp.masked_fill(~inside, -1e4), dim=1)

        opt = torch.optim.Adam([x], lr=0.02)
        for _ in range(steps):
            rough = (x[..., 1:] - x[..., :-1]).pow(2).sum()
            loss = -objective(x).sum() + 0.02 * (x - base).pow(2).sum() + (0.5 if echo else 0.05) * rough
            opt.zero_grad()
            loss.backward()
            opt.step()
        for p in model.parameters():
            p.requires_grad_(True)
        with torch.no_grad():
            probs = torch.exp(objective(x)) if echo else torch.softmax(model({"mel": x})["depth_bin"], 1)[idx, idx]
        a = x.detach().numpy()
        for c, ax in enumerate(axes[row]):
            title = f"{DEPTH_BINS_M[c]:g} m class ({'attention' if echo else 'p'}={probs[c]:.2f})"
            if echo:
                travel = SPEED_OF_SOUND * np.arange(a.shape[1]) / FS  # emitter -> surface -> microphone
                ax.plot(np.sqrt(np.maximum(travel ** 2 - MIC_ABOVE_EMITTER_M ** 2, 0)) / 2, 80 * a[c], lw=0.7)
                ax.axvspan(DEPTH_BINS_M[c] - 0.25, DEPTH_BINS_M[c] + 0.25, color="r", alpha=0.2)
                ax.set_xlim(0, 3.5)
                ax.set_xlabel("echo distance (m)", fontsize=7)
                if c == 0:
                    ax.set_ylabel(f"{name}\nenvelope (dB)", fontsize=7)
            else:
                lim = np.abs(a).max()
                ax.imshow(a[c], origin="lower", aspect="auto", cmap="RdBu_r", vmin=-lim, vmax=lim, extent=(0, 1000, 0, 62))
                ax.set_xlabel("time (ms)", fontsize=7)
                if c == 0:
                    ax.set_ylabel(f"{name}\nmel band", fontsize=7)
            ax.set_title(title, fontsize=8)
            ax.tick_params(labelsize=6)
    fig.suptitle("Depth head, activation maximisation: the input that most excites each depth class", fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return Path(path)
