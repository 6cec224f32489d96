"""Benchmark of localization (issue 5): direction, position and separation on simulated rooms.

Each room: a shoebox 3.5-7 x 3-6 x 2.4-3 m whose reverberation time runs evenly from 0.2 to
0.8 s over the rooms; 2 or 3 sources (alternating) at least 1 m apart and 1 m from the path,
each playing speech, music, appliance hum or one of PROTOCOL.md's sounds repeated; the headset's
four microphones (``headset4``) at 8 poses along an arc through the room, 1.5 s each, pink
background noise 30 dB down. Tables:

- direction error (degrees, median / 90th percentile over every capture and source, sources
  matched to estimates by the Hungarian method) for each pyroomacoustics method on single
  captures and for vrecho's joint estimate; the count is given to every method;
- 3D position error (m) of vrecho's (count given, and count estimated) and of EchoCNN-A's
  position head on microphone 0 alone (each capture's answer against the nearest source);
- SDR and SIR improvement (dB, fast_bss_eval, reference: each source's reverberant image at
  microphone 0; improvement over the mixture at microphone 0) on capture 4 of each room, per
  method and per reverberation time;
- the same at the issue's target condition (2 sources, 4 microphones, RT60 0.4 s) on
  ``--target-rooms`` more rooms of their own seeds.

Usage: python3 benchmarks/bench_localization.py [--rooms 50] [--target-rooms 20] [--seed 7000] [--jobs 2]
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

SLOW_PRA = ("CSSM", "WAVES", "TOPS")
N_POSES, SEGMENT_S = 8, 1.5
TARGET_RT60, TARGET_SEED_OFFSET = 0.4, 300
SEP_NAMES = {"informed": "vrecho informed (located positions)", "informed_true": "vrecho informed (true positions)"}


def _matched(true: np.ndarray, found: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Each true source's distance to the position matched to it (the assignment of least total
    distance) and that position's index: inf and -1 where none is (fewer found than there are)."""
    from scipy.optimize import linear_sum_assignment

    err, idx = np.full(len(true), np.inf), np.full(len(true), -1)
    if len(found):
        D = np.linalg.norm(true[:, None] - found[None], axis=-1)
        r, c = linear_sum_assignment(D)
        err[r], idx[r] = D[r, c], c
    return err, idx


def _angles(true_dirs: np.ndarray, est_dirs: np.ndarray) -> np.ndarray:
    from scipy.optimize import linear_sum_assignment

    ang = np.degrees(np.arccos(np.clip(true_dirs @ est_dirs.T, -1, 1)))
    r, c = linear_sum_assignment(ang)
    return ang[r, c]


def separation_metrics(ref, est, perm=True):
    import fast_bss_eval
    import torch

    out = fast_bss_eval.bss_eval_sources(torch.as_tensor(ref), torch.as_tensor(est), compute_permutation=perm)
    return np.asarray(out[0]), np.asarray(out[1])


def simulate_room(seed: int, n_src: int, rt60: float):
    """A benchmark room: the shoebox and its walk's simulated captures (``sim.sources``,
    ``sim.poses``), from ``seed`` alone (the figures draw the same rooms)."""
    from vrecho.sim.ambient import random_walk, simulate_walk_capture

    rng = np.random.default_rng(seed)
    room, sources, poses = random_walk(rng, n_src, rt60, n_poses=N_POSES, segment_s=SEGMENT_S)
    return room, simulate_walk_capture(room, sources, poses, rng, segment_s=SEGMENT_S)


def main_condition(index: int, n_rooms: int) -> tuple[int, float]:
    """Room ``index`` of the main set: its number of sources (2 and 3 alternating) and RT60
    (spread evenly from 0.2 to 0.8 s over ``n_rooms``)."""
    return 2 + index % 2, 0.2 + 0.6 * index / max(1, n_rooms - 1)


