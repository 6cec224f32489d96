"""The README's localization figure: one benchmark room seen from above.

The world map of vrecho's ``locate`` (each capture's onset votes toward every point, averaged
over captures; the highest point over height shown), the headset's poses along the walk with
their forward axes, the true sources and the located ones.

Usage: python3 benchmarks/figure_localization.py [--seed 7000] [--room 0] [--rooms 50] [--out docs/localization.png]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seed", type=int, default=7000)
    ap.add_argument("--room", type=int, default=0)
    ap.add_argument("--rooms", type=int, default=50, help="the benchmark's number of rooms (it spreads RT60 over them)")
    ap.add_argument("--out", type=Path, default=ROOT / "docs" / "localization.png")
    a = ap.parse_args()
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from bench_localization import main_condition, simulate_room
    from localization import locate
    from localization.locate import Votes, grid_points

    n_src, rt60 = main_condition(a.room, a.rooms)
    room, sim = simulate_room(a.seed + a.room, n_src, rt60)
    sources, poses = sim.sources, sim.poses
    found = locate(sim.captures, bounds=((0, 0, 0), room.dims))
    votes = Votes(sim.captures)
    step = 0.05
    grid = grid_points(np.zeros(3), np.array(room.dims), step)
    shape = [len(np.arange(0, d + 1e-9, step)) for d in room.dims]
    world = votes.power(grid).reshape(shape).max(axis=2)
    fig, ax = plt.subplots(figsize=(7, 7 * room.dims[1] / room.dims[0] + 0.5))
    ax.imshow(world.T, origin="lower", extent=(0, room.dims[0], 0, room.dims[1]), cmap="magma")
    for p in poses:
        ax.plot(*p.emitter[:2], "o", color="deepskyblue", ms=5)
        ax.arrow(*p.emitter[:2], *(0.35 * p.forward[:2]), color="deepskyblue", head_width=0.06)
    for s in sources:
        ax.plot(*s.position[:2], "x", color="lime", ms=12, mew=3)
        ax.annotate(s.name, s.position[:2], xytext=(6, 6), textcoords="offset points", color="lime")
    for x, u in zip(found.positions, found.uncertainty_m):
        ax.plot(*x[:2], "o", mfc="none", mec="white", ms=14, mew=2)
        ax.annotate(f"+/- {u:.2f} m", x[:2], xytext=(6, -14), textcoords="offset points", color="white")
    ax.set(xlabel="x (m)", ylabel="y (m)",
           title=f"RT60 {room.rt60_s:.2f} s: headset poses (blue), true sources (green x), located (white o)")
    fig.tight_layout()
    a.out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(a.out, dpi=110)
    print(f"{a.out}: {len(found.positions)} found of {n_src}; errors",
          np.round([np.min(np.linalg.norm(found.positions - s.position, axis=1)) for s in sources], 2))


if __name__ == "__main__":
    main()
