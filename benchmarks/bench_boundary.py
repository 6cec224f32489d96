"""The headset call on simulated walks: toward glass, mirrors and walls, and through openings.

    python3 benchmarks/bench_boundary.py [--rooms 30] [--seed 5000]

Each room (``random_scene``'s rooms and materials, seed ``--seed``) gets a glass pane, a mirror
and a door-sized opening on three of its walls, each reaching from near the floor to above head
height; a fourth wall is plain. A wearer (head 1.5 to 1.75 m high) walks toward each, at 0.5 to
2 m/s, from up to 3.5 m away, within 15 degrees of square, bobbing and swaying
(``vrecho.sim.walks``), with pink background noise 20 to 40 dB below the direct sound; closed
surfaces are walked to 15 cm, openings to their plane. Half the rooms run at 44.1 kHz, half at
48 kHz, in 10 ms blocks. Every walk is run twice: clean, and disturbed (the signal clipped at
half the direct sound's peak, a 20 ms dropout of zeros and a 10 ms block of NaNs every second,
and blocks of random sizes from 1 to 2048 samples).

The headset's camera (``vrecho.sim.walks.headset_frames``: 100 degrees, rendered with its depth
frame from the wearer's pose) shows the monitor a frame every 6 pulses (0.24 s), 50 ms after
the pulse it was taken at (``BoundaryMonitor.see``).

Reports: caution raised before 0.5 m on closed surfaces; the surface the alert names (glass,
mirror or wall) at the first caution and at the first stop, against the truth; false alarms on openings (any caution
or stop); the median and 90th percentile distance error (the reported distance against the
true distance at the measuring pulse, on closed walks while it reports the target); whether
"stop" came in the same block as the end of the echo that crossed 0.5 m; the
processing time per 10 ms block (one thread; the median and 99th percentile), against a
baseline timed beside every block: one matched filter (FFT correlation) of a 10 ms block; the
time per camera frame shown (off the audio thread).
"""

from __future__ import annotations

import argparse
import os
import platform
import time

os.environ.setdefault("OMP_NUM_THREADS", "1")  # one core, as a headset would give it

import numpy as np  # noqa: E402
from tqdm import tqdm  # noqa: E402

from vrecho.headset import BoundaryMonitor, ranging_probe  # noqa: E402
from vrecho.sim.render import World  # noqa: E402
from vrecho.scene import Discontinuity  # noqa: E402
from vrecho.sim.scenes import closed_absorption, random_scene  # noqa: E402
from vrecho.sim.walks import echo_round_trip_s, headset_frames, simulate_walk  # noqa: E402

KINDS = ("glass", "mirror", "wall", "open")


def bench_room(rng: np.random.Generator, k: int):
    scene = random_scene(rng, f"walk_{k:03d}", n_poses=0, n_sources=0, n_discontinuities=(1, 1))
    room = scene.room
    walls = [int(w) for w in rng.permutation(len(room.footprint)) if room.wall_lengths[w] >= 1.6][:4]
    if len(walls) < 4:
        return None
    scene.discontinuities = []
    targets = {}
    for kind, w in zip(KINDS, walls):
        length = room.wall_lengths[w]
        width = float(rng.uniform(1.0, min(2.0, length - 0.4)))
        u_c = float(rng.uniform(width / 2 + 0.1, length - width / 2 - 0.1))
        if kind == "open":
            z0, h = 0.0, float(rng.uniform(2.0, min(2.3, room.height_m - 0.1)))
        elif kind in ("glass", "mirror"):
            z0 = float(rng.uniform(0.1, 0.4))
            h = float(rng.uniform(1.9, room.height_m - 0.1)) - z0
        if kind != "wall":
            absorption = (1.0,) * 7 if kind == "open" else closed_absorption(kind, rng)
            scene.discontinuities.append(Discontinuity(w, u_c, z0 + h / 2, width, h, kind, absorption, 0.02))
        targets[kind] = (w, u_c)
    return scene, targets


def walk_for(scene, wall: int, u_c: float, rng: np.random.Generator):
    room = scene.room
    origin, u, normal = room.wall_frame(wall)  # normal: outward
    height = float(rng.uniform(1.5, 1.75))
    target = origin + u_c * u + [0.0, 0.0, height]
    angle = np.radians(rng.uniform(-15, 15))
    heading = np.cos(angle) * normal + np.sin(angle) * u  # toward the wall
    for d0 in np.arange(3.5, 0.9, -0.1):
        start = target - heading * d0 / np.cos(angle)  # d0 from the wall's plane
        if room.contains(start[None], margin_m=0.35)[0]:
            return start, start + heading, (origin, normal)
    return None