def one_room(args):
    index, seed, n_rooms = args
    import torch

    torch.set_num_threads(1)
    from scipy.signal import resample_poly

    from localization import doa, locate
    from localization.doa import PRA_METHODS
    from vrecho.classifier import load_classifier

    n_src, rt60 = main_condition(index, n_rooms)
    room, sim = simulate_room(seed + index, n_src, rt60)
    true = np.array([s.position for s in sim.sources])
    row = {"room": index, "rt60_s": rt60, "n_sources": n_src, "sounds": [s.name for s in sim.sources], "doa": {}, "time_s": {}}

    def true_dirs(c):
        d = true - c.center
        return d / np.linalg.norm(d, axis=1, keepdims=True)

    for method in PRA_METHODS:
        t = time.perf_counter()
        picks = (0, 4) if method in SLOW_PRA else range(0, N_POSES, 2)
        errs = []
        for k in picks:
            c = sim.captures[k]
            errs += list(_angles(true_dirs(c), doa(c, n_src, method=method, n_grid=2000 if method in SLOW_PRA else 4000,
                                                   n_freq=12 if method in SLOW_PRA else None)))
        row["doa"][method] = errs
        row["time_s"][method] = (time.perf_counter() - t) / len(picks)
    t = time.perf_counter()
    loc = locate(sim.captures, n_src, bounds=((0, 0, 0), room.dims))
    row["time_s"]["vrecho"] = (time.perf_counter() - t) / N_POSES
    row["doa"]["vrecho"] = [float(e) for k, c in enumerate(sim.captures) for e in _angles(true_dirs(c), loc.directions[k])]
    err, idx = _matched(true, loc.positions)
    row["position_m"] = err.tolist()
    row["uncertainty_m"] = np.where(idx >= 0, loc.uncertainty_m[np.maximum(idx, 0)], np.nan).tolist()
    free = locate(sim.captures, None, bounds=((0, 0, 0), room.dims))
    row["count_found"] = len(free.positions)
    row["position_free_m"] = _matched(true, free.positions)[0].tolist()  # a source none is matched to: not found
    # EchoCNN-A's position head on microphone 0, one answer per capture
    clf = load_classifier()
    frames = np.array([resample_poly(c.audio[0, :16000], 441, 160)[:44100] for c in sim.captures])
    preds = clf.predict_batch(frames.astype(np.float32), 44100)
    row["echocnn_position_m"] = [float(np.min(np.linalg.norm(true - (pose.emitter + pose.rotation @ np.array(p.source_m)), axis=1)))
                                 for pose, p in zip(sim.poses, preds)]
    row["sdr"], row["sir"], row["time_s"]["sep"], row["failed"] = _separation(sim, true, loc.positions, 4, loc.uncertainty_m)
    return row


def _separation(sim, true: np.ndarray, located: np.ndarray, k: int, uncertainty_m: np.ndarray):
    """SDR and SIR improvement of every method on capture ``k`` (dicts by method), each
    method's time, and the methods that failed (counted as the mixture); informed separation at
    the located positions reads their uncertainty, as :func:`localization.place_sources` does."""
    from localization import separate
    from localization.separate import METHODS
    from vrecho.errors import VrechoError

    n_src = len(true)
    cap, ref = sim.captures[k], sim.images[k, :, 0]
    sdr0, sir0 = separation_metrics(ref, np.repeat(cap.audio[:1], n_src, axis=0), perm=False)
    sdrs, sirs, times, failed = {}, {}, {}, []
    for method in METHODS + ("informed_true",):
        t = time.perf_counter()
        try:
            est = separate(cap, n_src, method="informed" if method == "informed_true" else method,
                           positions=true if method == "informed_true" else located,
                           uncertainty_m=None if method == "informed_true" else uncertainty_m)
        except VrechoError:  # a method that fails on a room counts as no improvement there
            est = np.repeat(cap.audio[:1], n_src, axis=0)
            failed.append(method)
        times[method] = time.perf_counter() - t
        sdr, sir = separation_metrics(ref, est)
        sdrs[method] = float(np.mean(sdr - sdr0))
        sirs[method] = float(np.mean(sir - sir0))
    return sdrs, sirs, times, failed


def target_room(args):
    """One room of the issue's separation condition: 2 sources, the 4 microphones, RT60 0.4 s
    (seeds ``seed + TARGET_SEED_OFFSET + index``); positions located with the count given."""
    index, seed = args
    import torch

    torch.set_num_threads(1)
    from localization import locate

    room, sim = simulate_room(seed + TARGET_SEED_OFFSET + index, 2, TARGET_RT60)
    true = np.array([s.position for s in sim.sources])
    loc = locate(sim.captures, 2, bounds=((0, 0, 0), room.dims))
    sdr, sir, times, failed = _separation(sim, true, loc.positions, 4, loc.uncertainty_m)
    return {"room": index, "sounds": [s.name for s in sim.sources], "sdr": sdr, "sir": sir, "time_s": times, "failed": failed,
            "position_m": np.sort(np.linalg.norm(true[:, None] - loc.positions[None], axis=-1).min(axis=1)).tolist()}


