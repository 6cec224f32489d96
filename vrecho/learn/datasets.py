"""Datasets: generation in parallel, storage, splits.

A dataset folder holds::

    manifest.json     preset, seed, counts, splits; "complete": true once every scene is in
    scenes/           one scene JSON per room (scene_0000.json, ...)
    frames.zarr/      Zarr v3 arrays, openable with zarr alone:
                        audio  (N, 44100) float16   1 s microphone frames from the pulse onset
                        logmel (N, 62, 25) float32  the paper's normalised log-mel spectrograms
                        image  (N, 64, 25) uint8    camera crop around the faced discontinuity
                        ir     (R, 44100) float32   the simulated impulse responses (for any probe)
    labels.csv        one row per frame (columns in LABEL_COLUMNS)
    progress/         one CSV per finished scene: the resume markers

Each room is one unit of work: its impulse responses are simulated once (image sources plus ray
tracing, cached) and convolved with all 16 sounds. Rows of a scene are written to ``progress/``
only after its arrays are, and ``labels.csv`` and ``complete`` only once every scene is done, so
an interrupted run loses nothing finished and a rerun does only what is missing.

Splits are by room (PROTOCOL.md's benchmark protocol): rooms are ``train``, ``val`` or ``test``;
every frame of every sound is stored, and the paper's protocol takes train sounds in train rooms
and held-out sounds in test rooms (:meth:`Dataset.paper_split`).
"""

from __future__ import annotations

import csv
import io
import json
import multiprocessing
import os
import signal
import time
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
from threadpoolctl import threadpool_limits
from tqdm import tqdm

from ..errors import VrechoError, check_count, read_json
from . import cluster
from ..features import logmel
from ..io import atomic_write_text, ensure_writable_dir
from ..scene import load_scene
from ..signals import FS, SOUNDS, TRAIN_SOUNDS, emitted_sound, probe, random_probe
from ..sim.acoustics import (device_direct_amplitude, device_impulse_response, direct_amplitude, impulse_responses,
                             record_pulse, record_source, recording_conditions)
from ..sim.render import World, crop
from ..sim.scenes import random_scene

FORMAT_VERSION = 1
LABEL_COLUMNS = ("frame", "scene", "split", "kind", "pose", "ir", "sound", "heard", "sound_seed", "surface",
                 "is_open", "material", "depth_m", "incidence_deg", "src_x", "src_y", "src_z", "onset_s",
                 "snr_db", "self_noise_db", "gain_db")
"""``kind`` is ``echo`` (the device hears its own pulse off the surface it faces: ``surface``,
``is_open``, ``material``, ``depth_m``) or ``source`` (an ambient source plays the sound once,
``onset_s`` into the frame, at ``src_x, src_y, src_z`` metres in the device frame: forward, left,
up from the emitter). Missing values are -1, empty or nan."""


@dataclass(frozen=True)
class Preset:
    """A dataset's size.

    Attributes
    ----------
    n_scenes : int
        Rooms.
    n_poses : int
        Device poses per room, each facing a discontinuity (echo frames).
    n_sources : int
        Ambient sources per room (source frames).
    split : tuple of float
        Share of rooms for train, val and test.
    """

    n_scenes: int
    n_poses: int
    n_sources: int
    split: tuple[float, float, float]  # share of rooms for train, val, test


PRESETS = {
    "tiny": Preset(n_scenes=6, n_poses=3, n_sources=1, split=(4 / 6, 1 / 6, 1 / 6)),
    "small": Preset(n_scenes=16, n_poses=8, n_sources=2, split=(0.75, 0.125, 0.125)),
    "default": Preset(n_scenes=160, n_poses=8, n_sources=2, split=(0.7, 0.1, 0.2)),
}


def _splits(preset: Preset, seed: int) -> list[str]:
    n = preset.n_scenes
    n_val = max(1, int(round(preset.split[1] * n)))
    n_test = max(1, int(round(preset.split[2] * n)))
    names = ["train"] * (n - n_val - n_test) + ["val"] * n_val + ["test"] * n_test
    order = np.random.default_rng([seed, 7919]).permutation(n)
    return [names[k] for k in np.argsort(order)]


def _block(preset: Preset) -> int:
    return (preset.n_poses + preset.n_sources) * len(SOUNDS)


