"""Issue 27: open/closed with the surface's distance known (``predict(..., surface_m=)``), across
the operating envelope, each condition on its own row.

Frames of :func:`vrecho.sim.devices.echo_frame`: the user's own broadband probe
(``random_probe``) passed as ``emitted``; ``surface_m`` the true distance plus a normal error of
2 cm (a scan's plane). Conditions (:data:`vrecho.sim.devices.CONDITIONS`): those of
:data:`TUNING` were used to tune :data:`vrecho.planes.SURFACE_WEIGHTS` (``--fit``, seeds
100 000 +); :data:`HELD_OUT` (AAC, 48 kHz, and all at once) never were. Every row here is on seeds
200 000 + (rooms and devices never used for tuning).

A second table pools the frames by the surface's distance. A third asks about walks
(:func:`vrecho.sim.devices.echo_frames`, seeds 300 000 +, never tuned on): 6 frames of one
device stepping about in front of one surface, each frame asked with its own distance (the
scan's plane, off by a normal 2 cm for the walk, and the pose's, 5 mm per frame), the answers
fused by :func:`vrecho.planes.fuse_open` over the first 1, 3 and 6 frames, and all 6 asked
with the device's geometry known (``mic_toward_surface_m``, as the reconstruction asks); then
the same walks by :func:`vrecho.planes.plane_open`, the plane's echo sought at one offset for
all the frames (its one number, :data:`~vrecho.planes.WALK_BIAS`, fitted by ``--fit`` on
walks of the tuning conditions, seeds 150 000 +).

Per condition: frames, open/closed accuracy with ``surface_m`` (the physics), the expected
calibration error of its probability (10 bins; beside it, what a perfectly calibrated model's
would be on as many frames by chance: :func:`ece_floor`), and the share of frames where another echo of the room (an image source of order 1 to
3 that never touches the surface: the floor, the ceiling, another wall, a corner of the
surface's wall with one of them) arrives within the window the echo is looked for in (:func:`crowded`):
one microphone hears delays, not directions, so those frames are bounded by physics. The last
column bounds it: the same features read at the echo's exact path (the true distance and the
microphone's true offset, :func:`exact`), weighed by a logistic fitted on the tuning frames.
A second table asks the same frames without ``surface_m``: EchoCNN-E, the shipped model (the
probe known; its device frames, ``vrecho generate --preset devices``, are of the tuning
conditions, other seeds), its open/closed, calibration and depth on closed surfaces; EchoCNN-A
(the paper's protocol, the probe unknown).

Usage: ``python3 benchmarks/bench_surface.py [--frames 60] [--walks 20] [--fit]``; ``--fit`` tunes
the weights on the tuning seeds and conditions and prints them (to paste into the classifier).
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
from multiprocessing import get_context

import numpy as np

from vrecho.learn.devices import calibration_error as ece
from vrecho.sim.devices import TUNING

HELD_OUT = ("AAC", "48 kHz", "envelope")
SURFACE_ERROR_M = 0.02
POSE_ERROR_M = 0.005
WALK = 6


def _frame(args):
    condition, seed, cache = args
    from vrecho.sim.devices import echo_frame

    rng = np.random.default_rng(seed)
    f = echo_frame(rng, condition, cache=cache)
    given = f.depth_m + rng.normal(0, SURFACE_ERROR_M)
    return f, given, crowded(f, given)


def crowded(f, given: float, toward: float | None = None) -> bool:
    """Whether another echo of the room (:attr:`~vrecho.sim.devices.EchoFrame.paths_m`) lies in
    the window :func:`vrecho.planes.plane_echo` looks in at the distance ``given``
    (:func:`vrecho.planes.plane_window_m`; with the microphone ``toward`` the plane known or not)."""
    from vrecho.planes import plane_window_m

    lo, hi = plane_window_m(given, float(np.linalg.norm(f.device.mic_m)), mic_toward_m=toward)
    return any(lo <= p <= hi for p in f.paths_m)


def _walk(args):
    condition, seed, cache = args
    from vrecho.sim.devices import echo_frames

    rng = np.random.default_rng(seed)
    fs = echo_frames(rng, condition, WALK, cache=cache)
    given = np.array([f.depth_m for f in fs]) + rng.normal(0, SURFACE_ERROR_M) + rng.normal(0, POSE_ERROR_M, WALK)
    return fs, given


def frames(conditions, n: int, base: int, cache, task=_frame):
    jobs = [(c, base + 1000 * k + i, cache) for k, c in enumerate(conditions) for i in range(n)]
    with get_context("spawn").Pool(min(2, os.cpu_count() or 1)) as pool:
        return pool.map(task, jobs, chunksize=4 if task is _frame else 1)


def ask(clf, frames, **kw) -> list:
    """``clf.predict_batch`` of :class:`~vrecho.sim.devices.EchoFrame` s, their probes as
    ``emitted``, a batch per recording rate; per-frame keywords (arrays) are split alike; the
    answers in the frames' order. ``emitted=None`` asks without the probe."""
    out = [None] * len(frames)
    with_probe = kw.pop("emitted", True) is not None
    for fs in sorted({f.device.fs for f in frames}):
        idx = [i for i, f in enumerate(frames) if f.device.fs == fs]
        part = {k: (np.asarray(v)[idx] if np.ndim(v) else v) for k, v in kw.items()}
        if with_probe:
            part["emitted"] = np.stack([frames[i].emitted for i in idx])
        for i, p in zip(idx, clf.predict_batch(np.stack([frames[i].audio for i in idx]), fs, **part)):
            out[i] = p
    return out


