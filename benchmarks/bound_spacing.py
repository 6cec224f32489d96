"""What the headset call's distance can be when the loudspeaker-to-microphone offset is not given
(``bench_boundary.py``'s row "spacing not given": the monitor then assumes 7 cm across).

A surface straight ahead at ``d`` returns its echo along the path from the loudspeaker's image,
2 d ahead, to the microphone, which sits ``f`` ahead of the loudspeaker and ``s`` from it; the
monitor times the echo against the direct sound: sqrt(4 d^2 - 4 d f + s^2) - s. For a given
spacing, each forward part ``f`` has its own distance that returns the same echo, so no one echo
tells them apart, and the error is about half the forward part the monitor assumed wrongly (the
floor's, the ceiling's and a corner's echoes can tell ``s``; the curvature of a surface's echo
over a walk, a few millimetres, the size of the offset across the way, and so at most the size
of ``f``, never its sign). Over the benchmark's headsets (:func:`bench_boundary.any_headset`: 1
to 15 cm in any direction), surfaces 0.5 to 3 m ahead, this prints the distance error of the
monitor's assumption, of one that knew the spacing but not its direction (the forward part taken
as 0), and with the offset given.

Usage: python3 benchmarks/bound_spacing.py [--n 20000] [--seed 0]
"""

from __future__ import annotations

import argparse

import numpy as np

from bench_boundary import any_headset
from vrecho.headset.kernels import echo_distance, echo_path


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=20000, help="headsets drawn (one surface each)")
    ap.add_argument("--seed", type=int, default=0)
    a = ap.parse_args()
    rng = np.random.default_rng(a.seed)
    rows = {"assumed 7 cm across (the monitor)": [], "spacing known, its direction not": [], "offset given": []}
    for _ in range(a.n):
        off = np.asarray(any_headset(rng).mic_offset_m)
        s, f, d = float(np.linalg.norm(off)), float(off[0]), float(rng.uniform(0.5, 3.0))
        excess = echo_path(d, s, f)  # what the microphone times: the echo's path less the direct sound's
        for name, (s_m, f_m) in zip(rows, ((0.07, 0.0), (s, 0.0), (s, f))):
            rows[name].append(abs(echo_distance(excess, s_m, f_m) - d) * 100)
    print(f"Distance error, surfaces 0.5 to 3 m straight ahead, {a.n} headsets of bench_boundary.any_headset "
          f"(seed {a.seed})\n")
    print("| the monitor knows | median cm | 90th percentile cm | within 1 cm |")
    print("|:---|---:|---:|---:|")
    for name, e in rows.items():
        e = np.array(e)
        print(f"| {name} | {np.median(e):.2f} | {np.percentile(e, 90):.2f} | {np.mean(e <= 1.0) * 100:.0f} % |")


if __name__ == "__main__":
    main()