def _scene_rows(out: Path, index: int, preset_name: str, seed: int, split: str, cache) -> list[dict]:
    """Simulate one room, write its arrays and return its label rows; BLAS on one thread, so
    that the arrays are the same bit for bit whatever runs it (a process of the pool, the
    driver, a Ray task: the log-mel's matrix product rounds by the threads' split)."""
    with threadpool_limits(1):
        return _scene_rows_here(out, index, preset_name, seed, split, cache)


def _scene_rows_here(out: Path, index: int, preset_name: str, seed: int, split: str, cache) -> list[dict]:
    import zarr  # heavy (0.5 s to import): only the dataset's arrays need it

    preset = PRESETS[preset_name]
    rng = np.random.default_rng([seed, index])
    scene = random_scene(rng, f"scene_{index:04d}", n_poses=preset.n_poses, n_sources=preset.n_sources)
    scene.save(out / "scenes" / f"scene_{index:04d}.json")
    world = World(scene)
    n_irs = preset.n_poses + preset.n_sources
    audio = np.zeros((_block(preset), FS), np.float32)
    images = np.zeros((_block(preset), 64, 25), np.uint8)
    irs = np.zeros((n_irs, FS), np.float32)
    rows = []
    base = index * _block(preset)
    crops = [crop(world, pose) for pose in scene.poses]  # source frames reuse their pose's crop
    for k in range(n_irs):
        is_echo = k < preset.n_poses
        pose = scene.poses[k % preset.n_poses]
        image = crops[k % preset.n_poses]
        if is_echo:
            ir = device_impulse_response(scene, pose, cache=cache)[0]
            disc = scene.discontinuities[pose.target]
            label = {"surface": pose.target, "is_open": int(disc.is_open), "material": disc.material or "",
                     "depth_m": round(scene.depth_m(pose), 5), "incidence_deg": round(scene.incidence_deg(pose), 3),
                     "src_x": np.nan, "src_y": np.nan, "src_z": np.nan}
        else:
            src = scene.sources[k - preset.n_poses]
            ir = impulse_responses(scene, src.position, pose.microphone[None], cache=cache)[0]
            rel = pose.rotation.T @ (np.asarray(src.position) - pose.emitter)
            label = {"surface": -1, "is_open": -1, "material": "", "depth_m": np.nan, "incidence_deg": np.nan,
                     "src_x": round(rel[0], 5), "src_y": round(rel[1], 5), "src_z": round(rel[2], 5)}
        irs[k] = ir
        for j, name in enumerate(SOUNDS):
            row = len(rows)
            sound_seed = int(rng.integers(2 ** 31))
            sound = emitted_sound(name, FS, np.random.default_rng(sound_seed))
            snr, self_noise, gain = recording_conditions(rng)
            if is_echo:
                onset = np.nan
                x = record_pulse(ir, sound, device_direct_amplitude(scene, pose), rng, snr, self_noise, gain)
            else:
                onset = rng.uniform(0, 0.1)
                x = record_source(ir, sound, onset, direct_amplitude(np.linalg.norm(pose.microphone - src.position)),
                                  rng, FS, snr, self_noise, gain + src.gain_db)
            audio[row] = x
            images[row] = image
            rows.append({"frame": base + row, "scene": index, "split": split, "kind": "echo" if is_echo else "source",
                         "pose": k % preset.n_poses, "ir": index * n_irs + k, "sound": name,
                         "heard": int(name in TRAIN_SOUNDS), "sound_seed": sound_seed, **label,
                         "onset_s": round(onset, 6), "snr_db": round(snr, 3), "self_noise_db": round(self_noise, 3),
                         "gain_db": round(gain, 3)})
    root = zarr.open_group(out / "frames.zarr", mode="r+")
    sl = slice(base, base + len(rows))
    root["audio"][sl] = audio.astype(np.float16)
    root["image"][sl] = images
    root["logmel"][sl] = logmel(audio)
    root["ir"][index * n_irs:(index + 1) * n_irs] = irs
    _write_rows(out / "progress" / f"scene_{index:04d}.csv", rows)
    return rows


def _write_rows(path: Path, rows: list[dict]) -> None:
    buf = io.StringIO()
    w = csv.DictWriter(buf, LABEL_COLUMNS, lineterminator="\n")
    w.writeheader()
    w.writerows(rows)
    atomic_write_text(path, buf.getvalue())


