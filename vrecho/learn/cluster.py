"""Ray: dataset generation and training on a cluster (``--ray``).

Ray is an extra (``pip install 'vrecho[ray]'``, pinned); without it every command runs as
before and ``--ray`` says in one line how to install it. vrecho never starts a cluster behind
the user's back: ``--ray auto`` starts a local one on this machine (its CPUs, a 1 GiB object
store, no dashboard, token authentication off: it listens on this machine only); ``--ray
ADDRESS`` joins the user's running cluster (``ray start --head`` prints the address) as it is
configured.

Generation: each room is one Ray task (:func:`run_rooms`; :data:`IN_FLIGHT_PER_CPU` per CPU of
the cluster at a time), run by whichever node is free, that writes the room's arrays and its
resume marker to the dataset's folder itself (a folder every node sees: NFS or the like). Ray
retries a task whose worker dies (:data:`RETRIES` times); a room that still fails is reported
by number and left for a rerun, which does only what is missing, exactly as on one machine. A
room's numbers follow from the seed and its index alone, so the arrays are the single-machine
path's, bit for bit.

Training: :func:`fit_on_ray` runs :func:`vrecho.learn.train.fit`'s loop as Ray Train's
``TorchTrainer`` (distributed data parallel): each worker reads its own shard of every batch
from the Zarr store, gradients are averaged, and each epoch's state is a Ray Train checkpoint
in the run folder, from which an interrupted run resumes.
"""

from __future__ import annotations

import functools
import itertools
import os
import socket
import sys
import tempfile
import threading
import zipfile
from pathlib import Path
from typing import Callable

from ..errors import VrechoError, check_count, check_number

INSTALL = "pip install 'vrecho[ray]'"
RETRIES = 3
"""How many times Ray reruns a room whose task failed (a worker or node lost, an error)."""
IN_FLIGHT_PER_CPU = 4
"""Rooms submitted per CPU of the cluster at a time (:func:`run_rooms`): enough to keep every
worker busy, few enough that the driver's wait stays short."""
OBJECT_STORE_BYTES = 1 << 30
"""A local cluster's object store (the rooms' arrays go to the folder, not through it)."""


def connect(address: str):
    """Ray, connected: to a local cluster started here (``"auto"``) or a running one's address.

    Parameters
    ----------
    address : str
        ``"auto"``: start (or reuse, in this process) a local cluster on this machine; else a
        cluster's address (``host:port``, or ``ray://host:port`` for Ray Client).

    Returns
    -------
    module
        The ``ray`` module, initialised.

    Raises
    ------
    VrechoError
        Where Ray is not installed, ``address`` is not a string, or no cluster answers there.
    """
    try:
        import ray  # an extra (pip install 'vrecho[ray]'), and heavy: only with --ray
    except ImportError:
        raise VrechoError(f"--ray needs Ray, an extra: {INSTALL}") from None
    if not isinstance(address, str) or not address.strip():
        raise VrechoError(f"ray: expected 'auto' or a cluster's address (host:port), got {address!r}")
    if ray.is_initialized():
        return ray
    try:
        if address == "auto":
            os.environ.setdefault("RAY_AUTH_MODE", "disabled")  # a local cluster, this machine only
            ray.init(address="local", object_store_memory=OBJECT_STORE_BYTES, include_dashboard=False,
                     log_to_driver=False, configure_logging=False)
        else:
            _answers(address)  # Ray itself retries an address where nothing listens for minutes
            ray.init(address=address, log_to_driver=False, configure_logging=False)
    except (OSError, RuntimeError, ValueError) as e:  # ConnectionError, TimeoutError, socket.gaierror
        raise VrechoError(f"ray: no Ray cluster answers at {address!r} ({str(e).splitlines()[0] if str(e) else type(e).__name__}); "
                          "start one with `ray start --head`, or pass --ray auto for one on this machine") from None
    return ray


