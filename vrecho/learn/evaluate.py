"""The benchmark harness: every method of PROTOCOL.md trained and judged on the same data in one
run (the paper's tables, confusion matrices and the activation-maximisation figure are drawn by
:mod:`.report`).

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

import copy
import json
import pickle
import time
from dataclasses import dataclass
from functools import partial
from pathlib import Path

import numpy as np
import torch  # this module trains and judges models: torch is what it is for
from scipy.signal import resample_poly
from tqdm import tqdm

from ..classifier import read_bundle
from ..errors import VrechoError, check_count, read_json
from ..features import echo_features, self_features
from ..io import OutputFolder, atomic_write_text, ensure_writable_dir
from ..models import HEADS, EchoCNN, FeatureBaseline, build
from . import cluster
from .datasets import open_dataset
from .devices import device_inputs, judge_devices, load_devices_manifest, open_temperature
from .report import activation_maximisation, confusion_figures, write_tables
from .train import fit, metrics, predict_batches, targets


@dataclass(frozen=True)
class Method:
    """One row of the tables: a model kind, its inputs and the protocol it is judged under.

    Attributes
    ----------
    name : str
    kind : {"cnn", "knn", "svm"}
        An :class:`~vrecho.models.EchoCNN`, or a :class:`~vrecho.models.FeatureBaseline`.
    inputs : tuple of str
        ``mel``, ``image``, ``wave``, ``echo``; ``envelope`` and ``bands`` for a baseline.
    protocol : {"paper", "product"}
    fusion : {"concat", "mfb"}
    wave_layers : {5, 8}
    max_epochs : int, optional
        A cap below the run's epochs (the slow raw-waveform baselines).
    echo_channels : int
        Channels of the echo branch's convolutions (:class:`~vrecho.models.EchoBranch`).
    """

    name: str
    kind: str  # "cnn", "knn" or "svm"
    inputs: tuple[str, ...]
    protocol: str = "paper"
    fusion: str = "concat"
    wave_layers: int = 8
    max_epochs: int | None = None  # a cap below the run's epochs (the slow raw-waveform baselines)
    echo_channels: int = 24

    @property
    def slug(self) -> str:
        """The name in lower case, its other characters ``_``: the model's file name."""
        return "".join(c if c.isalnum() else "_" for c in self.name.lower()).strip("_")

    def model(self) -> EchoCNN:
        """A new, untrained EchoCNN of this method's inputs, fusion, SoundNet depth and echo
        branch's width.

        Returns
        -------
        EchoCNN
        """
        return EchoCNN(self.inputs, fusion=self.fusion, wave_layers=self.wave_layers, echo_channels=self.echo_channels)

    def path(self, run) -> Path:
        """Where a run folder keeps this method's trained model.

        Parameters
        ----------
        run : str or path

        Returns
        -------
        pathlib.Path
            ``run/models/<slug>.pt`` (a CNN) or ``.pkl`` (a baseline).
        """
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
    Method("EchoCNN-A self-ref", "cnn", ("self",)),
    Method("EchoCNN-AV self-ref", "cnn", ("self", "image")),
    Method("EchoCNN-E", "cnn", ("echo",), protocol="product", echo_channels=16),
    Method("EchoCNN-EV", "cnn", ("echo", "image"), protocol="product", echo_channels=16),
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
    """The method of :data:`METHODS` with this name or slug.

    Parameters
    ----------
    name : str

    Returns
    -------
    Method

    Raises
    ------
    VrechoError
        When no method has this name or slug.
    """
    for m in METHODS:
        if m.name == name or m.slug == name:
            return m
    raise VrechoError(f"method: expected one of {', '.join(m.name for m in METHODS)}; got {name!r}")