def worker_init() -> None:
    """Set up a process of a generation pool (rooms here, device frames in :mod:`.devices`).

    One process per core does the parallel work: libraries loaded after this (open3d's OpenMP,
    numba under librosa) stay single-threaded; NumPy is already loaded, and its FFTs are anyway.
    Ctrl-C is left to the driver.
    """
    for var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
        os.environ[var] = "1"
    # Ctrl-C reaches every process of the terminal's group: the driver alone answers it (one line,
    # the running rooms finished and kept), not each worker with a traceback.
    signal.signal(signal.SIGINT, signal.SIG_IGN)


def generate(out: str | Path, *, preset: str = "tiny", seed: int = 0, workers: int | None = None,
             cache: str | Path | None = None, progress: bool = True, force: bool = False,
             ray: str | None = None) -> Path:
    """Generate (or finish) a dataset in ``out``.

    Resumable: a rerun does only the rooms not yet finished; a complete dataset is returned as
    it is.

    Parameters
    ----------
    out : path
        Dataset folder; created if missing. A folder holding another preset or seed is refused.
    preset : {"tiny", "small", "default"}
        ``tiny``: 6 rooms, 4 poses or sources each, 16 sounds (384 frames), for tests.
        ``small``: 16 rooms as ``default``'s (2 560 frames), for benchmarks and quick trials.
        ``default``: 160 rooms, 8 poses and 2 sources each (20 480 echo and 5 120 source frames).
    seed : int
        Everything (rooms, poses, sounds, noise, ray tracing) follows from it.
    workers : int, optional
        Processes; one per core by default.
    cache : path, optional
        Impulse-response cache folder (default: :func:`vrecho.sim.acoustics.default_cache_dir`).
    progress : bool
        Show a progress bar.
    force : bool
        Generate into an ``out`` that holds other files (not another dataset) beside them.
    ray : str, optional
        Run the rooms as Ray tasks (:mod:`vrecho.learn.cluster`): ``"auto"`` on a local cluster
        started here, or a running cluster's address; ``out`` and ``cache`` must be folders
        every node sees. The same arrays as without, bit for bit; ``workers`` is then unused.

    Returns
    -------
    pathlib.Path
        The dataset folder.

    Raises
    ------
    VrechoError
        For an unknown preset, a seed not a whole number from 0 to 2**32 - 1, fewer than 1 or more than 256
        workers, an ``out`` that cannot be written, or one that holds another dataset or (without
        ``force``) other files; with ``ray``, where Ray is not installed, no cluster answers, or
        rooms failed after Ray's retries (the others kept).
    """
    import zarr  # heavy (0.5 s to import): only the dataset's arrays need it

    if preset not in PRESETS:
        raise VrechoError(f"preset: expected one of {tuple(PRESETS)}, got {preset!r}")
    seed = check_count(seed, "seed", 2**32 - 1, 0)
    workers = (os.cpu_count() or 1) if workers is None else workers
    check_count(workers, "workers", 256)
    if ray is not None:
        cluster.connect(ray)  # before anything is written: Ray missing or no cluster there is one line
    out = ensure_writable_dir(out)
    p = PRESETS[preset]
    manifest_path = out / "manifest.json"
    identity = {"format": "vrecho-dataset", "version": FORMAT_VERSION, "preset": preset, "seed": int(seed)}
    if manifest_path.exists():
        old = read_json(manifest_path, "dataset manifest", expect=dict)
        if {k: old.get(k) for k in identity} != identity:
            raise VrechoError(f"out: {out} holds another dataset ({old.get('preset')}, seed {old.get('seed')}); "
                              "choose an empty folder")
        if old.get("complete"):
            return out
    elif any(out.iterdir()) and not force:
        raise VrechoError(f"out: {out} is not empty and holds no vrecho dataset; choose an empty folder, "
                          "or pass --force to generate beside its files")
    splits = _splits(p, seed)
    n_frames = p.n_scenes * _block(p)
    n_irs = p.n_scenes * (p.n_poses + p.n_sources)
    manifest = {**identity, "complete": False, "preset_settings": asdict(p), "fs": FS, "sounds": list(SOUNDS),
                "train_sounds": list(TRAIN_SOUNDS), "n_frames": n_frames, "n_irs": n_irs,
                "scene_splits": splits}
    atomic_write_text(manifest_path, json.dumps(manifest, indent=1))
    (out / "scenes").mkdir(exist_ok=True)
    (out / "progress").mkdir(exist_ok=True)
    root = zarr.open_group(out / "frames.zarr", mode="a")
    block = len(SOUNDS)  # one chunk per impulse response: a scene always writes whole chunks
    for name, shape, chunks, dtype in (("audio", (n_frames, FS), (block, FS), "float16"),
                                       ("logmel", (n_frames, 62, 25), (block, 62, 25), "float32"),
                                       ("image", (n_frames, 64, 25), (block, 64, 25), "uint8"),
                                       ("ir", (n_irs, FS), (1, FS), "float32")):
        if name not in root:
            root.create_array(name, shape=shape, chunks=chunks, dtype=dtype, fill_value=0)
    todo = [i for i in range(p.n_scenes) if not (out / "progress" / f"scene_{i:04d}.csv").exists()]
    start = time.time()
    bar = tqdm(total=p.n_scenes, initial=p.n_scenes - len(todo), unit="room", desc=f"generate {preset}",
               disable=not progress)
    try:
        if ray is not None:
            cluster.run_rooms(ray, _scene_rows, todo, lambda i: (out, i, preset, seed, splits[i], cache),
                              lambda i: bar.update())
        elif workers == 1 or len(todo) <= 1:
            for i in todo:
                _scene_rows(out, i, preset, seed, splits[i], cache)
                bar.update()
        else:
            with ProcessPoolExecutor(workers, mp_context=multiprocessing.get_context("spawn"),
                                     initializer=worker_init) as pool:
                futures = [pool.submit(_scene_rows, out, i, preset, seed, splits[i], cache) for i in todo]
                try:
                    for f in as_completed(futures):
                        f.result()
                        bar.update()
                except BaseException:
                    # Rooms already running finish and are kept; the rest wait for a rerun.
                    pool.shutdown(wait=True, cancel_futures=True)
                    raise
    finally:
        bar.close()
    rows = []
    for i in range(p.n_scenes):
        with open(out / "progress" / f"scene_{i:04d}.csv", newline="") as f:
            rows.extend(csv.DictReader(f))
    _write_rows(out / "labels.csv", rows)
    manifest.update(complete=True, seconds_last_run=round(time.time() - start, 1))
    atomic_write_text(manifest_path, json.dumps(manifest, indent=1))
    return out


