"""A phone's 2-minute 1080p capture through `vrecho capture` (issue 9): how long it takes.

    python3 benchmarks/bench_capture.py [--seconds 120] [--cache DIR]

The capture is the built-in living room walked for ``--seconds`` seconds by the simulator
(:func:`vrecho.capture.simulate_capture`: the pulse train heard where the device is at each
pulse, the pictures rendered at 2 per second and scaled to 1920 x 1080 at 30 frames per second
with sensor noise, H.264 with AAC sound at 256 kbps in MP4, as a phone writes it; COLMAP's poses
of the pictures at 2 per second; the depth camera's mesh). Made once and cached (several
minutes). Then, each in a fresh process, as a user runs them:

- the baseline: PyAV decoding every picture and the sound of the video, nothing else;
- ``vrecho capture VIDEO``: pulses, frames, EchoCNN's answers, the pictures at the frames;
- ``vrecho capture VIDEO --poses --mesh``: all that, and the repair of the mesh.

Prints one table: wall time, times real time, and the ratio to the baseline.
"""

from __future__ import annotations

import argparse
import json
import platform
import subprocess
import sys
import time
from pathlib import Path

DECODE = """
import sys, av
with av.open(sys.argv[1]) as c:
    c.streams.video[0].thread_type = "AUTO"
    n = sum(1 for _ in c.decode(c.streams.video[0], c.streams.audio[0]))
print(n)
"""


def make(folder: Path, seconds: int) -> dict:
    from vrecho.sim.captures import simulate_capture
    from vrecho.camera import Camera
    from vrecho.scene import builtin_scene

    done = folder / "capture.json"
    if done.exists():
        return json.loads(done.read_text())
    sim = simulate_capture(builtin_scene(), folder, n_pulses=seconds, fps=2, camera=Camera(384, 216), seed=12,
                           audio_codec="aac", video=(1920, 1080, 30), progress=True)
    meta = {"video": str(sim["video"]), "poses": str(sim["poses"]), "mesh": str(sim["mesh"]), "fps": sim["fps"]}
    done.write_text(json.dumps(meta))
    return meta


def timed(args: list[str]) -> tuple[float, str]:
    t = time.perf_counter()
    p = subprocess.run(args, capture_output=True, text=True)
    if p.returncode:
        sys.exit(f"{' '.join(args)} failed:\n{p.stderr[-2000:]}")
    return time.perf_counter() - t, p.stdout


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=int, default=120)
    ap.add_argument("--cache", type=Path, default=Path.home() / ".cache" / "vrecho" / "bench_capture")
    args = ap.parse_args()
    import av

    folder = args.cache / f"living_room_{args.seconds}s"
    meta = make(folder, args.seconds)
    with av.open(meta["video"]) as c:
        v = c.streams.video[0]
        duration = float(c.duration / av.time_base)
        shape = f"{v.codec_context.width} x {v.codec_context.height}, {float(v.average_rate):.0f} fps, {v.frames} frames"
    py = sys.executable
    rows = [("PyAV decodes pictures and sound (baseline)", *timed([py, "-c", DECODE, meta["video"]]))]
    out = folder / "out"
    rows.append(("vrecho capture VIDEO", *timed([py, "-m", "vrecho", "capture", meta["video"], "--out",
                                                  str(out / "plain"), "--quiet"])))
    rows.append(("vrecho capture VIDEO --poses --mesh (and the repair)",
                 *timed([py, "-m", "vrecho", "capture", meta["video"], "--poses", meta["poses"], "--mesh",
                         meta["mesh"], "--image-fps", str(meta["fps"]), "--out", str(out / "posed"), "--quiet"])))
    print(f"\n{meta['video']}: {duration:.0f} s, {shape}; {platform.node()} ({platform.processor() or 'cpu'}), "
          f"{time.strftime('%Y-%m-%d')}")
    print("| run | wall time s | times real time | / baseline |")
    print("|---|---|---|---|")
    base = rows[0][1]
    for name, seconds, _ in rows:
        print(f"| {name} | {seconds:.1f} | {duration / seconds:.2f} | {seconds / base:.2f} |")
    print("\n" + rows[2][2].strip())


if __name__ == "__main__":
    main()