class Frames:
    """The frames of one protocol and split, with every input any method asks for, loaded once.

    Parameters
    ----------
    ds : Dataset
    protocol : {"paper", "product"}
    split : {"train", "val", "test"}
    seed : int
        Seeds the product protocol's probes and recording conditions.
    progress : bool

    Raises
    ------
    VrechoError
        For an unknown protocol.
    """

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

    def shard(self, index: int, count: int) -> "Frames":
        """Every ``count``-th frame from ``index``: one worker's share (:mod:`.cluster`), read
        from the store alone (the product protocol's rendered frames are rendered whole, then
        shared out).

        Parameters
        ----------
        index, count : int
            The worker's rank and the number of workers.

        Returns
        -------
        Frames
        """
        part = copy.copy(self)
        if self.protocol == "product":
            self._audio()
            part.audio, part.emitted = self.audio[index::count], self.emitted[index::count]
        part.rows, part.group = self.rows[index::count], self.group[index::count]
        part.y = {k: v[index::count] for k, v in self.y.items()}
        part._x = {k: v[index::count] for k, v in self._x.items()}
        return part

    def _audio(self) -> np.ndarray:
        if self.audio is None and self.protocol == "product":
            self.audio, self.emitted, _, _ = self.ds.probe_frames(self.split, self.probes, seed=self.seed, progress=self.progress)
        elif self.audio is None:
            self.audio = _read_rows(self.ds.audio, self.rows).astype(np.float32)
        return self.audio

    def inputs(self, keys) -> dict[str, torch.Tensor]:
        """Tensors for the given input names (``echo`` means ``envelope`` and ``bands``).

        Parameters
        ----------
        keys : iterable of {"mel", "image", "wave", "echo", "envelope", "bands", "self", "self_envelope", "self_bands"}
            ``self`` means ``self_envelope`` and ``self_bands``.

        Returns
        -------
        dict of str to torch.Tensor
            ``mel`` (N, 62, 25), ``image`` (N, 64, 25) in [0, 1], ``wave`` (N, 11025) at
            11.025 kHz, ``envelope`` (N, 1323) and ``bands`` (N, 7, 20) (echo features, the
            emitted sound known), ``self_envelope`` and ``self_bands`` (the same from the
            recording alone, :func:`~vrecho.features.self_features`); all float32.

        Raises
        ------
        VrechoError
            For echo features under the paper protocol (no emitted sound), or an unknown name.
        """
        pairs = {"echo": ("envelope", "bands"), "self": ("self_envelope", "self_bands")}
        names = [k for key in keys for k in pairs.get(key, (key,))]
        for name in names:
            if name in self._x:
                continue
            if name == "mel":
                self._x[name] = torch.as_tensor(_read_rows(self.ds.logmel, self.rows))
            elif name == "image":
                self._x[name] = torch.as_tensor(_read_rows(self.ds.image, self.rows), dtype=torch.float32) / 255
            elif name == "wave":  # the SoundNet baselines' 11.025 kHz
                self._x[name] = torch.as_tensor(resample_poly(self._audio(), 1, 4, axis=1).astype(np.float32))
            elif name in ("envelope", "bands", "self_envelope", "self_bands"):
                own = name.startswith("self_")
                if not own and self.protocol != "product":
                    raise VrechoError("echo features need the emitted sound: use the product protocol")
                env, bands = [], []
                for i in tqdm(range(0, len(self), 256), desc="self-referenced echoes" if own else "echo features",
                              disable=not self.progress, leave=False):
                    part = self._audio()[i:i + 256]
                    f = self_features(part) if own else echo_features(part, self.emitted[i:i + 256])
                    env.append(f.envelope)
                    bands.append(f.bands)
                prefix = "self_" if own else ""
                self._x[prefix + "envelope"] = torch.as_tensor(np.concatenate(env))
                self._x[prefix + "bands"] = torch.as_tensor(np.concatenate(bands))
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
    """Frames of every protocol and split, loaded on demand and shared by the methods.

    Parameters
    ----------
    data : str or path
    seed : int
    progress : bool

    Raises
    ------
    VrechoError
        When ``data`` holds no finished dataset.
    """

    def __init__(self, data, *, seed: int = 0, progress: bool = True):
        self.ds = open_dataset(data)
        self.seed, self.progress = seed, progress
        self._frames: dict[tuple[str, str], Frames] = {}

    def frames(self, protocol: str, split: str) -> Frames:
        """The :class:`Frames` of a protocol and split (made on first use, then kept).

        Parameters
        ----------
        protocol : {"paper", "product"}
        split : {"train", "val", "test"}

        Returns
        -------
        Frames
        """
        key = (protocol, split)
        if key not in self._frames:
            self._frames[key] = Frames(self.ds, protocol, split, seed=self.seed, progress=self.progress)
        return self._frames[key]