class Dataset:
    """A finished dataset folder: arrays (lazy, Zarr) and labels (NumPy columns).

    ``labels[column]`` is a NumPy array per column of :data:`LABEL_COLUMNS`; ``audio``,
    ``logmel``, ``image`` and ``ir`` are Zarr arrays (index them to read). ``len(ds)`` is the
    number of frames.

    Parameters
    ----------
    path : str or path
        The dataset folder (:func:`generate`).

    Attributes
    ----------
    path : pathlib.Path
    manifest : dict
        ``manifest.json``.
    audio : zarr.Array, shape (N, 44100), float16
        1 s microphone frames at 44.1 kHz.
    logmel : zarr.Array, shape (N, 62, 25), float32
    image : zarr.Array, shape (N, 64, 25), uint8
    ir : zarr.Array, shape (R, 44100), float32
        The simulated impulse responses.
    labels : dict of str to numpy.ndarray
        One (N,) column per entry of :data:`LABEL_COLUMNS`.

    Raises
    ------
    VrechoError
        When ``path`` holds no manifest, an unfinished dataset, a manifest of another format
        or version or without its counts, or arrays or labels missing, damaged or of other
        lengths than the manifest's.
    """

    def __init__(self, path: str | Path):
        import zarr  # heavy (0.5 s to import): only the dataset's arrays need it

        self.path = Path(path)
        manifest_path = self.path / "manifest.json"
        if not manifest_path.exists():
            raise VrechoError(f"dataset {self.path}: no manifest.json; not a vrecho dataset")
        m = self.manifest = read_json(manifest_path, "dataset manifest", expect=dict)
        if m.get("format") != "vrecho-dataset" or m.get("version") != FORMAT_VERSION:
            raise VrechoError(f"dataset {self.path}: manifest.json is not a vrecho dataset's of version "
                              f"{FORMAT_VERSION} (format {m.get('format')!r}, version {m.get('version')!r})")
        if not m.get("complete"):
            raise VrechoError(f"dataset {self.path}: unfinished; run `vrecho generate` again to complete it")
        counts = {k: m.get(k) for k in ("n_frames", "n_irs", "seed")}
        settings = m.get("preset_settings")
        if (any(isinstance(v, bool) or not isinstance(v, int) or v < 0 for v in counts.values())
                or m.get("preset") not in PRESETS or not isinstance(settings, dict)
                or not isinstance(settings.get("n_scenes"), int)):
            raise VrechoError(f"dataset {self.path}: manifest.json lacks its preset, seed, preset_settings.n_scenes, "
                              "n_frames or n_irs; regenerate it with `vrecho generate`")
        try:
            root = zarr.open_group(self.path / "frames.zarr", mode="r")
            self.audio, self.logmel, self.image, self.ir = (root["audio"], root["logmel"], root["image"],
                                                            root["ir"])
        except (KeyError, FileNotFoundError, ValueError, TypeError, OSError) as e:
            raise VrechoError(f"dataset {self.path}: frames.zarr is missing or damaged ({type(e).__name__}: {e}); "
                              "regenerate it with `vrecho generate`") from None
        for name, arr, rows in (("audio", self.audio, m["n_frames"]), ("logmel", self.logmel, m["n_frames"]),
                                ("image", self.image, m["n_frames"]), ("ir", self.ir, m["n_irs"])):
            if arr.shape[0] != rows:
                raise VrechoError(f"dataset {self.path}: frames.zarr/{name} has {arr.shape[0]} rows where the "
                                  f"manifest says {rows}; regenerate it with `vrecho generate`")
        self.labels = read_labels(self.path / "labels.csv")
        if len(self.labels["frame"]) != m["n_frames"]:
            raise VrechoError(f"dataset {self.path}: labels.csv has {len(self.labels['frame'])} rows where the "
                              f"manifest says {m['n_frames']} frames; regenerate it with `vrecho generate`")

    def __len__(self) -> int:
        return len(self.labels["frame"])

    def mask(self, split: str | None = None, kind: str | None = "echo", *, heard: bool | None = None) -> np.ndarray:
        """Boolean mask of frames by room split, frame kind and whether the sound is a train sound.

        Parameters
        ----------
        split : {"train", "val", "test"}, optional
            The rooms' split; None for all.
        kind : {"echo", "source"}, optional
            The frames' kind (default ``echo``); None for both.
        heard : bool, optional
            True for the train sounds, False for the held-out ones; None for all.

        Returns
        -------
        numpy.ndarray, shape (N,), bool
        """
        m = np.ones(len(self), bool)
        if split is not None:
            m &= self.labels["split"] == split
        if kind is not None:
            m &= self.labels["kind"] == kind
        if heard is not None:
            m &= self.labels["heard"] == int(heard)
        return m

    def paper_split(self, split: str, kind: str = "echo") -> np.ndarray:
        """PROTOCOL.md's benchmark: train sounds in train/val rooms, held-out sounds in test rooms.

        Parameters
        ----------
        split : {"train", "val", "test"}
        kind : {"echo", "source"}
            Default ``echo``.

        Returns
        -------
        numpy.ndarray, shape (N,), bool
            The frames' mask.
        """
        return self.mask(split, kind, heard=split != "test")

    def echo_ir_rows(self, split: str) -> np.ndarray:
        """One stored frame per echo impulse response of a split (its first), in response order.

        Parameters
        ----------
        split : {"train", "val", "test"}

        Returns
        -------
        numpy.ndarray, shape (R,), int
            Frame indices.
        """
        m = self.mask(split, "echo")
        _, first = np.unique(self.labels["ir"][m], return_index=True)
        return np.where(m)[0][first]

    def probe_frames(self, split: str, probes: tuple[str, ...], *, seed: int = 0, progress: bool = False):
        """The product protocol's frames: each echo impulse response of a split heard with known
        probes, rendered now from the stored responses (noise, self-noise and gain drawn as in
        :func:`generate`).

        Parameters
        ----------
        split : {"train", "val", "test"}
        probes : tuple of {"vrecho", "random"}
            One frame per impulse response and entry: vrecho's own probe, or a random broadband
            probe (:func:`vrecho.signals.random_probe`).
        seed : int
            With the split, seeds the random probes and the recording conditions.
        progress : bool
            Show a progress bar (default False).

        Returns
        -------
        audio : numpy.ndarray, shape (N, 44100), float32
            1 s frames at 44.1 kHz from the emission.
        emitted : numpy.ndarray, shape (N, 4410), float32
            The 100 ms probe each frame emitted.
        rows : numpy.ndarray, shape (N,)
            For each frame, a stored frame of the same impulse response (its labels and image).
        probe_kind : numpy.ndarray of str, shape (N,)

        Raises
        ------
        VrechoError
            When ``probes`` holds an entry other than ``vrecho`` or ``random``.
        """
        if not set(probes) <= {"vrecho", "random"}:
            raise VrechoError(f"probes: expected 'vrecho' or 'random' entries, got {probes!r}")
        L = self.labels
        rows = self.echo_ir_rows(split)
        irs = L["ir"][rows]
        rng = np.random.default_rng([seed, 4099, ["train", "val", "test"].index(split)])
        own = probe()
        audio, emitted, out_rows, kinds = [], [], [], []
        scenes = {}
        for ir_index, row in tqdm(list(zip(irs, rows)), desc=f"probe frames ({split})", unit="ir", disable=not progress):
            ir = np.asarray(self.ir[int(ir_index)], dtype=np.float32)
            scene_index = int(L["scene"][row])
            scene = scenes.setdefault(scene_index, self.scene(scene_index))
            amp = device_direct_amplitude(scene, scene.poses[int(L["pose"][row])])
            for kind in probes:
                sound = own if kind == "vrecho" else random_probe(rng)
                audio.append(record_pulse(ir, sound, amp, rng, *recording_conditions(rng)))
                emitted.append(sound)
                out_rows.append(row)
                kinds.append(kind)
        return (np.asarray(audio, np.float32), np.asarray(emitted, np.float32), np.asarray(out_rows),
                np.asarray(kinds, dtype=str))

    def emitted(self, frame: int) -> np.ndarray:
        """The exact sound emitted for a frame (regenerated from its seed).

        Parameters
        ----------
        frame : int
            The frame's index.

        Returns
        -------
        numpy.ndarray, shape (4410,), float32
            The 100 ms sound at 44.1 kHz.
        """
        return emitted_sound(str(self.labels["sound"][frame]), FS,
                             np.random.default_rng(int(self.labels["sound_seed"][frame])))

    def scene(self, index: int):
        """The room ``index`` of the dataset, as a :class:`~vrecho.scene.Scene` (``scenes/``).

        Parameters
        ----------
        index : int
            The room's index, from 0.

        Returns
        -------
        Scene
        """
        return load_scene(self.path / "scenes" / f"scene_{index:04d}.json")