def ece_floor(p: np.ndarray, draws: int = 400) -> float:
    """The median :func:`ece` of a perfectly calibrated model giving the probabilities ``p``
    (each answer drawn true with its own probability): what so few frames show by chance alone
    (60 frames of spread-out probabilities: some 11 %; 720: some 3 %)."""
    rng = np.random.default_rng(0)
    return float(np.median([ece(p, rng.random(len(p)) < p) for _ in range(draws)]))


def exact(rows) -> np.ndarray:
    """:func:`vrecho.planes.plane_echo`'s features of frames asked at their surface's exact
    distance and the microphone's exact offset toward it (1 mm of tolerance): what one frame's
    microphone holds where the echo must be, with nothing of the scan's or the pose's error."""
    from vrecho.planes import plane_echo

    out = np.empty((len(rows), 6))
    for fs in sorted({r[0].device.fs for r in rows}):
        idx = [i for i, r in enumerate(rows) if r[0].device.fs == fs]
        f = [rows[i][0] for i in idx]
        out[idx] = plane_echo(np.stack([x.audio for x in f]), np.stack([x.emitted for x in f]), [x.depth_m for x in f],
                              fs, tolerance_m=0.001, mic_toward_m=[x.mic_toward_m for x in f]).features
    return out


def bound(cache, n: int):
    """The exact path's logistic (:func:`exact`'s features), fitted on the tuning frames as
    :data:`~vrecho.planes.SURFACE_WEIGHTS` are: how well one frame could do were the scan and
    the pose exact, the room's other echoes at the echo's own delay and the loudspeaker's
    directivity all that is left."""
    from sklearn.linear_model import LogisticRegression

    rows = frames(TUNING, n, 100_000, cache)
    return LogisticRegression(C=0.1, max_iter=5000).fit(exact(rows), [r[0].is_open for r in rows])


def walk_scores(rows, geometry: bool, k: int = WALK) -> np.ndarray:
    """:func:`vrecho.planes.plane_open`'s log-odds toward closed, before :data:`WALK_BIAS`, of
    walks (:func:`_walk`'s) from their first ``k`` frames, with the device's geometry known or not."""
    from vrecho.planes import WALK_BIAS, plane_open

    out = []
    for fs_, given in rows:
        fs_, given = fs_[:k], given[:k]
        toward = [f.mic_toward_m for f in fs_] if geometry else None
        a = plane_open(np.stack([f.audio for f in fs_]), fs_[0].device.fs, emitted=fs_[0].emitted, surface_m=given,
                       mic_toward_surface_m=toward)
        out.append(-np.log(a.p_open / (1 - a.p_open)) - WALK_BIAS)
    return np.array(out)


def fit_walk_bias(cache, n: int) -> None:
    """:data:`vrecho.planes.WALK_BIAS` fitted on walks of the tuning conditions (seeds
    150 000 +), their first 3 and all 6 frames, geometry known and not (the log-odds' scale held
    at 1), and printed."""
    from scipy.optimize import minimize_scalar

    rows = frames(TUNING, n, 150_000, cache, task=_walk)
    y = np.array([not fs_[0].is_open for fs_, _ in rows])
    z = np.concatenate([walk_scores(rows, g, k) for g in (False, True) for k in (3, WALK)])
    y = np.tile(y, 4)
    loss = minimize_scalar(lambda b: float(np.mean(np.logaddexp(0, -(2 * y - 1) * (z + b)))), bounds=(-5, 5),
                           method="bounded")
    print(f"tuned on {len(rows)} walks of {WALK} frames ({', '.join(TUNING)}; seeds 150000+): WALK_BIAS =",
          round(float(loss.x), 2), f"(accuracy {np.mean((z + loss.x > 0) == y):.3f})")