ENVELOPE_TUNING = ("reference", "flat 9x5", "any array", "two mics", "few poses", "head turning", "four sources",
                   "levels apart", "music", "hum")
"""The envelope's conditions that may be tuned on (seeds ``--envelope-seed - 500`` and on); the
others never are: their pooled row is the held-out figure."""


def envelope_room(args):
    """One walk of the envelope (:func:`vrecho.sim.arrays.envelope_walk`): positions with the count
    given (3-D and horizontal errors, the reported uncertainty), the count estimated and the positions
    found with it (each source's error to the estimate matched to it; none matched: not found), and the SI-SDR
    gain over microphone 0 of each source's informed separation (located and true positions) on
    the walk's middle capture: every track as separated, and as the guard gives it (microphone 0,
    or the track mixed with it: :func:`localization.separate.track_weights`; at the located positions
    with their uncertainty, as :func:`localization.place_sources` passes it), and as the guard would
    give it without the two mask networks' doubt (:data:`localization.separate.GUARD`'s ``doubt``), or without its uncertainty's bound."""
    condition, seed = args
    import torch

    torch.set_num_threads(1)
    from localization import locate
    from localization.separate import informed, mix_back, si_sdr, track_weights
    from vrecho.errors import VrechoError
    from vrecho.sim.arrays import envelope_walk

    t0 = time.perf_counter()
    try:
        walk = envelope_walk(np.random.default_rng(seed), condition, cache=os.environ.get("VRECHO_CACHE"))
    except VrechoError as e:  # a seed whose room, walk and sources do not fit: said, not counted
        return {"condition": condition, "seed": seed, "skipped": str(e)}
    sim = walk.sim
    true = np.array([s.position for s in sim.sources])
    n = len(true)
    row = {"condition": condition, "seed": seed, "sounds": [s.name for s in sim.sources], "n_mics": walk.array.n_mics,
           "poses": len(sim.captures), "fs": sim.captures[0].fs}
    t = time.perf_counter()
    loc = locate(sim.captures, n, bounds=walk.bounds)
    row["locate_s"] = time.perf_counter() - t
    err, idx = _matched(true, loc.positions)
    r, c = np.flatnonzero(idx >= 0), idx[idx >= 0]
    err_h, unc, strength, located = np.full(n, np.inf), np.full(n, np.nan), np.full(n, np.nan), np.full((n, 3), np.nan)
    err_h[r] = np.linalg.norm(true[r, :2] - loc.positions[c, :2], axis=1)
    unc[r], strength[r], located[r] = loc.uncertainty_m[c], loc.strength[c], loc.positions[c]
    row.update(position_m=err.tolist(), horizontal_m=err_h.tolist(), uncertainty_m=unc.tolist(), strength=strength.tolist(),
               agreement=loc.agreement)
    free = locate(sim.captures, None, bounds=walk.bounds).positions  # the count estimated, as place_sources does by default
    row["count_found"] = len(free)
    row["position_free_m"] = _matched(true, free)[0].tolist()  # a source none is matched to: not found
    k = len(sim.captures) // 2
    cap, ref = sim.captures[k], sim.images[k, :, 0]
    base = [si_sdr(ref[j], cap.audio[0]) for j in range(n)]
    for name, pos in (("located", located), ("true", true)):
        gains, out, kept, unsure, distinct, share, remixed, spatial, undoubted = ([float("nan")] * n for _ in range(9))
        have = np.all(np.isfinite(pos), axis=1)
        if have.any():
            u = unc[have] if name == "located" else None  # (the true positions are known)
            sep = informed(cap, pos[have], guard=False, uncertainty_m=u)  # every track; the guard's verdict and weight beside it
            w_undoubted = track_weights(sep.distinct, sep.share, sep.remixed, sep.spatial, u)  # the guard without the networks' doubt
            w_unsure = track_weights(sep.distinct, sep.share, sep.remixed, sep.spatial, None, sep.doubt)  # ... without the uncertainty's
            for i, j in enumerate(np.flatnonzero(have)):
                gains[j] = si_sdr(ref[j], sep.signals[i]) - base[j]
                w = float(sep.weight[i])  # what the guard gives: the track mixed with microphone 0
                out[j] = si_sdr(ref[j], mix_back(cap.audio[0], sep.signals[i], w)) - base[j] if w > 0 else 0.0
                for other, ws in ((undoubted, w_undoubted), (unsure, w_unsure)):
                    v = float(ws[i])
                    other[j] = si_sdr(ref[j], mix_back(cap.audio[0], sep.signals[i], v)) - base[j] if v > 0 else 0.0
                kept[j], distinct[j], share[j] = w > 0, float(sep.distinct[i]), float(sep.share[i])
                remixed[j], spatial[j] = float(sep.remixed[i]), float(sep.spatial[i])
        row[f"gain_{name}_db"], row[f"kept_{name}"], row[f"distinct_{name}"], row[f"share_{name}"] = gains, kept, distinct, share
        row[f"guarded_{name}_db"], row[f"guarded_unsure_{name}_db"], row[f"remixed_{name}"] = out, unsure, remixed
        row[f"spatial_{name}"], row[f"guarded_undoubted_{name}_db"] = spatial, undoubted
    row["time_s"] = time.perf_counter() - t0
    return row


