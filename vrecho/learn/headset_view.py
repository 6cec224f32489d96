"""Training the headset view's glass/mirror model (:mod:`vrecho.headset.view`): crops of simulated
headsets in front of glass and mirrors in random rooms, EchoCNN's visual branch trained on them.

``python3 -m vrecho.learn.headset_view --data views.npz`` trains the shipped weights again
(``vrecho/assets/headset_view.pt``; the rooms take some 30 minutes to render on 2 cores).
"""

from __future__ import annotations

import argparse
from multiprocessing import get_context
from pathlib import Path

import numpy as np
import torch  # this module trains: torch is what it is for
from tqdm import tqdm

from ..camera import Camera, camera_pose
from ..device import MIC_ABOVE_EMITTER_M
from ..headset.view import WEIGHTS, material_probability, pane_crop, save
from ..models import IGNORE, EchoCNN
from ..sim.render import World, render_view
from ..sim.scenes import random_scene
from . import cluster
from .train import fit

TRAIN_SEED = 31000
"""Training rooms are drawn from this seed up (never the benchmarks' 5000 and 6000)."""


# -- Training data: simulated headsets in front of glass and mirrors ----------------------------------
def headset_views(rng: np.random.Generator, name: str):
    """The crops :func:`~vrecho.headset.view.look` would classify, from one random room.

    The rooms and panes are PROTOCOL.md's (:func:`vrecho.sim.scenes.random_scene`): for each
    glass or mirror that spans a head's height, a few headset poses (up to 6) 0.5 to 3.5 m in
    front of it (head 1.45 to 1.85 m high, facing it within 20 degrees, pitched by up to 8 and
    rolled by up to 5 degrees), cameras 240, 320 or 400 pixels wide of 60 to 110 degrees, the
    echo's distance read to 2 cm (a normal error of 2 cm standard deviation).

    Parameters
    ----------
    rng : numpy.random.Generator
        Draws the room and the poses.
    name : str
        The room's name.

    Yields
    ------
    crop : numpy.ndarray, shape (64, 25), uint8
        The pane's crop (:func:`vrecho.headset.view.pane_crop`).
    is_mirror : bool
        Whether the pane is a mirror (else glass).
    distance_m : float
        The true distance from the loudspeaker to the pane's plane, in metres.
    """
    scene = random_scene(rng, name, n_poses=0, n_sources=0, n_discontinuities=(1, 3))
    room = scene.room
    world = None
    for d in scene.discontinuities:
        if d.kind == "open":
            continue
        u0, u1, z0, z1 = d.bounds()
        top, bottom = min(z1 - 0.1, 1.85), max(z0 + 0.1, 1.45)
        if top <= bottom or u1 - u0 < 0.3:
            continue  # no head's height faces it: the echo ahead would be the wall's
        origin, u, normal = room.wall_frame(d.wall)
        for _ in range(6):
            foot = origin + rng.uniform(u0 + 0.1, u1 - 0.1) * u + [0.0, 0.0, rng.uniform(bottom, top)]
            dist = rng.uniform(0.5, 3.5)
            yaw = np.radians(rng.uniform(-20, 20))
            forward = np.cos(yaw) * normal + np.sin(yaw) * np.cross([0.0, 0.0, 1.0], normal)
            emitter = foot - dist * normal  # the echo's distance is to the plane: the foot stays on the pane
            if not room.contains(emitter[None], margin_m=0.2)[0]:
                continue
            forward = forward + [0.0, 0.0, np.tan(np.radians(rng.uniform(-8, 8)))]
            roll = np.radians(rng.uniform(-5, 5))
            side = np.cross(forward, [0.0, 0.0, 1.0])
            up = np.cos(roll) * np.array([0.0, 0.0, 1.0]) + np.sin(roll) * side / np.linalg.norm(side)
            width = int(rng.choice([240, 320, 400]))
            camera = Camera(width, width * 3 // 4, float(rng.uniform(60, 110)))
            world = world or World(scene)
            view = render_view(world, camera_pose(emitter + [0.0, 0.0, MIC_ABOVE_EMITTER_M], forward, up), camera=camera)
            echo = dist + rng.normal(0.0, 0.02)
            _, crop = pane_crop(view.gray, view.depth, view.intrinsics, echo)
            if crop is not None:
                yield crop, d.kind == "mirror", dist


def _room_views(seed: int) -> list:
    return list(headset_views(np.random.default_rng(seed), f"view_{seed}"))


def make_dataset(n_rooms: int, *, seed: int = TRAIN_SEED, jobs: int = 1, progress: bool = True) -> dict[str, np.ndarray]:
    """Crops of ``n_rooms`` rooms drawn from ``seed`` on (room ``k`` from ``seed + k``, so the
    data do not depend on ``jobs``, the processes that render them).

    Parameters
    ----------
    n_rooms : int
        Random rooms (:func:`headset_views`).
    seed : int
        The first room's seed (default :data:`TRAIN_SEED`).
    jobs : int
        Processes rendering the rooms (default 1).
    progress : bool
        Show a progress bar.

    Returns
    -------
    dict of str to numpy.ndarray
        ``crops`` (N, 64, 25) uint8, ``mirror`` (N,) bool, ``distance_m`` (N,) float in metres,
        ``room`` (N,) int, the room's index from 0.
    """
    seeds = range(seed, seed + n_rooms)
    out = {"crops": [], "mirror": [], "distance_m": [], "room": []}
    with get_context("spawn").Pool(jobs) as pool:
        views = pool.imap(_room_views, seeds)
        for k, room in enumerate(tqdm(views, total=n_rooms, desc="headset views", unit="room", disable=not progress)):
            for crop, mirror, dist in room:
                for key, value in zip(out, (crop, mirror, dist, k)):
                    out[key].append(value)
    return {k: np.asarray(v) for k, v in out.items()}


def train(data: dict[str, np.ndarray], *, epochs: int = 60, seed: int = 0, progress: bool = True, ray: str | None = None,
          workers: int = 1, gpus_per_worker: float = 0.0, checkpoints: Path | None = None) -> tuple[EchoCNN, dict]:
    """EchoCNN's visual branch trained on :func:`make_dataset`'s crops.

    Trained with :func:`vrecho.learn.train.fit` (a tenth of the rooms held out for early
    stopping, patience 8 epochs), its material head alone: the other heads' targets are left out
    (a depth guessed from a picture only distracts it). The training crops are taken both as
    they are and flipped left-right (a pane seen from either side).

    Parameters
    ----------
    data : dict of str to numpy.ndarray
        :func:`make_dataset`'s ``crops``, ``mirror`` and ``room``.
    epochs : int
        Most epochs (default 60).
    seed : int
        Seeds the held-out rooms, the weights and the training.
    progress : bool
        Show a progress bar.
    ray : str, optional
        Train with Ray Train on ``workers`` workers (:func:`.cluster.fit_on_ray`): ``"auto"``
        (a local cluster) or a cluster's address; the crops go through Ray's object store.
    workers : int
        Ray Train workers, 1 to 1024 (with ``ray``; default 1).
    gpus_per_worker : float
        GPUs per worker, 0 to 8 (with ``ray``; default 0).
    checkpoints : path, optional
        Where Ray Train keeps the epochs' checkpoints (with ``ray``; a folder every node sees),
        and a rerun resumes from; default ``headset-view-ray`` in the working folder.

    Returns
    -------
    model : EchoCNN
        ``inputs=("image",)``, 64 wide.
    figures : dict
        ``train_crops`` and ``val_crops`` (counts, before flipping), ``val_accuracy`` (0 to 1,
        on the held-out rooms), ``epochs`` and ``seconds``.
    """
    rooms = np.unique(data["room"])
    val_rooms = np.random.default_rng(seed).choice(rooms, max(1, len(rooms) // 10), replace=False)
    is_val = np.isin(data["room"], val_rooms)

    def split(rows, flip):
        crops, mirror = data["crops"][rows], data["mirror"][rows]
        if flip:
            crops, mirror = np.concatenate([crops, crops[:, :, ::-1]]), np.concatenate([mirror, mirror])
        n = len(crops)
        ignored = torch.full((n,), IGNORE, dtype=torch.long)
        y = {"open": ignored, "material": torch.as_tensor(mirror.astype(np.int64)), "depth_bin": ignored,
             "depth_ft": ignored, "depth_m": torch.full((n,), float("nan")),
             "src_cell": torch.full((n, 3), IGNORE, dtype=torch.long), "src_m": torch.full((n, 3), float("nan"))}
        return {"image": torch.as_tensor(crops.astype(np.float32) / 255)}, y

    workers, gpus_per_worker = cluster.scaling(ray, workers, gpus_per_worker)
    x_tr, y_tr = split(np.flatnonzero(~is_val), True)
    x_va, y_va = split(np.flatnonzero(is_val), False)
    if ray is not None:
        model, history = cluster.fit_on_ray(ray, name="headset_view", model=_model, load=cluster.arrays(x_tr, y_tr, x_va, y_va),
                                            seed=seed, epochs=epochs, patience=8, workers=workers,
                                            gpus_per_worker=gpus_per_worker,
                                            storage_path=Path(checkpoints or "headset-view-ray"))
    else:
        torch.manual_seed(seed)
        model = _model()
        history = fit(model, x_tr, y_tr, x_va, y_va, epochs=epochs, patience=8, seed=seed, progress=progress,
                      desc="headset view")
    p = material_probability(data["crops"][is_val], model=model)
    figures = {"train_crops": int((~is_val).sum()), "val_crops": int(is_val.sum()),
               "val_accuracy": float(np.mean((p > 0.5) == data["mirror"][is_val])), "epochs": history.epochs,
               "seconds": history.seconds}
    return model, figures


def _model() -> EchoCNN:
    return EchoCNN(inputs=("image",), hidden=64)


def main(argv: list[str] | None = None) -> None:
    """``python3 -m vrecho.learn.headset_view``: make (or load, with ``--data``) the crops, train
    on them and save the weights to ``--out`` (the shipped file by default).

    Parameters
    ----------
    argv : list of str, optional
        The arguments (default: the command line's).
    """
    ap = argparse.ArgumentParser(prog="python3 -m vrecho.learn.headset_view",
                                 description="Train the headset view's glass/mirror model on simulated rooms.")
    ap.add_argument("--rooms", type=int, default=3000)
    ap.add_argument("--seed", type=int, default=TRAIN_SEED)
    ap.add_argument("--epochs", type=int, default=60)
    ap.add_argument("--jobs", type=int, default=2, help="processes rendering the rooms")
    ap.add_argument("--data", help="an .npz of make_dataset's crops to train on (made, and kept there, if missing)")
    ap.add_argument("--out", default=str(Path(__file__).resolve().parent.parent / "assets" / WEIGHTS))
    cluster.add_argument(ap, "train with Ray Train (distributed data parallel)")
    ap.add_argument("--workers", type=int, default=1, help="Ray Train workers (with --ray)")
    ap.add_argument("--gpus-per-worker", type=float, default=0.0, help="GPUs per Ray Train worker (with --ray)")
    ap.add_argument("--checkpoints", type=Path, default=None,
                    help="Ray Train's checkpoints, and a rerun's resume (default: ./headset-view-ray)")
    args = ap.parse_args(argv)
    if args.data and Path(args.data).is_file():
        data = dict(np.load(args.data))
    else:
        data = make_dataset(args.rooms, seed=args.seed, jobs=args.jobs)
        if args.data:
            np.savez_compressed(args.data, **data)
    model, figures = train(data, epochs=args.epochs, ray=args.ray, workers=args.workers,
                           gpus_per_worker=args.gpus_per_worker, checkpoints=args.checkpoints)
    save(model, args.out)
    print(f"{args.out}: {figures}")


if __name__ == "__main__":
    main()
