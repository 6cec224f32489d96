"""Issue 28: generation and training on Ray against the single-machine paths, in one run.

Usage: ``python3 benchmarks/bench_cluster.py [--preset small] [--runs 1] [--epochs 20] [--seeds 5]``
prints four tables and draws ``docs/cluster_throughput.png`` (frames per second against workers):

1. generation: frames per second of a preset (``small``: 16 rooms as the default preset's, 2 560
   frames a run; ``--runs`` runs of seeds 1000, 1001, ..., each into a fresh folder with a fresh
   impulse-response cache, so every room is simulated; the command's own start-up counted, as a
   user meets it), by the process pool (``generate(workers=N)``) and by Ray tasks on
   a local cluster of N CPUs (``generate(ray="auto")``), N = 1 and up to the machine's cores;
   the scaling efficiency (rate with N over N times the rate with 1) and Ray's overhead against
   the pool at the same N;
2. training: EchoCNN-A on the ``small`` preset (the paper protocol's 1 440 training frames, 240
   validation frames), at most ``--epochs`` epochs (patience 6), samples per second (the
   training loop's own time; Ray Train's start-up, its workers and their data, apart), in one
   process (``fit``) and with Ray Train on 2 workers, each over seeds 0 to ``--seeds`` - 1, and
   on 1 worker (seed 0); the best validation loss's mean and standard deviation over the seeds,
   and whether the two paths agree within noise: their means no further apart than twice the
   standard error of a difference of two means of that many seeds (2 sd sqrt(2 / seeds), sd the
   one process's over seeds: what changing the seed alone does);
3. the mask network (8 channels wide, 16 rooms' walks, 4 epochs) in one process and on 2 Ray
   Train workers: examples per second and the last epoch's validation loss;
4. the driver: units per second through ``cluster.run_rooms`` of tasks that do nothing, 1 000,
   10 000 and 30 000 of them on a local cluster of this machine's CPUs (Ray's own cost per task and
   the driver's loop, which a 10-million-frame run asks 62 500 times);
5. a projection of 10 million frames on a 64-node cluster from the per-worker rate measured.

Every Ray run here starts its own local cluster (``ray.init(num_cpus=N)``), shut down after.
Absolute rates hold on the machine stated only.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import statistics
import tempfile
import time
from pathlib import Path

os.environ.setdefault("RAY_AUTH_MODE", "disabled")  # local clusters only


def gen_rate(preset: str, workers: int, use_ray: bool, runs: int, base: Path) -> float:
    import ray

    from vrecho.learn.datasets import generate

    if use_ray:
        ray.init(num_cpus=workers, object_store_memory=1 << 30, include_dashboard=False, log_to_driver=False,
                 configure_logging=False)
    try:
        frames, seconds = 0, 0.0
        for k in range(runs):
            out, cache = base / f"ds{k}", base / f"cache{k}"
            t = time.perf_counter()
            generate(out, preset=preset, seed=1000 + k, workers=workers, cache=cache, progress=False,
                     ray="auto" if use_ray else None)
            seconds += time.perf_counter() - t
            frames += json.loads((out / "manifest.json").read_text())["n_frames"]
            shutil.rmtree(out)
            shutil.rmtree(cache)
    finally:
        if use_ray:
            ray.shutdown()
    return frames / seconds


def train_rate(data: Path, epochs: int, workers: int | None, base: Path, seed: int = 0) -> tuple[float, float, float]:
    """Samples per second in the training loop, the seconds around it (start-up) and the best
    validation loss: ``workers`` None is one process."""
    import ray

    from vrecho.learn.evaluate import train_methods

    out = base / f"run{workers}-{seed}"
    if workers:
        ray.init(num_cpus=workers, object_store_memory=1 << 30, include_dashboard=False, log_to_driver=False,
                 configure_logging=False)
    try:
        t = time.perf_counter()
        rec = train_methods(data, out, methods=["EchoCNN-A"], seed=seed, epochs=epochs, progress=False,
                            ray="auto" if workers else None, workers=workers or 1)["EchoCNN-A"]
        seconds = time.perf_counter() - t
    finally:
        if workers:
            ray.shutdown()
    return rec["n_train"] * rec["epochs"] / rec["seconds"], seconds - rec["seconds"], rec["val_loss"]


def masknet_rate(data: Path, epochs: int, workers: int | None, base: Path) -> tuple[float, float]:
    """The mask network's examples per second (start-up included) and last validation loss."""
    import numpy as np

    from vrecho.learn.masknet import make_examples, train

    n = sum(len(np.load(p)["t"]) for p in make_examples(data, rooms=16, jobs=2))
    t = time.perf_counter()
    losses = train(base / f"mask{workers}.pt", rooms=16, jobs=2, epochs=epochs, width=8, data_dir=data, progress=False,
                   ray="auto" if workers else None, workers=workers or 1, checkpoints=base / f"mask-ray{workers}")
    return n * epochs / (time.perf_counter() - t), float(losses[-1])


def _nothing(i: int) -> None:
    return None


def driver_rate(n: int, cpus: int) -> float:
    """Units per second through ``cluster.run_rooms`` of ``n`` tasks that do nothing."""
    import ray

    from vrecho.learn.cluster import run_rooms

    ray.init(num_cpus=cpus, object_store_memory=1 << 30, include_dashboard=False, log_to_driver=False,
             configure_logging=False)
    try:
        run_rooms("auto", _nothing, [0], lambda i: (i,), lambda i: None)  # the workers started
        t = time.perf_counter()
        run_rooms("auto", _nothing, list(range(n)), lambda i: (i,), lambda i: None, what="units")
        return n / (time.perf_counter() - t)
    finally:
        ray.shutdown()


