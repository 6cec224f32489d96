"""Finding the pulses in a real capture's recording (issue 9): share found and onset error.

    python3 benchmarks/bench_onsets.py [--rooms 20] [--pulses 30] [--seed 9000]

Recordings are simulated with the project's acoustics (``random_scene`` rooms, a device pose in
each, pyroomacoustics impulse responses; seed 9000, never used while building the detector) as
a phone makes them: vrecho's probe every second, the clocks drifting by up to 0.5 %, the train
starting at a random fraction of a sample, pink noise 10 to 40 dB below the direct sound, and in
each condition: clean, clipped at 0.3 of the direct sound's peak, two pulses not played, and
all of these at once; and with other sounds in the room: five hand claps as loud as the direct
sound at random times ("claps"), and speech-like voice and whistles (the protocol's sounds,
looped) 6 dB below the direct sound's peak ("talk"); and the player paused twice, for 0.1 to 3
s (or looping its file with a gap at the seam: "paused"). A pulse is found when an onset lies within 5 ms of its direct sound's
arrival; the error is that onset's distance from the arrival, in samples (44.1 kHz). A false
pulse is an onset more than 5 ms from every pulse played. Prints one table.
"""

from __future__ import annotations

import argparse
import platform
import time

import numpy as np
from tqdm import tqdm

from vrecho.sim.acoustics import MIC_SENSITIVITY, device_impulse_response
from vrecho.capture import find_onsets
from vrecho.sim.captures import simulate_recording
from vrecho.errors import VrechoError
from vrecho.sim.scenes import random_scene
from vrecho.signals import FS, emitted_sound, probe

CONDITIONS = {"clean": {}, "clipped": {"clip": 0.3}, "2 dropped": {"dropped": 2},
              "all": {"clip": 0.3, "dropped": 2}, "claps": {"claps": 5}, "talk": {"talk": 0.5},
              "paused": {"pauses": 2}}


def interference(n: int, level: float, rng: np.random.Generator, claps: int = 0, talk: float = 0.0) -> np.ndarray:
    """Other sounds of a room: ``claps`` hand claps with peak ``level`` at random times, and a bed
    of voice and whistle pulses back to back with peak ``talk * level``."""
    out = np.zeros(n)
    for _ in range(claps):
        c = emitted_sound("clap", FS, rng)
        i = int(rng.integers(0, n - c.size))
        out[i:i + c.size] += level * c / np.abs(c).max()
    if talk:
        i = 0
        while i < n:
            c = emitted_sound(str(rng.choice(["voice", "whistle"])), FS, rng)
            c = c[:n - i]
            out[i:i + c.size] += talk * level * c / np.abs(c).max()
            i += c.size
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rooms", type=int, default=20)
    ap.add_argument("--pulses", type=int, default=30)
    ap.add_argument("--seed", type=int, default=9000)
    args = ap.parse_args()
    rows, seconds, audio_s = [], [], 0.0
    for r in tqdm(range(args.rooms), desc="rooms", unit="room"):
        rng = np.random.default_rng([args.seed, r])
        scene = random_scene(rng, f"onsets_{r}", n_poses=1)
        ir = device_impulse_response(scene, scene.poses[0])[0]
        for snr in (10, 20, 30, 40):
            for name, cond in CONDITIONS.items():
                dropped = tuple(rng.choice(np.arange(1, args.pulses - 1), cond.get("dropped", 0), replace=False))
                pauses = {int(k): float(rng.uniform(0.1, 3.0))
                          for k in rng.choice(np.arange(2, args.pulses - 2), cond.get("pauses", 0), replace=False)}
                x, truth = simulate_recording(ir, args.pulses, rng, snr_db=snr, drift=float(rng.uniform(-0.005, 0.005)),
                                              clip=cond.get("clip"), dropped=dropped, pauses=pauses)
                if "claps" in cond or "talk" in cond:
                    level = MIC_SENSITIVITY * np.abs(ir).max() * np.abs(probe()).max()  # the direct sound's peak
                    x = x + interference(len(x), level, rng, cond.get("claps", 0), cond.get("talk", 0.0)).astype(np.float32)
                t = time.perf_counter()
                try:
                    onsets = find_onsets(x, FS)
                    found, reported = onsets.samples, onsets.missing
                except VrechoError:
                    found, reported = np.zeros(0), np.zeros(0)
                seconds.append(time.perf_counter() - t)
                audio_s += len(x) / FS
                played = truth[~np.isnan(truth)]
                err = np.array([np.min(np.abs(found - t)) if len(found) else np.inf for t in played])
                hit = err <= 0.005 * FS
                false = sum(np.min(np.abs(played - f)) > 0.005 * FS for f in found)
                kept = np.flatnonzero(~np.isnan(truth))
                due = np.interp(list(dropped), kept, truth[kept])  # where the dropped pulses were due
                flagged = int(sum(np.min(np.abs(due - m)) <= 0.005 * FS for m in reported)) if dropped else 0
                rows.append(dict(snr=snr, cond=name, n=len(played), hit=int(hit.sum()), err=err[hit].tolist(),
                                 false=int(false), dropped=len(dropped), flagged=flagged,
                                 wrong_flags=len(reported) - flagged))
    print(f"\n{args.rooms} rooms (seed {args.seed}), {args.pulses} pulses per recording; "
          f"{platform.node()} {time.strftime('%Y-%m-%d')}")
    print("| SNR dB | condition | pulses | found | onset error median / p99 / max (samples) | false pulses | "
          "dropped: reported missing / other reports |")
    print("|---|---|---|---|---|---|---|")
    for snr in (10, 20, 30, 40):
        for name in CONDITIONS:
            rs = [x for x in rows if x["snr"] == snr and x["cond"] == name]
            n, hit = sum(x["n"] for x in rs), sum(x["hit"] for x in rs)
            err = np.concatenate([x["err"] for x in rs]) if hit else np.array([np.nan])
            print(f"| {snr} | {name} | {n} | {hit / n:.2%} | {np.median(err):.2f} / {np.percentile(err, 99):.2f} / "
                  f"{err.max():.2f} | {sum(x['false'] for x in rs)} | {sum(x['flagged'] for x in rs)} of "
                  f"{sum(x['dropped'] for x in rs)} / {sum(x['wrong_flags'] for x in rs)} |")
    print(f"\nfind_onsets: {audio_s / sum(seconds):.0f}x real time (median {np.median(seconds):.2f} s per "
          f"{args.pulses + 1} s recording), one process")


if __name__ == "__main__":
    main()
