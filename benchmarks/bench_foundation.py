"""Foundation benchmark: simulator and dataset throughput, and storage per 1 000 frames.

    python3 benchmarks/bench_foundation.py [--rooms 4] [--seed 0]

Prints a Markdown table. Speed is given as a ratio against a baseline measured in the same run:
the naive pipeline that simulates a fresh impulse response for every (pose, sound) frame, against
vrecho's, which simulates one per pose and convolves it with all 16 sounds. Absolute times hold only
on the machine they were measured on.
"""

from __future__ import annotations

import argparse
import platform
import tempfile
import time
from pathlib import Path

import numpy as np

from vrecho.sim.acoustics import device_direct_amplitude, device_impulse_response, record_pulse
from vrecho.learn.datasets import generate, open_dataset
from vrecho.features import logmel
from vrecho.sim.render import World, crop
from vrecho.sim.scenes import random_scene
from vrecho.signals import FS, SOUNDS, emitted_sound


def _frames_for_pose(scene, world, pose, rng, ir=None):
    """All 16 frames of one pose (vrecho's way: one impulse response, 16 convolutions)."""
    ir = device_impulse_response(scene, pose, cache=False)[0] if ir is None else ir
    crop(world, pose)
    direct = device_direct_amplitude(scene, pose)
    frames = np.stack([record_pulse(ir, emitted_sound(s, FS, rng), direct, rng) for s in SOUNDS])
    logmel(frames)
    return frames


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rooms", type=int, default=4)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    rng = np.random.default_rng(args.seed)
    scenes = [random_scene(rng, f"bench_{i}", n_poses=3, n_sources=0) for i in range(args.rooms)]
    worlds = [World(s) for s in scenes]
    logmel(np.zeros((1, FS), np.float32))  # librosa's first call compiles; keep it out of the timings

    t = time.perf_counter()
    n_ir = 0
    for s in scenes:
        for p in s.poses:
            device_impulse_response(s, p, cache=False)
            n_ir += 1
    t_ir = (time.perf_counter() - t) / n_ir

    t = time.perf_counter()
    n_frames = 0
    for s, w in zip(scenes, worlds):
        for p in s.poses:
            n_frames += len(_frames_for_pose(s, w, p, rng))
    t_frame = (time.perf_counter() - t) / n_frames

    # Baseline: a fresh simulation for every frame (4 sounds of one pose per room suffice to time it).
    t = time.perf_counter()
    n_base = 0
    for s, w in zip(scenes, worlds):
        p = s.poses[0]
        for name in SOUNDS[:4]:
            ir = device_impulse_response(s, p, cache=False)[0]
            crop(w, p)
            logmel(record_pulse(ir, emitted_sound(name, FS, rng), device_direct_amplitude(s, p), rng)[None])
            n_base += 1
    t_base = (time.perf_counter() - t) / n_base

    with tempfile.TemporaryDirectory() as tmp:
        t = time.perf_counter()
        out = generate(Path(tmp) / "ds", preset="tiny", seed=args.seed, workers=None, cache=Path(tmp) / "cache", progress=False)
        t_tiny = time.perf_counter() - t
        ds = open_dataset(out)
        disk = sum(f.stat().st_size for f in (out / "frames.zarr").rglob("*") if f.is_file() and "/ir/" not in str(f))
        ram = ds.audio.nbytes + ds.logmel.nbytes + ds.image.nbytes
        n = len(ds)

    print(f"Foundation benchmark, {args.rooms} random rooms x 3 poses, seed {args.seed}; "
          f"{platform.machine()}, {__import__('os').cpu_count()} cores\n")
    print("| quantity | value |")
    print("|:---|---:|")
    print(f"| impulse responses per second (hybrid ISM order 3 + 3000 rays, 1 process) | {1 / t_ir:.2f} |")
    print(f"| frames per second, vrecho (1 response per pose x 16 sounds, crop, log-mel; 1 process) | {1 / t_frame:.1f} |")
    print(f"| frames per second, baseline (fresh simulation per frame; 1 process) | {1 / t_base:.2f} |")
    print(f"| speed-up over the baseline | {t_base / t_frame:.1f}x |")
    print(f"| frames per simulated impulse response | {len(SOUNDS)} |")
    print(f"| tiny preset end to end ({n} frames, all cores) | {t_tiny:.1f} s |")
    print(f"| storage per 1 000 frames on disk (audio f16, log-mel, image; Zarr, compressed) | {disk / n * 1000 / 2**20:.0f} MiB |")
    print(f"| memory per 1 000 frames loaded (audio f16, log-mel f32, image u8) | {ram / n * 1000 / 2**20:.0f} MiB |")


if __name__ == "__main__":
    main()