def disconnect() -> None:
    """Leave Ray, where this process joined it (a local cluster started here stops with it).

    The command line calls it before its last line (an error, an interrupt), so that what Ray's
    core prints while it shuts down (tasks cut off, replies it could not deliver) comes before
    vrecho's line, not after it. Nothing happens where Ray was never imported or connected.
    """
    ray = sys.modules.get("ray")
    if ray is not None and ray.is_initialized():
        ray.shutdown()


def add_argument(parser, does: str) -> None:
    """``--ray [ADDRESS]`` on a command line (argparse), its value for :func:`connect`.

    Parameters
    ----------
    parser : argparse.ArgumentParser
        The command's parser.
    does : str
        What runs on the cluster, for the help (e.g. ``"rooms as Ray tasks"``).
    """
    parser.add_argument("--ray", nargs="?", const="auto", default=None, metavar="ADDRESS",
                        help=f"{does}: on a running Ray cluster's ADDRESS (host:port; the command's folders on one "
                             f"every node sees), or, with 'auto' or no ADDRESS, on a local cluster started here "
                             f"(needs: {INSTALL})")


def scaling(ray: str | None, workers, gpus_per_worker) -> tuple[int, float]:
    """Ray Train's workers and GPUs per worker checked, and the cluster connected, before any
    work (:func:`fit_on_ray`).

    Parameters
    ----------
    ray : str or None
        As :func:`connect` takes it; None: one process trains, without Ray.
    workers : int
        Ray Train workers, 1 to 1024 (1 without ``ray``).
    gpus_per_worker : float
        GPUs per worker, 0 to 8 (0 without ``ray``).

    Returns
    -------
    workers : int
    gpus_per_worker : float

    Raises
    ------
    VrechoError
        For either out of its range or given without ``ray``, and those of :func:`connect`.
    """
    workers = check_count(workers, "workers", 1024)
    gpus_per_worker = check_number(gpus_per_worker, "gpus-per-worker", lo=0, hi=8)
    if ray is None and (workers != 1 or gpus_per_worker):
        raise VrechoError("workers and gpus-per-worker go with --ray (one process trains without it)")
    if ray is not None:
        connect(ray)  # before anything is written
    return workers, gpus_per_worker


def _answers(address: str, timeout_s: float = 5.0) -> None:
    """Raise ConnectionError unless something listens at ``address`` (``[ray://]host:port``)."""
    host, _, port = address.removeprefix("ray://").rpartition(":")
    if not host or not port.isdigit():
        raise ValueError("expected host:port")
    with socket.create_connection((host.strip("[]"), int(port)), timeout=timeout_s):
        pass


def run_rooms(address: str, work: Callable, rooms: list[int], args: Callable[[int], tuple], on_done: Callable[[int], None],
              *, what: str = "rooms") -> None:
    """``work(*args(i))`` for every room ``i`` of ``rooms``, one Ray task each, ``on_done(i)``
    on the driver as each finishes.

    Parameters
    ----------
    address : str
        As :func:`connect` takes it.
    work : callable
        A module-level function (Ray pickles it by reference) that writes its room's results.
    rooms : list of int
        The rooms to do.
    args : callable
        A room's arguments to ``work``.
    on_done : callable
        Called with each room's index on the driver when it is written.
    what : str
        What the units are called in messages (default "rooms").

    Raises
    ------
    VrechoError
        Naming the rooms that failed after :data:`RETRIES` retries (the others are kept), and
        those of :func:`connect`.
    """
    ray = connect(address)
    task = ray.remote(num_cpus=1, max_retries=RETRIES, retry_exceptions=True)(_room_task)
    # A bounded window of rooms in flight, refilled as they finish: each wait looks at the window,
    # not at every room of the run (a million-frame run has tens of thousands).
    window = max(8, IN_FLIGHT_PER_CPU * int(ray.cluster_resources().get("CPU", 1)))
    queue = iter(rooms)
    pending = {task.remote(work, *args(i)): i for i in itertools.islice(queue, window)}
    failed = {}
    # An interrupt leaves the rooms under way to end with this driver (its tasks die with it; a room
    # without its marker is done again by a rerun): force-cancelling them here raced their replies
    # and aborted Ray's core worker after vrecho's line (a failed check in its task manager).
    while pending:
        done, _ = ray.wait(list(pending), num_returns=1)
        for ref in done:
            i = pending.pop(ref)
            for j in itertools.islice(queue, 1):
                pending[task.remote(work, *args(j))] = j
            try:
                ray.get(ref)
            except (ray.exceptions.RayError, OSError) as e:
                failed[i] = str(e).strip().splitlines()[-1][:200]
                continue
            on_done(i)
    if failed:
        first = ", ".join(f"{i} ({why})" for i, why in list(failed.items())[:3])
        raise VrechoError(f"ray: {len(failed)} of {len(rooms)} {what} failed after {RETRIES} retries: {first}; "
                          "the rest are kept: rerun the same command to retry them")