def read_labels(path: str | Path) -> dict[str, np.ndarray]:
    """``labels.csv`` as a dict of NumPy columns (ints, floats or strings by column).

    Parameters
    ----------
    path : str or path
        The CSV file.

    Returns
    -------
    dict of str to numpy.ndarray
        One (N,) column per entry of :data:`LABEL_COLUMNS`: ``split``, ``kind``, ``sound`` and
        ``material`` str; ``frame``, ``scene``, ``pose``, ``ir``, ``heard``, ``sound_seed``,
        ``surface`` and ``is_open`` int64; the rest float64 (metres, degrees, seconds, dB).

    Raises
    ------
    VrechoError
        For a file that cannot be read, is not UTF-8 CSV, lacks a column or holds a value
        that is not of its column's type.
    """
    try:
        with open(path, newline="", encoding="utf-8") as f:
            rows = list(csv.DictReader(f))
        out = {}
        for col in LABEL_COLUMNS:
            vals = [r[col] for r in rows]
            if col in ("split", "kind", "sound", "material"):
                out[col] = np.array(vals, dtype=str)
            elif col in ("frame", "scene", "pose", "ir", "heard", "sound_seed", "surface", "is_open"):
                out[col] = np.array(vals, dtype=np.int64)
            else:
                out[col] = np.array(vals, dtype=np.float64)
    except (OSError, UnicodeDecodeError, csv.Error, KeyError, ValueError, TypeError) as e:
        what = f"no column {e}" if isinstance(e, KeyError) else f"{type(e).__name__}: {e}"
        raise VrechoError(f"{path}: not a readable labels table ({what}); regenerate the dataset") from None
    return out


def open_dataset(path: str | Path) -> Dataset:
    """Open a finished dataset folder (see :class:`Dataset`).

    Parameters
    ----------
    path : str or path
        The dataset folder.

    Returns
    -------
    Dataset

    Raises
    ------
    VrechoError
        When ``path`` holds no dataset or an unfinished one.
    """
    return Dataset(path)