def main() -> None:
    from vrecho.sim.devices import CONDITIONS

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=60, help="frames per condition")
    ap.add_argument("--walks", type=int, default=20, help="walks per condition")
    ap.add_argument("--fit", action="store_true", help="tune the weights on the tuning seeds and print them")
    a = ap.parse_args()
    cache = os.environ.get("VRECHO_CACHE") or tempfile.mkdtemp(prefix="vrecho-surface-")
    if a.fit:
        from sklearn.linear_model import LogisticRegression

        from vrecho.planes import plane_echo

        rows = frames(TUNING, a.frames, 100_000, cache)
        x = plane_echo(np.stack([r[0].audio for r in rows]), np.stack([r[0].emitted for r in rows]),
                       np.array([r[1] for r in rows])).features
        y = np.array([not r[0].is_open for r in rows])  # closed
        m = LogisticRegression(C=0.1, max_iter=5000).fit(x, y)
        print(f"tuned on {len(rows)} frames ({', '.join(TUNING)}; seeds 100000+): accuracy {m.score(x, y):.3f}")
        print("SURFACE_WEIGHTS =", tuple(round(float(w), 4) for w in m.coef_[0]))
        print("SURFACE_BIAS =", round(float(m.intercept_[0]), 4))
        fit_walk_bias(cache, a.walks)
        return
    import vrecho

    clf = vrecho.load_classifier()
    rows = frames(CONDITIONS, a.frames, 200_000, cache)
    oracle = bound(cache, 100)
    print(f"open/closed across the envelope: {a.frames} frames per condition, seeds 200000+ (never tuned on); "
          f"surface_m = truth + N(0, {100 * SURFACE_ERROR_M:.0f} cm)\n")
    print("| condition | tuned on | frames | open | with surface_m | calibration error (a calibrated model's by chance) "
          "| another echo in the window | with surface_m, the others | at the exact distance and pose |")
    print("|---|---|---|---|---|---|---|---|---|")
    keys = ("with", "without", "p", "y", "amb", "pe", "pa", "d", "wg", "pg", "ambg", "ex", "de")
    pooled = {k: [] for k in keys}
    geometry, models = [], []
    for c in (*CONDITIONS, "all"):
        sel = rows if c == "all" else [r for r in rows if r[0].condition == c]
        if c == "all":
            w, wo, p, y, amb, pe, pa, d, wg, pg, ambg, ex, de = (np.concatenate(pooled[k]) for k in keys)
        else:
            fr = [r[0] for r in sel]
            given = np.array([r[1] for r in sel])
            toward = np.array([f.mic_toward_m for f in fr])
            y = np.array([f.is_open for f in fr])
            with_s = ask(clf, fr, surface_m=given)
            with_g = ask(clf, fr, surface_m=given, mic_toward_surface_m=toward)
            without = ask(clf, fr)
            pe = np.array([q.probabilities["open"] for q in without])
            de = np.array([q.depth_m for q in without])
            pa = np.array([q.probabilities["open"] for q in ask(clf, fr, emitted=None)])
            p = np.array([q.probabilities["open"] for q in with_s])
            pg = np.array([q.probabilities["open"] for q in with_g])
            w, wg = (p > 0.5) == y, (pg > 0.5) == y
            wo = (pe > 0.5) == y
            amb = np.array([r[2] for r in sel])
            ambg = np.array([crowded(r[0], r[1], r[0].mic_toward_m) for r in sel])
            d = np.array([r[0].depth_m for r in sel])
            ex = oracle.predict(exact(sel)) == y
            for k, v in zip(keys, (w, wo, p, y, amb, pe, pa, d, wg, pg, ambg, ex, de)):
                pooled[k].append(v)
        clear = w[~amb].mean() if (~amb).any() else float("nan")
        tuned = "partly" if c == "all" else "no" if c in HELD_OUT else "yes"
        print(f"| {c} | {tuned} | {len(w)} | {np.mean(y):.0%} | {w.mean():.1%} | {ece(p, y):.1%} ({ece_floor(p):.1%}) "
              f"| {amb.mean():.0%} | {clear:.1%} | {ex.mean():.1%} |", flush=True)
        err = 100 * np.abs(de - d)[~y]  # a closed surface's depth; an opening has none
        models.append(f"| {c} | {tuned} | {len(w)} | {wo.mean():.1%} | {ece(pe, y):.1%} ({ece_floor(pe):.1%}) "
                      f"| {np.median(err):.1f} | {np.mean(err <= 10):.0%} | {np.mean((pa > 0.5) == y):.1%} | {ece(pa, y):.1%} |")
        geometry.append(f"| {c} | {len(w)} | {wg.mean():.1%} | {ece(pg, y):.1%} | {ambg.mean():.0%} "
                        f"| {wg[~ambg].mean() if (~ambg).any() else float('nan'):.1%} |")
    print("\nwithout surface_m: EchoCNN-E (the probe known), its depth on closed surfaces; EchoCNN-A (the probe "
          "unknown); the same frames\n")
    print("| condition | tuned on | frames | EchoCNN-E | calibration error (by chance) | closed: depth error median, cm "
          "| closed: within 10 cm | EchoCNN-A | calibration error |")
    print("|---|---|---|---|---|---|---|---|---|")
    print("\n".join(models), flush=True)
    print("\nwith the microphone's place on the device and the device's pose known (mic_toward_surface_m, "
          "as a scan knows them): the same frames\n")
    print("| condition | frames | with surface_m | calibration error | another echo in the window | the others |")
    print("|---|---|---|---|---|---|")
    print("\n".join(geometry), flush=True)
    w, wo, p, y, amb, pe, pa, d, *_ = (np.concatenate(pooled[k]) for k in keys)
    print("\nby the surface's distance, every condition pooled\n")
    print("| distance | frames | another echo in the window | with surface_m | the others (no other echo in the window) | EchoCNN-E | calibration error, surface_m |")
    print("|---|---|---|---|---|---|---|")
    for lo, hi in ((0.25, 1.0), (1.0, 2.0), (2.0, 3.01)):
        m = (d >= lo) & (d < hi)
        print(f"| {lo:g} to {min(hi, 3):g} m | {m.sum()} | {amb[m].mean():.0%} | {w[m].mean():.1%} | {w[m & ~amb].mean():.1%} | {wo[m].mean():.1%} "
              f"| {ece(p[m], y[m]):.1%} |", flush=True)
    walks(clf, CONDITIONS, a.walks, cache)