def disturb(x: np.ndarray, fs: int, rng: np.random.Generator) -> np.ndarray:
    y = np.clip(x, -0.25, 0.25)  # clipped at half the direct sound's peak
    for s in range(int(0.5 * fs), len(y), fs):
        a = s + int(rng.integers(0, fs // 2))
        y[a:a + int(0.02 * fs)] = 0.0  # dropout
        b = s + int(rng.integers(fs // 2, fs - int(0.01 * fs)))
        y[b:b + int(0.01 * fs)] = np.nan
    return y


_BASE = (np.random.default_rng(0).standard_normal(480), np.conj(np.fft.rfft(ranging_probe(48000), 1024)))


def baseline() -> None:
    """One FFT matched filter of a 10 ms block against the probe: timed beside every block, so
    that the machine's state (another process, a busy host) weighs on both alike."""
    from scipy import fft

    fft.irfft(fft.rfft(_BASE[0], 1024) * _BASE[1], 1024)


def run_walk(x: np.ndarray, fs: int, walk, kind: str, blocks: str, rng: np.random.Generator, frames: list) -> dict:
    mon = BoundaryMonitor(fs)
    period = mon.period
    n10 = int(0.01 * fs)
    first_alert = first_stop = None
    errors, times, see_s = [], [], []
    frames = list(frames)
    i = 0
    while i < len(x):
        n = n10 if blocks == "10ms" else int(rng.integers(1, 2049))
        block = x[i:i + n]
        t = time.perf_counter()
        a = mon.process(block)
        t1 = time.perf_counter()
        baseline()
        times.append((t1 - t, len(block), time.perf_counter() - t1))
        i += len(block)
        t_end = i / fs
        while frames and frames[0][0] <= t_end:
            t = time.perf_counter()
            mon.see(*frames.pop(0)[1:])
            see_s.append(time.perf_counter() - t)
        if a.pulse_time_s is not None and a.distance_m is not None and kind != "open":
            k = int(round(a.pulse_time_s * fs / period))
            if k < len(walk.distance_m) and abs(a.distance_m - walk.distance_m[k]) < 0.25:
                errors.append(abs(a.distance_m - walk.distance_m[k]))
        if a.level != "clear" and first_alert is None and t_end > 0.2:
            # The true distance when the alert came (the wearer kept walking after the pulse).
            now = min(int(t_end * fs / period), len(walk.distance_m) - 1)
            first_alert = {"distance_at_alert_m": float(walk.distance_m[now]), "level": a.level}
            alert_surface = a.surface
        if a.level == "stop" and first_stop is None and a.pulse_time_s is not None:
            stop_surface = a.surface
            # Was "stop" raised in the block in which the echo that crossed stop_m ended?
            k = min(int(round(a.pulse_time_s * fs / period)), len(walk.distance_m) - 1)
            echo_end = k * period / fs + walk.latency_s + echo_round_trip_s(a.distance_m) + len(mon.probe) / fs
            first_stop = bool(t_end - len(block) / fs < echo_end <= t_end + 1e-9)
    return {"first_alert": first_alert, "first_stop_same_block": first_stop, "errors": errors, "times": times,
            "alert_surface": alert_surface if first_alert else None,
            "stop_surface": stop_surface if first_stop is not None else None, "see_s": see_s}


def named(rows: list, key: str) -> str:
    """How often the surface named at ``key`` (on the walks that got there) is right."""
    said = [(r[key], r["kind"]) for r in rows if r[key] is not None]
    wrong = sum(a not in (k, "closed") for a, k in said)
    return (f"{sum(a == k for a, k in said)}/{len(said)} "
            f"({wrong} wrong, {sum(a == 'closed' for a, _ in said)} 'closed')")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rooms", type=int, default=30)
    ap.add_argument("--seed", type=int, default=5000)
    args = ap.parse_args()
    rows = []
    rng_rooms = np.random.default_rng(args.seed)
    made = 0
    bar = tqdm(total=args.rooms * len(KINDS), desc="walks", unit="walk")
    while made < args.rooms:
        built = bench_room(rng_rooms, made)
        if built is None:
            continue
        scene, targets = built
        world = World(scene)
        fs = (44100, 48000)[made % 2]
        for kind in KINDS:
            rng = np.random.default_rng([args.seed, made, KINDS.index(kind)])
            geometry = walk_for(scene, *targets[kind], rng)
            bar.update()
            if geometry is None:
                continue
            start, goal, plane = geometry
            speed = float(rng.uniform(0.5, 2.0))
            walk = simulate_walk(scene, start, goal, speed, ranging_probe(fs), 0.04, fs, rng, plane,
                                 stop_m=0.0 if kind == "open" else 0.15)
            frames = headset_frames(world, walk)
            for condition in ("clean", "disturbed"):
                x = walk.mic if condition == "clean" else disturb(walk.mic.copy(), fs, rng)
                r = run_walk(x, fs, walk, kind, "10ms" if condition == "clean" else "random", rng, frames)
                rows.append({"room": made, "kind": kind, "speed": speed, "fs": fs, "condition": condition,
                             "start_m": float(walk.distance_m[0]), **r})
        made += 1
    bar.close()

    print(f"\n{args.rooms} rooms (seed {args.seed}), {len(rows) // 2} walks, two conditions; "
          f"{platform.node()} {time.strftime('%Y-%m-%d')}")
    print("| condition | walks toward glass / mirror / wall | caution before 0.5 m | walks through openings "
          "| false alarms | distance error median / p90 | stop raised in the echo's block |")
    print("|---|---|---|---|---|---|---|")
    for condition in ("clean", "disturbed"):
        rs = [r for r in rows if r["condition"] == condition]
        closed = [r for r in rs if r["kind"] != "open"]
        opened = [r for r in rs if r["kind"] == "open"]
        hit = [r for r in closed if r["first_alert"] and r["first_alert"]["distance_at_alert_m"] >= 0.5]
        fa = [r for r in opened if r["first_alert"]]
        errs = np.array([e for r in closed for e in r["errors"]])
        same = [r["first_stop_same_block"] for r in closed if r["first_stop_same_block"] is not None]
        per_kind = " / ".join(str(sum(r["kind"] == k for r in closed)) for k in KINDS[:3])
        print(f"| {condition} | {per_kind} | {len(hit) / len(closed):.1%} ({len(hit)}/{len(closed)}) | {len(opened)} | "
              f"{len(fa) / max(len(opened), 1):.1%} ({len(fa)}/{len(opened)}) | "
              f"{np.median(errs) * 100:.2f} / {np.percentile(errs, 90) * 100:.2f} cm | {np.mean(same):.1%} |")
        for kind in KINDS[:3]:
            missed = [r for r in closed if r["kind"] == kind and r not in hit]
            if missed:
                print(f"  missed ({kind}): " + ", ".join(
                    f"room {r['room']} {r['speed']:.1f} m/s alert at "
                    f"{r['first_alert']['distance_at_alert_m']:.2f} m" if r["first_alert"] else
                    f"room {r['room']} {r['speed']:.1f} m/s no alert" for r in missed))
    print("\nThe surface the alert names at the first caution and at the first stop: right / all (named wrong; "
          "'closed': no frame has named it yet)")
    print("| condition | glass | mirror | wall | all |")
    print("|---|---|---|---|---|")
    for condition in ("clean", "disturbed"):
        cells = []
        for kinds in (("glass",), ("mirror",), ("wall",), KINDS[:3]):
            rs = [r for r in rows if r["condition"] == condition and r["kind"] in kinds]
            cells.append(" / ".join(named(rs, key) for key in ("alert_surface", "stop_surface")))
        print(f"| {condition} | " + " | ".join(cells) + " |")
        wrong = [f"room {r['room']} {r['kind']} {r['speed']:.1f} m/s: {r['stop_surface']}" for r in rows
                 if r["condition"] == condition and r["stop_surface"] is not None and r["stop_surface"] != r["kind"]]
        if wrong:
            print("  not right at stop: " + ", ".join(wrong))
    see = np.array([t * 1e3 for r in rows if r["condition"] == "clean" for t in r["see_s"]])
    print(f"camera frames shown: {len(see)} (clean), {np.mean(see):.1f} ms each (median {np.median(see):.1f}, "
          f"99th percentile {np.percentile(see, 99):.1f})")
    ms = np.array([t * 1e3 for r in rows if r["condition"] == "clean" for t, _, _ in r["times"]])  # 10 ms blocks
    base_ms = np.mean([b * 1e3 for r in rows if r["condition"] == "clean" for _, _, b in r["times"]])
    print(f"\nprocessing per 10 ms block (one thread): mean {np.mean(ms):.3f} ms, median {np.median(ms):.3f} ms, "
          f"99th percentile {np.percentile(ms, 99):.3f} ms; baseline (one 1024-point FFT matched filter of a "
          f"block, timed beside each block) {base_ms:.3f} ms: the mean is {np.mean(ms) / base_ms:.1f} x the baseline")


if __name__ == "__main__":
    main()
