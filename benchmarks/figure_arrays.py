"""Figure: what physics lets an array tell apart, against where each kind of source has its energy.

Top: for each array, how different two directions 30 degrees apart look to it at each
frequency (1 - the coherence of their steering vectors, azimuth 0 and 30 degrees in the
horizontal plane, far field; 0: the same, 1: orthogonal): a 9 x 5 cm array hears them alike below
about 1.5 kHz, the headset's 16 cm below about 1 kHz. Bottom: the share of each source kind's
power below each frequency (``vrecho.sim.sounds`` and ``vrecho.sim.arrays``' kinds, 20 s of
each at 16 kHz): a mains hum has most of its power below 1 kHz, where the small arrays cannot
separate it from another source by direction, whatever the method.

It also prints a table: for each array, the lowest frequency at which those two directions are
at least 0.2 apart (a plane wave's normalised beam power toward the other direction then at
most 0.64, its vote, the 8th power, under 3 %), and the share of each kind's power above it:
what direction alone can act on in a measure weighed by power (SI-SDR), whatever the method.
And a line per kind: the share of its time-frequency bins that vote in ``localization.locate``
(:func:`localization.onsets.onset_bins` on the same dry sound) and the share of those above
2 kHz: localization counts bins, not power.

Usage: python3 benchmarks/figure_arrays.py [--out docs/arrays_physics.png]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))


DISTINCT = 0.2
"""How far apart (1 - coherence) two directions must look for the table's frequency."""


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
    offsets = {}
    for name, arr in arrays.items():
        if arr is None:
            n = 2 if name.startswith("two") else 8
            ang = np.linspace(0, 2 * np.pi, n, endpoint=False)
            r = 0.025 if n == 2 else 0.125
            off = np.stack([np.zeros(n), r * np.cos(ang), r * np.sin(ang)], 1)
        else:
            off = np.asarray(arr.offsets, float)
        offsets[name] = off
        top.plot(freqs, distinctness(off, freqs), label=name)
    top.set_ylabel("1 - coherence, directions 30° apart")
    top.set_title("How far apart two directions look to the array")
    top.legend(fontsize=8)
    top.grid(alpha=0.3)
    fs = 16_000
    kinds = ("hum", "fan", "music", "speech", "tv")
    power, sounds = {}, {}
    for kind in kinds:
        x = sounds[kind] = source_sound(kind, 20.0, fs, rng)
        f, p = np.fft.rfftfreq(len(x), 1 / fs), np.abs(np.fft.rfft(x.astype(float))) ** 2
        power[kind] = (f, p)
        c = np.cumsum(p) / p.sum()
        bottom.plot(freqs, np.interp(freqs, f, c), label=kind)
    print(f"| array | directions 30 degrees apart at least {DISTINCT} apart from | "
          + " | ".join(f"{k}: power above it" for k in kinds) + " |")
    print("|---|---:|" + "---:|" * len(kinds))
    fine = np.linspace(50, 8000, 8000)
    for name, off in offsets.items():
        f0 = float(fine[np.argmax(distinctness(off, fine) >= DISTINCT)])
        shares = [f"{p[f >= f0].sum() / p.sum():.0%}" for f, p in power.values()]
        print(f"| {name} | {f0:.0f} Hz | " + " | ".join(shares) + " |")
    import importlib

    from localization.onsets import onset_bins

    loc = importlib.import_module("localization.locate")
    band = loc.band_bins(fs)
    high = np.fft.rfftfreq(loc.NFFT, 1 / fs)[band] > 2000
    for kind, x in sounds.items():
        keep = onset_bins((np.abs(loc.stft(x.astype(np.float32)[None])[:, band]) ** 2).sum(axis=0))
        print(f"{kind}: {keep.mean():.0%} of its bins vote, {keep[high].sum() / max(keep.sum(), 1):.0%} of those above 2 kHz")
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