def figure(rates: dict, path: Path) -> None:
    """Generation's frames per second against workers, both paths, and the ideal (linear from 1)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    ns = sorted(rates)
    fig, ax = plt.subplots(figsize=(5, 3.6), dpi=120)
    ax.plot(ns, [n * rates[1][0] for n in ns], ":", color="grey", label="ideal (1 worker x N)")
    ax.plot(ns, [rates[n][0] for n in ns], "o-", label="process pool")
    ax.plot(ns, [rates[n][1] for n in ns], "s-", label="Ray tasks")
    ax.set(xlabel="workers (CPUs)", ylabel="frames generated per second", xticks=ns,
           title=f"Generation throughput ({os.cpu_count()} cores)")
    ax.grid(alpha=0.3)
    ax.legend()
    fig.tight_layout()
    fig.savefig(path)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--preset", default="small", choices=("tiny", "small", "default"))
    ap.add_argument("--runs", type=int, default=1)
    ap.add_argument("--epochs", type=int, default=20)
    ap.add_argument("--seeds", type=int, default=5)
    ap.add_argument("--driver-only", action="store_true", help="only the driver's table")
    a = ap.parse_args()
    if a.driver_only:
        for n in (1000, 10_000, 30_000):
            print(f"| {n} | {driver_rate(n, os.cpu_count() or 1):.0f} |", flush=True)
        return
    cores = os.cpu_count() or 1
    ns = sorted({1, 2, min(cores, 4), min(cores, 8), min(cores, 16)} & set(range(1, cores + 1)))
    with tempfile.TemporaryDirectory() as tmp:
        base = Path(tmp)
        print(f"generation: {a.preset} preset, {a.runs} run(s) per row, fresh caches; {cores} cores\n")
        print("| workers | process pool: frames/s | Ray tasks: frames/s | pool efficiency | Ray efficiency | Ray overhead vs pool |")
        print("|---|---|---|---|---|---|")
        rates = {}
        for n in ns:
            rates[n] = (gen_rate(a.preset, n, False, a.runs, base), gen_rate(a.preset, n, True, a.runs, base))
            pool, ray_ = rates[n]
            print(f"| {n} | {pool:.1f} | {ray_:.1f} | {pool / (n * rates[1][0]):.0%} | {ray_ / (n * rates[1][1]):.0%} "
                  f"| {pool / ray_ - 1:+.0%} |", flush=True)
        figure(rates, Path(__file__).resolve().parent.parent / "docs" / "cluster_throughput.png")
        from vrecho.learn.datasets import generate

        data = generate(base / "train_ds", preset="small", seed=0, cache=base / "train_cache", progress=False)
        print(f"\ntraining: EchoCNN-A, small preset (paper protocol), at most {a.epochs} epochs, seeds 0-{a.seeds - 1}\n")
        print("| path | samples/s in training | start-up and the rest (s) | best validation loss: mean | sd | seeds |")
        print("|---|---|---|---|---|---|")
        losses = {}
        for label, w, seeds in (("one process (fit)", None, range(a.seeds)), ("Ray Train, 1 worker", 1, [0]),
                                ("Ray Train, 2 workers (DDP)", 2, range(a.seeds))):
            runs = [train_rate(data, a.epochs, w, base, seed) for seed in seeds]
            losses[w] = [r[2] for r in runs]
            sd = statistics.stdev(losses[w]) if len(runs) > 1 else float("nan")
            print(f"| {label} | {statistics.mean(r[0] for r in runs):.0f} | {statistics.mean(r[1] for r in runs):.1f} "
                  f"| {statistics.mean(losses[w]):.3f} | {sd:.3f} | {len(runs)} |", flush=True)
        gap = statistics.mean(losses[2]) - statistics.mean(losses[None])
        tol = 2 * statistics.stdev(losses[None]) * (2 / a.seeds) ** 0.5
        print(f"\n2 workers against one process: {gap:+.3f} (tolerance {tol:.3f}): "
              f"{'within' if abs(gap) <= tol else 'OUTSIDE'} noise")
        print("\nmask network: 8 wide, 16 rooms, 4 epochs\n")
        print("| path | examples/s (start-up included) | last validation loss (dB) |")
        print("|---|---|---|")
        for label, w in (("one process", None), ("Ray Train, 2 workers (DDP)", 2)):
            rate, val = masknet_rate(base / "masknet", 4, w, base)
            print(f"| {label} | {rate:.1f} | {val:.2f} |", flush=True)
        print(f"\ndriver: units that do nothing through run_rooms, a local cluster of {cores} CPUs\n")
        print("| units | units/s |")
        print("|---|---|")
        for n in (1000, 10_000, 30_000):
            print(f"| {n} | {driver_rate(n, cores):.0f} |", flush=True)
        per_worker = rates[1][1]
        eff = rates[max(ns)][1] / (max(ns) * per_worker)
        nodes, cores_per_node, frames = 64, 16, 10_000_000
        workers = nodes * cores_per_node
        hours = frames / (per_worker * workers * eff) / 3600
        bytes_per_frame = 44100 * 2 + 62 * 25 * 4 + 64 * 25  # audio float16, log-mel float32, image uint8
        print(f"\nprojection: {frames:,} frames on {nodes} nodes x {cores_per_node} cores = {workers} Ray workers at "
              f"{per_worker:.1f} frames/s each and the efficiency measured at {max(ns)} ({eff:.0%}): {hours:.1f} h; "
              f"the store takes {frames * bytes_per_frame / 1e12:.2f} TB at "
              f"{per_worker * workers * eff * bytes_per_frame / 1e6:.0f} MB/s; the driver sees "
              f"{per_worker * workers * eff / 160:.1f} rooms/s (160 frames a room at the default preset)")


if __name__ == "__main__":
    main()