def walks(clf, conditions, n: int, cache) -> None:
    """The walks' table: open/closed of each walk's surface from its first 1, 3 and :data:`WALK`
    frames, fused, and by one plane for all its frames (:func:`vrecho.planes.plane_open`)."""
    from scipy.special import expit

    from vrecho.planes import WALK_BIAS, fuse_open

    rows = frames(conditions, n, 300_000, cache, task=_walk)
    flat = [f for fs, _ in rows for f in fs]
    given = np.concatenate([g for _, g in rows])
    y = np.array([fs[0].is_open for fs, _ in rows])
    cond = np.array([fs[0].condition for fs, _ in rows])
    ks = (1, 3, WALK)
    p = {}
    one = {(g, k): expit(-(walk_scores(rows, g, k) + WALK_BIAS)) for g in (False, True) for k in (3, WALK)}
    for geometry in (False, True):
        kw = {"mic_toward_surface_m": np.array([f.mic_toward_m for f in flat])} if geometry else {}
        preds = ask(clf, flat, surface_m=given, **kw)
        preds = [preds[i:i + WALK] for i in range(0, len(preds), WALK)]
        p.update({(geometry, k): np.array([fuse_open(q[:k]) for q in preds]) for k in ks})
    print(f"\nwalks: {n} per condition of {WALK} frames in front of one surface (seeds 300000+, never tuned on), "
          f"the answers fused (fuse_open) over the first 1, 3 and {WALK} frames; then {WALK} frames with the "
          "device's geometry known (mic_toward_surface_m); then one plane for all the frames (plane_open) "
          f"over 3 and {WALK} frames, and {WALK} with the geometry known\n")
    print("| condition | walks | open | 1 frame | 3 frames | 6 frames | calibration error, 1 / 3 / 6 | 6 frames, geometry known "
          "| one plane: 3 / 6 frames | one plane, geometry known: 6 frames | calibration error, one plane: 6 / 6 known |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    for c in (*conditions, "all"):
        m = np.ones(len(y), bool) if c == "all" else cond == c
        acc = " | ".join(f"{np.mean((p[False, k][m] > 0.5) == y[m]):.1%}" for k in ks)
        print(f"| {c} | {m.sum()} | {y[m].mean():.0%} | {acc} | {' / '.join(f'{ece(p[False, k][m], y[m]):.1%}' for k in ks)} "
              f"| {np.mean((p[True, WALK][m] > 0.5) == y[m]):.1%} "
              f"| {np.mean((one[False, 3][m] > 0.5) == y[m]):.1%} / {np.mean((one[False, WALK][m] > 0.5) == y[m]):.1%} "
              f"| {np.mean((one[True, WALK][m] > 0.5) == y[m]):.1%} "
              f"| {ece(one[False, WALK][m], y[m]):.1%} / {ece(one[True, WALK][m], y[m]):.1%} |", flush=True)


if __name__ == "__main__":
    sys.exit(main())