def _room_task(work: Callable, *args) -> None:
    # One task per CPU: the libraries stay single-threaded, as in generate's process pool.
    for var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
        os.environ[var] = "1"
    import torch  # heavy (1.7 s): loaded by the room's work anyway

    torch.set_num_threads(1)
    work(*args)


def fit_on_ray(address: str, *, name: str, model: Callable, load: Callable, seed: int, epochs: int, patience: int,
               workers: int, gpus_per_worker: float, storage_path: Path, fit: Callable | None = None):
    """A training loop as Ray Train's ``TorchTrainer``: distributed data parallel.

    Each of ``workers`` workers loads its own share of the training frames (``load``) and runs
    the loop (``fit``; :func:`~.train.fit` by default) with the model wrapped for distributed
    data parallel (``ray.train.torch.prepare_model``), a batch shared out (:func:`~.train.fit`'s
    64 frames: 64 / ``workers`` per worker and step; the gradients are averaged, the batch-norm
    statistics are each worker's); every worker judges the whole validation set, so all stop
    together. Each epoch's state is reported as a Ray Train checkpoint in ``storage_path /
    name``; a rerun resumes from the last one.

    Parameters
    ----------
    address : str
        As :func:`connect` takes it.
    name : str
        The run's name (a file name: the model's).
    model : callable
        Makes the untrained model (called after ``torch.manual_seed(seed)``, on every worker).
    load : callable
        ``load(rank, workers)`` gives a worker its data: for :func:`~.train.fit`, ``(x, y,
        x_val, y_val)``, its share of the training inputs and targets (the same count for every
        worker) and the whole validation set (:func:`arrays`, or a reader of the dataset's store
        every node sees).
    seed, epochs, patience : int
        As :func:`~.train.fit` takes them.
    workers : int
        Ray Train workers.
    gpus_per_worker : float
        GPUs per worker (0: CPU, gloo).
    storage_path : pathlib.Path
        Where Ray Train keeps the runs' checkpoints (every node must see it).
    fit : callable, optional
        Another training loop, a module-level function (Ray pickles it by reference):
        ``fit(model, net, data, *, world, seed, epochs, patience, checkpoint, on_epoch)``, where
        ``data`` is ``load``'s, ``net`` the model wrapped for the workers, ``world`` their count;
        it writes each epoch's state to ``checkpoint`` (resuming from it where it exists) as
        :func:`~.train.fit` does (``epoch``, ``stopped``, ``state``, ``best_state``, ``best``,
        ``best_epoch``, ``seconds``, ``losses``), then calls ``on_epoch(record)``.

    Returns
    -------
    model : torch.nn.Module
        With the best validation loss's weights, on the CPU, in evaluation mode.
    history : vrecho.learn.train.History

    Raises
    ------
    VrechoError
        Those of :func:`connect`, or where training failed after Ray's retries (a rerun goes on
        from the last epoch).
    """
    import torch  # heavy (1.7 s): only when training

    ray = connect(address)
    from ray.train import CheckpointConfig, FailureConfig, RunConfig, ScalingConfig  # an extra: only with --ray
    from ray.train.torch import TorchTrainer  # an extra: only with --ray

    from .train import History  # torch-bound: only when training

    latest = latest_checkpoint(Path(storage_path) / name)
    saved = None
    if latest is not None:  # a run that stopped, or ran its epochs, is read, not relaunched
        last = torch.load(latest / "state.pt", map_location="cpu", weights_only=False)
        saved = last if last["stopped"] or last["epoch"] >= epochs else None
    if saved is None:
        config = {"model": model, "load": load, "seed": seed, "epochs": epochs, "patience": patience,
                  "fit": fit or _fit, "resume": str(latest) if latest is not None else None}
        resources = {"CPU": 1, "GPU": gpus_per_worker} if gpus_per_worker else {"CPU": 1}
        trainer = TorchTrainer(_train_loop, train_loop_config=config,
                               scaling_config=ScalingConfig(num_workers=workers, use_gpu=gpus_per_worker > 0,
                                                            resources_per_worker=resources),
                               run_config=RunConfig(name=name, storage_path=str(Path(storage_path).resolve()),
                                                    checkpoint_config=CheckpointConfig(num_to_keep=2),
                                                    failure_config=FailureConfig(max_failures=RETRIES)))
        try:
            result = _in_thread(trainer.fit)
        except ray.exceptions.RayError as e:
            raise VrechoError(f"ray: training {name} failed ({str(e).strip().splitlines()[-1][:200]}); "
                              "rerun the same command to resume from its last epoch") from None
        if result.checkpoint is None:
            raise VrechoError(f"ray: training {name} reported no checkpoint")
        with result.checkpoint.as_directory() as d:
            saved = torch.load(Path(d) / "state.pt", map_location="cpu", weights_only=False)
    torch.manual_seed(seed)
    net = model()
    net.load_state_dict(saved["best_state"] if saved["best_state"] is not None else saved["state"])
    net.eval()
    return net, History(saved["epoch"], saved["best_epoch"], saved["best"], saved["seconds"], tuple(saved.get("losses", ())))


