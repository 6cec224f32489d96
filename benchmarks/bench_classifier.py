"""Latency of the shipped classifier's ``predict`` on one frame, features included, on one CPU core.

Prints a table: median milliseconds per call for each model the classifier picks, and each as a
ratio to a reference measured in the same run (librosa's own melspectrogram of the same frame,
the paper's front end). Run: ``python3 benchmarks/bench_classifier.py``.
"""

from __future__ import annotations

import os

os.environ.setdefault("OMP_NUM_THREADS", "1")

import statistics  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402
import torch  # noqa: E402


def median_ms(fn, repeats: int = 200) -> float:
    fn()
    times = []
    for _ in range(repeats):
        t = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t)
    return 1000 * statistics.median(times)


def main() -> None:
    import librosa

    import vrecho
    from vrecho.sim.acoustics import device_direct_amplitude, device_impulse_response, record_pulse
    from vrecho.sim.render import World, crop
    from vrecho.signals import probe

    torch.set_num_threads(1)
    scene = vrecho.builtin_scene()
    pose = scene.poses[0]
    ir = device_impulse_response(scene, pose)[0]
    frame = record_pulse(ir, probe(), device_direct_amplitude(scene, pose), np.random.default_rng(0), 30.0)
    image = crop(World(scene), pose)
    clf = vrecho.load_classifier()
    reference = median_ms(lambda: librosa.feature.melspectrogram(y=frame, sr=44100, n_fft=2048, hop_length=512,
                                                                 n_mels=62))
    rows = [("reference: librosa melspectrogram alone", reference)]
    for label, kwargs in (("EchoCNN-A (audio)", {}), ("EchoCNN-AV (audio, image)", {"image": image}),
                          ("EchoCNN-E (audio, emitted probe)", {"emitted": probe()}),
                          ("EchoCNN-EV (audio, image, emitted probe)", {"image": image, "emitted": probe()})):
        rows.append((label, median_ms(lambda: clf.predict(frame, 44100, **kwargs))))
    print("predict on one 1 s frame, features included, 1 thread (median of 200 calls)\n")
    print(f"| {'call':42s} | {'ms':>6s} | {'x reference':>11s} |")
    print(f"|{'-' * 44}|{'-' * 8}|{'-' * 13}|")
    for label, ms in rows:
        print(f"| {label:42s} | {ms:6.2f} | {ms / reference:11.2f} |")


if __name__ == "__main__":
    main()