def train_methods(data, out, *, methods=None, seed: int = 0, epochs: int = 40, patience: int = 6,
                  progress: bool = True, force: bool = False, ray: str | None = None, workers: int = 1,
                  gpus_per_worker: float = 0.0, devices=None, base=None) -> dict[str, dict]:
    """Train every method (or those named) on a dataset, resumably, into the run folder ``out``.

    A method already trained is skipped. When the methods of :data:`SHIPPED` are all trained (or
    some, with ``base``), writes ``classifier.pt`` (the classifier's weights).

    Parameters
    ----------
    data, out : str or path
        The dataset folder, and the run folder: empty, or a run of the same dataset and seed.
    methods : list of str, optional
        Names or slugs of :data:`METHODS` (default: all).
    seed : int
        Seeds the weights, the shuffling and the product protocol's frames.
    epochs, patience : int
        Most epochs per CNN (default 40; a method's ``max_epochs`` caps it), and epochs without
        improvement before stopping (default 6); each 1 to 10000.
    progress : bool
    force : bool
        Train into an ``out`` that holds files training did not write (not another run).
    ray : str, optional
        Train the CNNs with Ray Train on ``workers`` workers (:func:`.cluster.fit_on_ray`):
        ``"auto"`` (a local cluster) or a cluster's address; ``data`` and ``out`` on folders
        every node sees. The baselines train here, on one process. Ray Train's checkpoints go
        to ``out/ray/``.
    workers : int
        Ray Train workers, 1 to 1024 (default 1; only with ``ray``).
    gpus_per_worker : float
        GPUs per Ray Train worker, 0 to 8 (default 0; only with ``ray``).
    devices : str or path, optional
        A folder of other devices' echo frames (:func:`.devices.generate_devices`), added to the
        training and validation frames of the product protocol's CNNs without a camera image
        (EchoCNN-E): the loudspeakers, microphones and heights of the operating envelope, not
        the reference device's alone. Not with ``ray``.
    base : str or path, optional
        A classifier bundle (``classifier.pt``, or the package's ``vrecho/assets/echocnn.pt``)
        whose models ``classifier.pt`` takes where a method of :data:`SHIPPED` is not trained
        in ``out``: one model retrained, the others as shipped.

    Returns
    -------
    dict of str to dict
        Per method trained in ``out``, its record: ``seconds``, ``seed``, ``n_train``, ``n_val``,
        ``protocol``; for a CNN also ``epochs``, ``best_epoch`` (from 0) and ``val_loss``.

    Raises
    ------
    VrechoError
        For an unknown method, a seed, ``epochs`` or ``patience`` out of range, a missing or
        unfinished dataset or devices folder, ``devices`` with ``ray``, or an unwritable or
        foreign ``out``.
    """
    check_count(seed, "seed", 2**32 - 1, 0)
    check_count(epochs, "epochs", 10000)
    check_count(patience, "patience", 10000)
    workers, gpus_per_worker = cluster.scaling(ray, workers, gpus_per_worker)
    out = ensure_writable_dir(out)
    chosen = [method(m) for m in methods] if methods else list(METHODS)
    harness = Harness(data, seed=seed, progress=progress)
    m = harness.ds.manifest
    identity = {"format": "vrecho-run", "dataset": {k: m[k] for k in ("preset", "seed", "n_frames")}, "seed": seed}
    if devices is not None:
        if ray is not None:
            raise VrechoError("devices: not with ray (the device frames are read here)")
        dm = load_devices_manifest(devices)
        identity["devices"] = {k: dm[k] for k in ("seed", "n_frames")}
    run_path = out / "run.json"
    if run_path.exists():
        old = read_json(run_path, "run", expect=dict)
        if old != identity:
            raise VrechoError(f"out: {out} holds models of another dataset or seed ({old.get('dataset')}, seed "
                              f"{old.get('seed')}); choose another folder")
    elif any(out.iterdir()) and not force:
        raise VrechoError(f"out: {out} is not empty and holds no vrecho run; choose an empty folder, "
                          "or pass --force to train beside its files")
    atomic_write_text(run_path, json.dumps(identity, indent=1))
    (out / "models").mkdir(exist_ok=True)
    records_path = out / "training.json"
    records = read_json(records_path, "training records", expect=dict) if records_path.exists() else {}
    for m in chosen:
        path = m.path(out)
        if m.name in records and path.exists():
            continue
        tr, va = harness.frames(m.protocol, "train"), harness.frames(m.protocol, "val")
        start = time.time()
        if m.kind == "cnn" and ray is not None:
            load = partial(_share, partial(Harness, Path(harness.ds.path).resolve(), seed=seed, progress=False), m)
            model, h = cluster.fit_on_ray(ray, name=m.slug, model=m.model, load=load, seed=seed,
                                          epochs=min(epochs, m.max_epochs or epochs), patience=patience,
                                          workers=workers, gpus_per_worker=gpus_per_worker, storage_path=out / "ray")
            torch.save({"config": model.config, "state": model.state_dict()}, path)
            rec = {"epochs": h.epochs, "best_epoch": h.best_epoch, "val_loss": round(h.best_val_loss, 4),
                   "seconds": round(h.seconds, 1), "ray_workers": workers}
        elif m.kind == "cnn":
            torch.manual_seed(seed)
            model = m.model()
            (x_tr, y_tr), (x_va, y_va) = (tr.inputs(m.inputs), tr.y), (va.inputs(m.inputs), va.y)
            if devices is not None and m.protocol == "product" and "image" not in m.inputs:
                more = device_inputs(devices, progress=progress)
                x_tr, y_tr = _joined(x_tr, y_tr, *more["train"])
                x_va, y_va = _joined(x_va, y_va, *more["val"])
            h = fit(model, x_tr, y_tr, x_va, y_va,
                    epochs=min(epochs, m.max_epochs or epochs), patience=patience,
                    seed=seed, checkpoint=path.with_suffix(".ckpt"), progress=progress, desc=m.name)
            if len(y_tr["open"]) > len(tr):  # other devices heard: their validation frames calibrate open/closed
                model.config["open_temperature"] = open_temperature(model, *more["val"])
            torch.save({"config": model.config, "state": model.state_dict()}, path)
            rec = {"epochs": h.epochs, "best_epoch": h.best_epoch, "val_loss": round(h.best_val_loss, 4),
                   "seconds": round(h.seconds, 1)}
            if len(y_tr["open"]) > len(tr):
                rec["device_frames"] = [len(y_tr["open"]) - len(tr), len(y_va["open"]) - len(va)]
                rec["open_temperature"] = model.config["open_temperature"]
        else:
            est = FeatureBaseline(m.kind, m.inputs).fit(tr.inputs(m.inputs), tr.y)
            path.write_bytes(pickle.dumps(est))
            rec = {"seconds": round(time.time() - start, 1)}
        rec.update(seed=seed, n_train=len(tr), n_val=len(va), protocol=m.protocol)
        records[m.name] = rec
        atomic_write_text(records_path, json.dumps(records, indent=1))
    if all(name in records for name in SHIPPED.values()) or (
            base is not None and any(name in records for name in SHIPPED.values())):
        export_classifier(out, out / "classifier.pt", base=base)
    return records