def arrays(x: dict, y: dict, x_val: dict, y_val: dict) -> Callable:
    """A ``load`` for :func:`fit_on_ray` of tensors in memory: put once in Ray's object store,
    every ``workers``-th frame from a worker's rank its share (cut to the same count).

    Parameters
    ----------
    x, y, x_val, y_val : dict of str to torch.Tensor
        The training and validation inputs and targets, frames on the first axis.

    Returns
    -------
    callable
    """
    import ray  # an extra: only with --ray (connected by then)

    return functools.partial(_array_share, ray.put((x, y, x_val, y_val)))


def _array_share(ref, rank: int, workers: int):
    import ray  # an extra: only where Ray runs

    x, y, x_val, y_val = ray.get(ref)
    n = len(next(iter(y.values()))) // workers
    return ({k: v[rank::workers][:n] for k, v in x.items()}, {k: v[rank::workers][:n] for k, v in y.items()},
            x_val, y_val)


DRIVER_GRACE_S = 30.0
"""How long an interrupted command waits for Ray Train's driver thread to end once Ray is shut down."""


def _in_thread(call: Callable):
    """``call()`` in a thread of its own, the main thread waiting: Ray Train installs its own
    Ctrl-C handler (for good, exiting with status 1 and no word) only when it runs in the main
    thread; here Ctrl-C stays vrecho's (one line, status 130), and the workers end with this
    driver (a local cluster with it, a remote one's job as it disconnects). Interrupted, it shuts
    Ray down and waits up to :data:`DRIVER_GRACE_S` for the thread to end before it passes the
    interrupt on."""
    box = {}

    def run():
        try:
            box["result"] = call()
        except BaseException as e:  # handed to the main thread as it is
            box["error"] = e

    thread = threading.Thread(target=run, name="ray-train-driver", daemon=True)
    thread.start()
    try:
        while thread.is_alive():
            thread.join(0.2)
    except BaseException:  # Ctrl-C: Ray shut down, and its driver thread let end before the interpreter does
        disconnect()  # (a daemon thread still in Ray's C++ core as Python finalizes can take the process
        thread.join(DRIVER_GRACE_S)  # down with it: a run of CI ended so, SIGSEGV in place of status 130)
        raise
    if "error" in box:
        raise box["error"]
    return box["result"]