def report_envelope(rows: list[dict]) -> str:
    """One row per condition of the envelope, then the pooled tuning and held-out figures."""
    def cells(sel):
        pos = np.array([e for r in sel for e in r["position_m"]])
        hor = np.array([e for r in sel for e in r["horizontal_m"]])
        unc = np.array([u for r in sel for u in r["uncertainty_m"]], float)
        ok = np.isfinite(unc) & np.isfinite(pos)

        def gains(name):  # every track, and as the guard leaves them (microphone 0: 0 dB); no source found: 0 dB
            g = np.array([x for r in sel for x in r[f"gain_{name}_db"]], float)
            kept = np.array([k is True for r in sel for k in r[f"kept_{name}"]])
            g = np.where(np.isfinite(g), g, 0.0)
            out = np.array([x for r in sel for x in r[f"guarded_{name}_db"]], float)  # each kept track mixed with microphone 0
            return g, np.where(kept & np.isfinite(out), out, 0.0), kept
        raw, guarded, kept = gains("located")
        _, true_guarded, _ = gains("true")
        undoubted, unsure = (np.array([x if np.isfinite(x) else 0.0 for r in sel for x in r.get(f"guarded_{key}_located_db", [np.nan] * len(r["sounds"]))])
                             for key in ("undoubted", "unsure"))
        free = np.array([e for r in sel for e in r.get("position_free_m", [np.nan] * len(r["sounds"]))], float)
        return (f"{len(sel)} / {len(pos)} | {np.median(pos):.2f} | {np.median(hor):.2f} | {np.mean(pos < 0.5):.0%} | "
                f"{np.mean(free < 0.5):.0%} | "
                f"{np.mean(pos[ok] <= 2 * unc[ok]):.0%} | {np.mean([r['count_found'] == len(r['sounds']) for r in sel]):.0%} | "
                f"{np.median(guarded):+.1f} / {np.mean(guarded >= 0):.0%} / {np.mean(guarded):+.2f} | {np.mean(kept):.0%} | "
                f"{np.median(undoubted):+.1f} / {np.mean(undoubted >= 0):.0%} / {np.mean(undoubted):+.2f} | "
                f"{np.median(unsure):+.1f} / {np.mean(unsure >= 0):.0%} / {np.mean(unsure):+.2f} | "
                f"{np.median(raw):+.1f} / {np.mean(raw >= 0):.0%} | {np.median(true_guarded):+.1f} / {np.mean(true_guarded >= 0):.0%} | "
                f"{np.mean([r['locate_s'] / r['poses'] for r in sel]):.1f} s")
    lines = ["| condition | walks / sources | 3-D median m | horizontal median m | within 0.5 m | "
             "within 0.5 m, count estimated | error within 2 x uncertainty | "
             "count right | SI-SDR gain median / >= 0 dB / mean | tracks kept by the guard | "
             "the guard without the networks' doubt: median / >= 0 dB / mean | "
             "the guard without the uncertainty bound: median / >= 0 dB / mean | unguarded: median / >= 0 dB | "
             "true positions (guarded): median / >= 0 dB | locate per capture |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    by = {}
    for r in rows:
        by.setdefault(r["condition"], []).append(r)
    for c, sel in by.items():
        lines.append(f"| {c}{'' if c in ENVELOPE_TUNING else ' (held out)'} | " + cells(sel) + " |")
    tune = [r for r in rows if r["condition"] in ENVELOPE_TUNING]
    held = [r for r in rows if r["condition"] not in ENVELOPE_TUNING]
    for name, sel in (("pooled: tuning conditions", tune), ("pooled: held-out conditions", held)):
        if sel:
            lines.append(f"| **{name}** | " + cells(sel) + " |")
    return "\n".join(lines)


def _pct(v, q):
    """The ``q``-th percentile of ``v``, interpolated; inf where it falls among sources not found
    (inf), which interpolation would turn into nan; nan for none."""
    if not len(v):
        return float("nan")
    with np.errstate(invalid="ignore"):
        p = float(np.percentile(v, q))
    return float(np.percentile(v, q, method="higher")) if np.isnan(p) else p


def report(rows: list[dict]) -> str:
    lines = [f"{len(rows)} rooms, RT60 {min(r['rt60_s'] for r in rows):.2f}-{max(r['rt60_s'] for r in rows):.2f} s, "
             f"{sum(r['n_sources'] == 2 for r in rows)} with 2 sources and {sum(r['n_sources'] == 3 for r in rows)} with 3", ""]
    lines += ["Direction error (degrees), count given", "",
              "| method | all: median | all: p90 | RT60 <= 0.6 s: median | captures | time per capture |",
              "|---|---|---|---|---|---|"]
    for m in list(rows[0]["doa"]):
        allv = [e for r in rows for e in r["doa"][m]]
        low = [e for r in rows if r["rt60_s"] <= 0.6 + 1e-9 for e in r["doa"][m]]
        n_caps = sum(len(r["doa"][m]) // r["n_sources"] for r in rows)
        t = np.mean([r["time_s"][m] for r in rows])
        name = "vrecho (joint, all captures)" if m == "vrecho" else f"pyroomacoustics {m}"
        lines.append(f"| {name} | {np.median(allv):.1f} | {_pct(allv, 90):.1f} | {np.median(low):.1f} | {n_caps} | {t:.2f} s |")
    pos = [e for r in rows for e in r["position_m"]]
    free = [e for r in rows for e in r["position_free_m"]]
    cnn = [e for r in rows for e in r["echocnn_position_m"]]
    unc = np.array([u for r in rows for u in r["uncertainty_m"]])
    count_ok = np.mean([r["count_found"] == r["n_sources"] for r in rows])
    lines += ["", "3D position error (m)", "", "| method | median | p90 | share within 0.5 m |", "|---|---|---|---|",
              f"| vrecho, count given | {np.median(pos):.2f} | {_pct(pos, 90):.2f} | {np.mean(np.array(pos) < 0.5):.0%} |",
              f"| vrecho, count estimated ({count_ok:.0%} of rooms counted right, {np.mean(np.isinf(free)):.0%} of sources "
              f"not reached: inf) | {np.median(free):.2f} | {_pct(free, 90):.2f} | "
              f"{np.mean(np.array(free) < 0.5):.0%} |",
              f"| EchoCNN-A position head, microphone 0 (nearest source) | {np.median(cnn):.2f} | {_pct(cnn, 90):.2f} | "
              f"{np.mean(np.array(cnn) < 0.5):.0%} |",
              "", f"Reported uncertainty (median {np.nanmedian(unc):.2f} m) against the error: "
              f"{np.mean(np.array(pos)[np.isfinite(unc)] <= 2 * unc[np.isfinite(unc)]):.0%} of errors within twice it."]
    bins = [(0.2, 0.35), (0.35, 0.5), (0.5, 0.65), (0.65, 0.81)]
    lines += ["", "SDR / SIR improvement (dB, mean over sources, median over rooms), capture 4", "",
              "| method | all | 2 sources, RT60 0.35-0.5 s | " + " | ".join(f"RT60 {a:.2f}-{b:.2f}" for a, b in bins) + " | time |",
              "|---|---|---|" + "---|" * len(bins) + "---|"]
    for m in rows[0]["sdr"]:
        cells = [f"{np.median([r['sdr'][m] for r in rows]):+.1f} / {np.median([r['sir'][m] for r in rows]):+.1f}"]
        two = [r for r in rows if r["n_sources"] == 2 and 0.35 <= r["rt60_s"] < 0.5]
        cells.append(f"{np.median([r['sdr'][m] for r in two]):+.1f} / {np.median([r['sir'][m] for r in two]):+.1f}" if two else "-")
        for a, b in bins:
            sel = [r for r in rows if a <= r["rt60_s"] < b]
            cells.append(f"{np.median([r['sdr'][m] for r in sel]):+.1f} / {np.median([r['sir'][m] for r in sel]):+.1f}" if sel else "-")
        lines.append(f"| {SEP_NAMES.get(m, m)} | " + " | ".join(cells) + f" | {np.mean([r['time_s']['sep'][m] for r in rows]):.1f} s |")
    return "\n".join(lines + _failures(rows))


def _failures(rows: list[dict]) -> list[str]:
    failed = [m for r in rows for m in r["failed"]]
    return [f"\nSeparation failures (counted as the mixture): {', '.join(sorted(set(failed)))} ({len(failed)})"] if failed else []


def report_target(rows: list[dict], seed: int) -> str:
    """The issue's separation condition: one row per method."""
    pos = [e for r in rows for e in r["position_m"]]
    lines = [f"Separation at the target condition: 2 sources, 4 microphones, RT60 {TARGET_RT60} s, capture 4 "
             f"({len(rows)} rooms, seeds {seed + TARGET_SEED_OFFSET}+; located within 0.5 m: {np.mean(np.array(pos) < 0.5):.0%} of sources)",
             "", "| method | SDR improvement: median | mean | p25 | SIR improvement: median | time |", "|---|---|---|---|---|---|"]
    for m in rows[0]["sdr"]:
        v = [r["sdr"][m] for r in rows]
        lines.append(f"| {SEP_NAMES.get(m, m)} | {np.median(v):+.1f} | {np.mean(v):+.1f} | {_pct(v, 25):+.1f} | "
                     f"{np.median([r['sir'][m] for r in rows]):+.1f} | {np.mean([r['time_s'][m] for r in rows]):.1f} s |")
    return "\n".join(lines + _failures(rows))


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--rooms", type=int, default=50)
    ap.add_argument("--seed", type=int, default=7000)
    ap.add_argument("--target-rooms", type=int, default=20, help="extra rooms at the issue's separation condition")
    ap.add_argument("--envelope", type=int, default=0, help="walks per condition of the operating envelope (0: none)")
    ap.add_argument("--envelope-seed", type=int, default=9500, help="the envelope's walks: seeds from here, per condition")
    ap.add_argument("--only-envelope", action="store_true", help="the envelope's section alone")
    ap.add_argument("--conditions", nargs="*", default=None, help="the envelope's conditions to run (default: all)")
    ap.add_argument("--jobs", type=int, default=min(2, os.cpu_count() or 1))
    ap.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "results" / "localization.json")
    a = ap.parse_args()
    from multiprocessing import get_context

    from tqdm import tqdm

    from vrecho.sim.arrays import CONDITIONS

    t0 = time.time()
    rows, target, envelope = [], [], []
    conditions = a.conditions or CONDITIONS
    with get_context("spawn").Pool(a.jobs) as pool:
        if not a.only_envelope:
            rows = list(tqdm(pool.imap(one_room, [(i, a.seed, a.rooms) for i in range(a.rooms)]), total=a.rooms, desc="rooms"))
            target = list(tqdm(pool.imap(target_room, [(i, a.seed) for i in range(a.target_rooms)]), total=a.target_rooms,
                               desc="target rooms"))
        work = [(c, a.envelope_seed + 1000 * CONDITIONS.index(c) + i) for i in range(a.envelope) for c in conditions]
        envelope = list(tqdm(pool.imap_unordered(envelope_room, work), total=len(work), desc="envelope walks"))
    envelope.sort(key=lambda r: (CONDITIONS.index(r["condition"]), r["seed"]))
    skipped = [r for r in envelope if "skipped" in r]
    envelope = [r for r in envelope if "skipped" not in r]
    parts = ([report(rows)] if rows else []) + ([report_target(target, a.seed)] if target else [])
    if envelope:
        parts.append(f"The operating envelope: {a.envelope} walks per condition (seeds {a.envelope_seed} + 1000 x the "
                     f"condition's number + i)\n\n" + report_envelope(envelope))
    text = "\n\n".join(parts + [f"Skipped: {r['condition']}, seed {r['seed']}: {r['skipped']}" for r in skipped])
    print(text)
    print(f"\n{0 if a.only_envelope else a.rooms} rooms, seed {a.seed}, {time.time() - t0:.0f} s with {a.jobs} processes")
    a.out.parent.mkdir(parents=True, exist_ok=True)
    a.out.write_text(json.dumps({"seed": a.seed, "rows": rows, "target_rows": target, "envelope_rows": envelope,
                                 "skipped": skipped}, indent=1))


if __name__ == "__main__":
    main()
