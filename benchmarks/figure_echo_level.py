"""The headset call's misses against what the microphone held: each walk toward glass, a mirror or a
wall of a ``bench_boundary.py --out DIR`` run, its echo level at 1.5 to 1 m (:func:`bench_boundary.echo_level`:
the echo's envelope over the envelope's median; noise alone about 2) by row, cautioned in time or not.

Usage: python3 benchmarks/figure_echo_level.py DIR [--out docs/boundary_echo_level.png]
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("dir", type=Path, help="a bench_boundary.py --out folder")
    ap.add_argument("--out", type=Path, default=ROOT / "docs" / "boundary_echo_level.png")
    a = ap.parse_args()
    import matplotlib  # heavy (0.5 s to import): only the figure needs it

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # heavy: as above

    from bench_boundary import CLOSED, cautioned

    walks = [w for w in json.loads((a.dir / "walks.json").read_text())
             if w.get("kind") in CLOSED and "echo_level" in w and np.isfinite(w["echo_level"][2])]
    rows = list(dict.fromkeys(w["row"] for w in walks))
    rng = np.random.default_rng(0)
    fig, ax = plt.subplots(figsize=(8, 0.35 * len(rows) + 1.6))
    for i, row in enumerate(rows):
        for w in (w for w in walks if w["row"] == row):
            ok = cautioned(w)
            ax.scatter(w["echo_level"][2], i + rng.uniform(-0.25, 0.25), s=12 if ok else 28,
                       c="tab:green" if ok else "tab:red", marker="o" if ok else "x", alpha=0.6 if ok else 0.9, lw=1.2)
    ax.axvline(2.0, color="0.5", ls=":", lw=1)
    ax.text(2.0, len(rows) - 0.4, " noise alone", color="0.4", fontsize=8)
    ax.set_xscale("log")
    ticks = [1, 1.5, 2, 3, 5, 10, 20, 50, 100]
    ax.set_xticks(ticks, [f"{t:g}" for t in ticks])
    ax.xaxis.set_minor_locator(matplotlib.ticker.NullLocator())
    ax.set_yticks(range(len(rows)), rows)
    ax.invert_yaxis()
    ax.set_xlabel("echo level at 1.5 to 1 m: the echo's envelope over the envelope's median (log)")
    ax.scatter([], [], c="tab:green", s=12, label="caution before 0.5 m")
    ax.scatter([], [], c="tab:red", marker="x", s=28, label="caution late or none")
    ax.legend(loc="lower right", fontsize=8)
    ax.set_title("The headset call: walks toward glass, mirrors and walls", fontsize=10)
    fig.tight_layout()
    a.out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(a.out, dpi=120)
    print(a.out)


if __name__ == "__main__":
    main()