def _joined(x: dict, y: dict, x2: dict, y2: dict) -> tuple[dict, dict]:
    """Two sets of frames' inputs and targets, one after the other (the inputs both have)."""
    return ({k: torch.cat([x[k], x2[k]]) for k in x}, {k: torch.cat([y[k], y2[k]]) for k in y})


def _share(harness, m: Method, rank: int, workers: int):
    """A Ray Train worker's share of a method's frames (:func:`.cluster.fit_on_ray`'s ``load``):
    every ``workers``-th training frame from ``rank``, read from the dataset's store alone, the
    same count on every worker; the whole validation split."""
    h = harness()
    train, val = h.frames(m.protocol, "train"), h.frames(m.protocol, "val")
    n = len(train) // workers
    train = train.shard(rank, workers)
    x = {k: v[:n] for k, v in train.inputs(m.inputs).items()}
    return x, {k: v[:n] for k, v in train.y.items()}, val.inputs(m.inputs), val.y


def load_method(run, m: Method):
    """A method's trained model from a run folder.

    Parameters
    ----------
    run : str or path
    m : Method

    Returns
    -------
    EchoCNN or FeatureBaseline
        A CNN in evaluation mode, or the fitted baseline.

    Raises
    ------
    VrechoError
        When ``m`` is not trained in ``run``.
    """
    path = m.path(run)
    if not path.exists():
        raise VrechoError(f"{run}: {m.name} is not trained (no {path.name}); run `vrecho train` first")
    if m.kind != "cnn":
        return pickle.loads(path.read_bytes())
    saved = torch.load(path, weights_only=True)
    model = build(saved["config"])
    model.load_state_dict(saved["state"])
    return model.eval()