def latest_checkpoint(run_dir: Path) -> Path | None:
    """The newest whole checkpoint folder of an earlier run, which a rerun resumes from.

    Ray Train's layout: ``checkpoint_<time>`` folders holding ``state.pt``. One cut short (an
    interrupt while Ray copied it into the run's folder: its zip archive has no end, and
    ``torch.load`` fails on it) is passed over.

    Parameters
    ----------
    run_dir : pathlib.Path
        The run's folder (``storage_path / name``); it need not exist.

    Returns
    -------
    pathlib.Path or None
        The newest folder whose ``state.pt`` is whole, or None.
    """
    found = sorted((p for p in run_dir.glob("checkpoint_*") if zipfile.is_zipfile(p / "state.pt")),
                   key=lambda p: p.stat().st_mtime) if run_dir.is_dir() else []
    return found[-1] if found else None


def _train_loop(config: dict) -> None:
    """One Ray Train worker's part of :func:`fit_on_ray`."""
    import ray.train  # an extra, and heavy: only where Ray runs
    import torch  # heavy (1.7 s): only where a worker trains
    from ray.train.torch import prepare_model  # an extra: only where Ray runs

    ctx = ray.train.get_context()
    rank, world = ctx.get_world_rank(), ctx.get_world_size()
    torch.set_num_threads(1)
    data = config["load"](rank, world)
    torch.manual_seed(config["seed"])
    model = config["model"]()
    # on this worker's device; wrapped for DDP where there are several workers (a frame's kind leaves
    # some heads out of the loss: their parameters get no gradient on some steps)
    net = prepare_model(model, parallel_strategy_kwargs={"find_unused_parameters": True})
    with tempfile.TemporaryDirectory() as work:
        ckpt = Path(work) / "state.pt"
        # a worker restarted within the run resumes from the run's checkpoint; a run started again
        # after an interrupt, from the last one its folder holds
        resume = ray.train.get_checkpoint()
        if resume is not None:
            with resume.as_directory() as d:
                ckpt.write_bytes((Path(d) / "state.pt").read_bytes())
        elif config["resume"] is not None:
            ckpt.write_bytes((Path(config["resume"]) / "state.pt").read_bytes())

        def report(record: dict) -> None:
            if rank == 0:
                with tempfile.TemporaryDirectory() as out:
                    (Path(out) / "state.pt").write_bytes(ckpt.read_bytes())
                    ray.train.report(record, checkpoint=ray.train.Checkpoint.from_directory(out))
            else:
                ray.train.report(record)

        config["fit"](model, net, data, world=world, seed=config["seed"], epochs=config["epochs"],
                      patience=config["patience"], checkpoint=ckpt, on_epoch=report)


def _fit(model, net, data, *, world: int, seed: int, epochs: int, patience: int, checkpoint: Path, on_epoch: Callable) -> None:
    """:func:`~.train.fit` on one worker, the batch of 64 shared out (``data``: its share of the
    training inputs and targets, and the validation set)."""
    from .train import fit  # torch-bound: only where a worker trains

    x, y, x_val, y_val = data
    fit(model, x, y, x_val, y_val, epochs=epochs, batch_size=max(2, 64 // world), patience=patience, seed=seed,
        checkpoint=checkpoint, progress=False, net=net, on_epoch=on_epoch)
