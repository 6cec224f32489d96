"""Figure: what physics lets an array tell apart, against where each kind of source has its energy.

Top: for each array, how different two directions 30 degrees apart look to it at each
frequency (1 - the coherence of their steering vectors, azimuth 0 and 30 degrees in the
horizontal plane, far field; 0: the same, 1: orthogonal): a 9 x 5 cm array hears them alike below
about 1.5 kHz, the headset's 16 cm below about 1 kHz. Bottom: the share of each source kind's
power below each frequency (``vrecho.sim.sounds`` and ``vrecho.sim.arrays``' kinds, 20 s of
each at 16 kHz): a mains hum has most of its power below 1 kHz, where the small arrays cannot
separate it from another source by direction, whatever the method.

Usage: python3 benchmarks/figure_arrays.py [--out docs/arrays_physics.png]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))


def distinctness(offsets: np.ndarray, freqs: np.ndarray, angle_deg: float = 30.0) -> np.ndarray:
    """1 - |a0^H a1| / M for plane waves from azimuth 0 and ``angle_deg`` (device frame)."""
    u0 = np.array([1.0, 0.0, 0.0])
    a = np.radians(angle_deg)
    u1 = np.array([np.cos(a), np.sin(a), 0.0])
    d0, d1 = offsets @ u0 / 343.0, offsets @ u1 / 343.0
    a0 = np.exp(2j * np.pi * freqs[:, None] * d0[None])
    a1 = np.exp(2j * np.pi * freqs[:, None] * d1[None])
    return 1 - np.abs((np.conj(a0) * a1).sum(axis=1)) / len(offsets)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--out", type=Path, default=ROOT / "docs" / "arrays_physics.png")
    a = ap.parse_args()
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from vrecho.device import MIC_ARRAYS
    from vrecho.sim.arrays import FLAT_9X5, source_sound

    freqs = np.linspace(50, 8000, 800)
    arrays = {"headset4 (16 cm)": MIC_ARRAYS["headset4"], "flat 9 x 5 cm": FLAT_9X5,
              "two microphones 5 cm apart": None, "8 microphones, 25 cm": None}
    rng = np.random.default_rng(0)
    fig, (top, bottom) = plt.subplots(2, 1, figsize=(8, 7), sharex=True)
    for name, arr in arrays.items():
        if arr is None:
            n = 2 if name.startswith("two") else 8
            ang = np.linspace(0, 2 * np.pi, n, endpoint=False)
            r = 0.025 if n == 2 else 0.125
            off = np.stack([np.zeros(n), r * np.cos(ang), r * np.sin(ang)], 1)
        else:
            off = np.asarray(arr.offsets, float)
        top.plot(freqs, distinctness(off, freqs), label=name)
    top.set_ylabel("1 - coherence, directions 30° apart")
    top.set_title("How far apart two directions look to the array")
    top.legend(fontsize=8)
    top.grid(alpha=0.3)
    fs = 16_000
    for kind in ("hum", "fan", "music", "speech", "tv"):
        x = source_sound(kind, 20.0, fs, rng).astype(float)
        f, p = np.fft.rfftfreq(len(x), 1 / fs), np.abs(np.fft.rfft(x)) ** 2
        c = np.cumsum(p) / p.sum()
        bottom.plot(freqs, np.interp(freqs, f, c), label=kind)
    bottom.set_ylabel("share of the source's power below f")
    bottom.set_xlabel("frequency f (Hz)")
    bottom.set_xscale("log")
    bottom.legend(fontsize=8)
    bottom.grid(alpha=0.3)
    fig.tight_layout()
    a.out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(a.out, dpi=110)
    print(f"wrote {a.out}")


if __name__ == "__main__":
    main()