def export_classifier(run, path, *, base=None) -> Path:
    """Bundle the shipped methods' weights (float16, a few MB) into one file for the classifier.

    Parameters
    ----------
    run : str or path
        A run folder holding every method of :data:`SHIPPED` (or some, with ``base``).
    path : str or path
        The bundle's file (written atomically; it may be ``base`` itself).
    base : str or path, optional
        A bundle whose models are taken where ``run`` lacks a method of :data:`SHIPPED`.

    Returns
    -------
    pathlib.Path

    Raises
    ------
    VrechoError
        When a method of :data:`SHIPPED` is not trained in ``run`` (and ``base`` is None), or
        ``base`` is not a vrecho classifier.
    """
    bundle = {}
    kept = read_bundle(base)["models"] if base is not None else {}
    for key, name in SHIPPED.items():
        if key in kept and not method(name).path(run).exists():
            bundle[key] = kept[key]
            continue
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


def evaluate(data, run, out, *, seed: int = 0, progress: bool = True, methods=None,
             force: bool = False, devices=None) -> dict[str, dict]:
    """Judge every trained method on the test frames; write tables (Markdown and CSV), confusion
    matrices and the activation-maximisation figure into ``out``.

    Parameters
    ----------
    data, run, out : str or path
        The dataset, the run (:func:`train_methods`) and the output folder (created if missing).
    seed : int
        Seeds the product protocol's test probes.
    progress : bool
    methods : list of str, optional
        Names or slugs of :data:`METHODS` (default: every method trained in ``run``).
    force : bool
        Write into an ``out`` that holds files evaluation did not write (the policy of
        :class:`vrecho.io.OutputFolder`: its files appear at once, when all are written).
    devices : str or path, optional
        A devices folder of every condition (``vrecho generate --preset devices --conditions
        all``, a seed no training used): EchoCNN-E judged on it per condition, with and without
        the surface's distance, and EchoCNN-A, the probe unknown (:func:`.devices.judge_devices`),
        their tables in ``tables.md``.

    Returns
    -------
    dict of str to dict
        Per method, :func:`vrecho.learn.train.metrics` on its test frames, with
        ``seconds_per_frame`` and ``by_group`` (the same metrics per test sound or probe); with
        ``devices``, EchoCNN-E's and EchoCNN-A's also ``devices`` (per condition).

    Raises
    ------
    VrechoError
        For an unknown or untrained method, none trained in ``run``, a bad dataset, devices
        folder or ``out``, or ``devices`` where neither EchoCNN-E nor EchoCNN-A is judged.
    """
    if devices is not None:
        load_devices_manifest(devices)  # before anything is judged: one clear line
    with OutputFolder(out, "evaluate", force=force) as folder:
        return _evaluate(data, run, folder, seed, progress, methods, devices)


def _evaluate(data, run, folder: OutputFolder, seed: int, progress: bool, methods, devices=None) -> dict[str, dict]:
    harness = Harness(data, seed=seed, progress=progress)
    chosen = [method(m) for m in methods] if methods else [m for m in METHODS if _trained(run, m)]
    if not chosen:
        raise VrechoError(f"{run}: no trained methods; run `vrecho train --data {data} --out {run}` first")
    if devices is not None and not {"EchoCNN-E", "EchoCNN-A"} & {m.name for m in chosen}:
        raise VrechoError("devices: neither EchoCNN-E nor EchoCNN-A is judged here (train one, or name it with --method)")
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
        if devices is not None and m.name in ("EchoCNN-E", "EchoCNN-A"):
            res["devices"] = judge_devices(model, devices, seed=seed, emitted=m.name == "EchoCNN-E")
        results[m.name], outputs[m.name] = res, o
    meta = {"seed": seed, "data": str(data), "n": {p: {s: len(harness.frames(p, s)) for s in ("train", "val", "test")}
                                                   for p in sorted({m.protocol for m in chosen})}}
    meta["devices"] = None if devices is None else str(devices)
    shown = {m.name: load_method(run, m) for m in chosen if m.name in ("EchoCNN-A", "EchoCNN-E")}
    with folder.writing() as out:
        write_tables(results, chosen, meta, out)
        confusion_figures(outputs, chosen, harness, out)
        if shown:
            activation_maximisation(shown, out / "activation_maximisation_depth.png")
        atomic_write_text(out / "metrics.json", json.dumps({"meta": meta, "results": results}, indent=1))
    return results


def _trained(run, m: Method) -> bool:
    return m.path(run).exists()


