"""The README's separation figure: one room of the benchmark's target condition, capture 4.

Spectrograms at microphone 0: the mixture, and for each source its reverberant image (the
reference), vrecho's informed separation (located positions) and pyroomacoustics' AuxIVA, each
titled with its SDR improvement.

Usage: python3 benchmarks/figure_separation.py [--seed 7000] [--room 0] [--out docs/separation.png]
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
    ap.add_argument("--seed", type=int, default=7000, help="the benchmark's seed (its target rooms start at seed + 300)")
    ap.add_argument("--room", type=int, default=0)
    ap.add_argument("--out", type=Path, default=ROOT / "docs" / "separation.png")
    a = ap.parse_args()
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from bench_localization import TARGET_RT60, TARGET_SEED_OFFSET, separation_metrics, simulate_room
    from localization import locate, separate
    from localization.separate import analysis

    room, sim = simulate_room(a.seed + TARGET_SEED_OFFSET + a.room, 2, TARGET_RT60)
    cap, ref = sim.captures[4], sim.images[4, :, 0]
    found = locate(sim.captures, 2, bounds=((0, 0, 0), room.dims))
    sdr0, _ = separation_metrics(ref, np.repeat(cap.audio[:1], 2, axis=0), perm=False)
    outs = {}
    for name, method in (("vrecho informed", "informed"), ("AuxIVA", "auxiva")):
        y = separate(cap, 2, method=method, positions=found.positions)
        err = np.array([[np.sum((r - e) ** 2) for e in y] for r in ref])  # the output that matches each reference
        y = y[[0, 1] if err[0, 0] + err[1, 1] <= err[0, 1] + err[1, 0] else [1, 0]]
        outs[name] = (y, separation_metrics(ref, y, perm=False)[0] - sdr0)

    def spec(x):
        return 10 * np.log10(np.abs(analysis(x[None], 512)[:, :, 0].T) ** 2 + 1e-10)

    top = spec(cap.audio[0]).max()
    kw = dict(origin="lower", aspect="auto", cmap="magma", vmin=top - 70, vmax=top,
              extent=(0, cap.audio.shape[1] / cap.fs, 0, cap.fs / 2000))
    fig, axes = plt.subplots(3, 3, figsize=(12, 8), sharex=True, sharey=True)
    axes[0, 0].imshow(spec(cap.audio[0]), **kw)
    axes[0, 0].set_title("mixture at microphone 0")
    for ax in axes[0, 1:]:
        ax.axis("off")
    for k, s in enumerate(sim.sources):
        d = np.linalg.norm(s.position - cap.center)
        axes[k + 1, 0].imshow(spec(ref[k]), **kw)
        axes[k + 1, 0].set_title(f"{s.name} ({d:.1f} m away): reference")
        for j, (name, (y, gain)) in enumerate(outs.items()):
            axes[k + 1, j + 1].imshow(spec(y[k]), **kw)
            axes[k + 1, j + 1].set_title(f"{name}: SDR {gain[k]:+.1f} dB")
    for ax in axes[:, 0]:
        ax.set_ylabel("kHz")
    for ax in axes[-1]:
        ax.set_xlabel("s")
    fig.suptitle(f"Target room {a.room} (seed {a.seed + TARGET_SEED_OFFSET + a.room}): 2 sources, RT60 {TARGET_RT60} s, "
                 "the headset's 4 microphones, 1.5 s")
    fig.tight_layout()
    a.out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(a.out, dpi=90)
    print(a.out, {n: np.round(g, 1).tolist() for n, (_, g) in outs.items()})


if __name__ == "__main__":
    main()
