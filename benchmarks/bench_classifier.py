"""Latency of the shipped classifier as a user calls it: default thread settings, a fresh process.

Prints a table per machine state, quiet and with another process keeping one core busy (a
headset app rendering while it listens): for each model the classifier picks, and EchoCNN-E
with ``surface_m`` (the echo at the plane's distance read too, as the reconstruction asks), ``predict`` on
one frame (median and 90th percentile of 200 calls, features included) and ``predict_batch``
on 64 frames (milliseconds per frame, median of 10 calls), each also as a ratio to a reference
measured beside it in the same state (librosa's own melspectrogram of the same frame, the
paper's front end, at the same default settings). The calls are made in :data:`PASSES` passes,
each pass every model and the reference in turn: the machine's speed drifts over seconds, and
the models take their turns through the same seconds. Run:
``python3 benchmarks/bench_classifier.py``. Nothing here sets threads: whatever the library
sets, it sets for itself.
"""

from __future__ import annotations

import multiprocessing as mp
import time

import numpy as np


def _spin() -> None:
    while True:
        pass


PASSES = 5
"""The passes a table's calls are made in (each pass: 40 ``predict`` calls and 2 ``predict_batch``
calls of every model, 40 reference calls)."""


def _times_ms(fn, repeats: int, per: int = 1) -> list[float]:
    out = []
    for _ in range(repeats):
        t = time.perf_counter()
        fn()
        out.append(1000 * (time.perf_counter() - t) / per)
    return out


def table(state: str) -> None:
    import librosa

    import vrecho
    from vrecho.sim.acoustics import device_direct_amplitude, device_impulse_response, record_pulse
    from vrecho.sim.render import World, crop
    from vrecho.signals import probe

    scene = vrecho.builtin_scene()
    pose = scene.poses[0]
    ir = device_impulse_response(scene, pose)[0]
    frame = record_pulse(ir, probe(), device_direct_amplitude(scene, pose), np.random.default_rng(0), 30.0)
    image = crop(World(scene), pose)
    frames, images = np.stack([frame] * 64), np.stack([image] * 64)
    clf = vrecho.load_classifier()
    mel = lambda: librosa.feature.melspectrogram(y=frame, sr=44100, n_fft=2048, hop_length=512, n_mels=62)
    rows = (("EchoCNN-A (audio)", {}, {}), ("EchoCNN-AV (audio, image)", {"image": image}, {"images": images}),
            ("EchoCNN-E (audio, emitted probe)", {"emitted": probe()}, {"emitted": probe()}),
            ("EchoCNN-EV (audio, image, emitted probe)", {"image": image, "emitted": probe()},
             {"images": images, "emitted": probe()}),
            ("EchoCNN-E + echo at surface_m (the probe, the plane's distance)",
             {"emitted": probe(), "surface_m": 1.5}, {"emitted": probe(), "surface_m": 1.5}))
    mel()
    for _, one, many in rows:  # warm: each model's first calls
        clf.predict(frame, 44100, **one)
        clf.predict_batch(frames, 44100, **many)
    ref, t1, tb = [], {r[0]: [] for r in rows}, {r[0]: [] for r in rows}
    for _ in range(PASSES):
        ref += _times_ms(mel, 200 // PASSES)
        for label, one, many in rows:
            t1[label] += _times_ms(lambda: clf.predict(frame, 44100, **one), 200 // PASSES)
            tb[label] += _times_ms(lambda: clf.predict_batch(frames, 44100, **many), 10 // PASSES, per=64)
    ref_ms = float(np.median(ref))
    print(f"\n{state}: reference (librosa melspectrogram of one frame) median {ref_ms:.2f} ms, "
          f"90th percentile {np.percentile(ref, 90):.2f} ms\n")
    print("| model | predict: median ms | 90th pct ms | x reference | predict_batch (64): ms per frame | x reference |")
    print("|:---|---:|---:|---:|---:|---:|")
    for label, _, _ in rows:
        one, many = float(np.median(t1[label])), float(np.median(tb[label]))
        print(f"| {label} | {one:.2f} | {np.percentile(t1[label], 90):.2f} | {one / ref_ms:.2f} "
              f"| {many:.2f} | {many / ref_ms:.2f} |", flush=True)


def main() -> None:
    import os

    print(f"predict as a user calls it: default thread settings, a fresh process, {os.cpu_count()} cores")
    ctx = mp.get_context("spawn")
    for state, busy in (("quiet", False), ("one core kept busy by another process", True)):
        spinner = ctx.Process(target=_spin, daemon=True) if busy else None
        if spinner:
            spinner.start()
        try:
            p = ctx.Process(target=table, args=(state,))  # a fresh process per state, as a user's
            p.start()
            p.join()
        finally:
            if spinner:
                spinner.terminate()


if __name__ == "__main__":
    main()
