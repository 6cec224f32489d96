"""The ``vrecho`` command.

Bad input ends with one line on stderr (``vrecho: error: ...``) and exit status 2; an interrupt
with status 130, keeping whatever was finished.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from .errors import VrechoError


def _generate(args) -> int:
    from .data import generate, open_dataset

    out = generate(args.out, args.preset, args.seed, args.workers, args.cache, progress=not args.quiet)
    ds = open_dataset(out)
    m = ds.manifest
    print(f"{out}: {len(ds)} frames ({int(ds.mask(kind='echo').sum())} echo, {int(ds.mask(kind='source').sum())} "
          f"source) from {m['n_irs']} impulse responses in {m['preset_settings']['n_scenes']} rooms")
    for split in ("train", "val", "test"):
        print(f"  {split:5s}: {int(ds.mask(split).sum()):6d} echo frames, paper protocol {int(ds.paper_split(split).sum()):6d}")
    return 0


def _train(args) -> int:
    from .evaluate import train_methods

    records = train_methods(args.data, args.out, args.method, args.seed, args.epochs, args.patience,
                            progress=not args.quiet)
    for name, r in records.items():
        extra = f", {r['epochs']} epochs (best {r['best_epoch'] + 1})" if "epochs" in r else ""
        print(f"{name:18s} {r['protocol']:7s} {r['n_train']:6d} train frames, {r['seconds']:7.1f} s{extra}")
    if (args.out / "classifier.pt").exists():
        print(f"classifier: {args.out / 'classifier.pt'} (vrecho.load_classifier(path) loads it)")
    return 0


def _evaluate(args) -> int:
    from .evaluate import evaluate

    out = args.run / "evaluation" if args.out is None else args.out
    evaluate(args.data, args.run, out, args.seed, progress=not args.quiet, methods=args.method)
    print((out / "tables.md").read_text())
    print(f"written to {out}: tables.md, results.csv, metrics.json, confusion_*.png, "
          "activation_maximisation_depth.png")
    return 0


def _reconstruct(args) -> int:
    from .reconstruct import run, summary

    result = run(args.scene, args.out, args.labels, args.variant, args.frames, args.seed, args.save_scan,
                 progress=not args.quiet)
    print(summary(result))
    s = result.seconds
    print(f"{len(result.surfaces)} surfaces added; discontinuities and repair {s['total_without_simulation']:.1f} s")
    print(f"written to {args.out}: initial.ply, repaired.ply, report.json, before_after.png"
          + (", scan/" if args.save_scan else ""))
    return 0


def _export(args) -> int:
    import usd_export

    from .reconstruct import open_source, reconstruct

    usd_export.check_target(args.out)  # before the work, not after
    if args.sources not in ("none", "truth", "heard") and not Path(args.sources).is_file():
        raise VrechoError(f"sources: expected 'none', 'truth', 'heard' or a JSON file, got {args.sources!r}")
    scan, scene = open_source(args.scene, args.frames, progress=not args.quiet)
    if args.sources in ("truth", "heard") and scene is None:
        raise VrechoError(f"sources: {args.sources!r} needs a scene (builtin or a scene JSON), not a scan folder")
    result = reconstruct(scan, scene, args.labels, args.variant, seed=args.seed, progress=not args.quiet)
    room, surfaces = usd_export.from_reconstruction(result)
    sources = {"none": lambda: [], "truth": lambda: usd_export.sources_from_scene(scene),
               "heard": lambda: _heard(scene, args.seed, not args.quiet)}.get(
        args.sources, lambda: usd_export.sources_from_json(args.sources))()
    path = usd_export.write_scene(args.out, room, surfaces, sources)  # refuses a stage with validation errors
    problems = usd_export.validate(path)  # the file as it lies now, and its warnings for the user
    errors = [p for p in problems if p.severity == "error"]
    if errors:
        raise VrechoError(f"export: {path} has {len(errors)} validation error(s); first: {errors[0]}")
    for p in problems:
        print(f"  {p}")
    print(f"{path}: {len(room[1]):,} room triangles, {len(surfaces)} surfaces "
          f"({', '.join(f'{s.name} {s.state}' for s in surfaces) or 'none'}), {len(sources)} sound sources; "
          f"OpenUSD's validators: no errors, {len(problems)} other findings")
    return 0


def _heard(scene, seed: int, progress: bool) -> list:
    """The scene's sources heard by the headset along its walkthrough, located and separated."""
    import numpy as np

    import localization

    sim = localization.hear_scene(scene, np.random.default_rng(seed))
    placed = localization.place_sources(sim.captures, bounds=scene.room.box, progress=progress)
    for p in placed:
        err = min(np.linalg.norm(p.position - s.position) for s in sim.sources)
        print(f"  {p.name} at {np.round(p.position, 2).tolist()} m (+/- {p.uncertainty_m or float('nan'):.2f} m, "
              f"confidence {p.confidence:.2f}); nearest true source {err:.2f} m away")
    return placed


def _capture(args) -> int:
    from .capture import run

    done = run(args.out, args.video, args.audio, args.images, args.poses, args.mesh, args.image_fps, args.labels,
               args.emitter_distance, progress=not args.quiet)
    rows, result = done["rows"], done["result"]
    n_open = sum(r["open"] for r in rows)
    print(f"{len(rows)} frames: {n_open} open, {len(rows) - n_open} closed "
          f"({sum(r['material'] == 'mirror' for r in rows)} mirror)")
    files = "frames.csv, capture.png" + (", images.npz" if args.video or args.images else "")
    if result is not None:
        from .reconstruct import summary

        posed = sum("x_m" in r for r in rows)
        print(f"{posed} frames posed; {len(result.holes)} holes in the mesh, {len(result.surfaces)} surfaces added")
        if result.holes:
            print(summary(result))
        files += ", initial.ply, repaired.ply, report.json, before_after.png, scan/ (vrecho export takes it)"
    print(f"written to {args.out}: {files}")
    return 0


def _demo(args) -> int:
    import demo

    demo.run(args.out, args.scene, args.html, browser=not args.no_browser, seed=args.seed, serve=args.serve,
             progress=not args.quiet)
    return 0


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="vrecho", description="Audio-augmented 3D scene reconstruction.")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    g = sub.add_parser("generate", help="simulate a labelled dataset of echo frames",
                       description="Simulate rooms, render every emitted sound and store frames, images, "
                                   "impulse responses and labels. Resumable: rerun to finish an interrupted run.")
    g.add_argument("--out", required=True, type=Path, help="dataset folder (created; must be empty or this dataset)")
    g.add_argument("--preset", choices=("tiny", "default"), default="tiny", help="dataset size (default: tiny)")
    g.add_argument("--seed", type=int, default=0, help="random seed (default: 0)")
    g.add_argument("--workers", type=int, default=None, help="processes (default: one per core)")
    g.add_argument("--cache", type=Path, default=None, help="impulse-response cache folder (default: ~/.cache/vrecho/ir)")
    g.add_argument("--quiet", action="store_true", help="no progress bar")
    g.set_defaults(func=_generate)

    t = sub.add_parser("train", help="train EchoCNN and every baseline on a dataset",
                       description="Train every method of the benchmark (EchoCNN variants and baselines) on a dataset "
                                   "made by `vrecho generate`, with early stopping on the validation rooms. Resumable: "
                                   "rerun to continue from the last finished epoch. Writes OUT/classifier.pt.")
    t.add_argument("--data", required=True, type=Path, help="dataset folder")
    t.add_argument("--out", required=True, type=Path, help="run folder for checkpoints and models")
    t.add_argument("--method", action="append", default=None, help="train only this method (repeatable; default: all)")
    t.add_argument("--seed", type=int, default=0, help="random seed (default: 0)")
    t.add_argument("--epochs", type=int, default=40, help="most epochs per model (default: 40)")
    t.add_argument("--patience", type=int, default=6, help="epochs without improvement before stopping (default: 6)")
    t.add_argument("--quiet", action="store_true", help="no progress bars")
    t.set_defaults(func=_train)

    e = sub.add_parser("evaluate", help="the paper's tables for every trained method",
                       description="Judge every method trained in RUN on the test rooms: the paper's two tables "
                                   "(1/2/3 ft and 0.5 m depth classes) for both protocols, a per-sound breakdown, "
                                   "confusion matrices and the activation-maximisation figure.")
    e.add_argument("--data", required=True, type=Path, help="dataset folder")
    e.add_argument("--run", required=True, type=Path, help="run folder written by `vrecho train`")
    e.add_argument("--out", type=Path, default=None, help="output folder (default: RUN/evaluation)")
    e.add_argument("--method", action="append", default=None, help="evaluate only this method (repeatable)")
    e.add_argument("--seed", type=int, default=0, help="seed of the product protocol's probes (default: 0)")
    e.add_argument("--quiet", action="store_true", help="no progress bars")
    e.set_defaults(func=_evaluate)

    r = sub.add_parser("reconstruct", help="scan a scene, find its glass, mirrors and openings, and repair the scan",
                       description="The initial reconstruction (a walkthrough fused by TSDF, with the camera's glass and "
                                   "mirror failures), its discontinuities (wall planes, holes, phantom geometry) and the "
                                   "repair of the paper's Algorithm 1 with EchoCNN's answers (or the truth).")
    r.add_argument("scene", help="'builtin' (the living room), a scene JSON file, or a scan folder (frames.npz, "
                                 "optional mesh.ply and echoes.npz; see vrecho.reconstruct.load_scan)")
    r.add_argument("--out", required=True, type=Path, help="output folder")
    r.add_argument("--labels", choices=("echocnn", "echocnn-only", "oracle"), default="echocnn",
                   help="who decides what each hole is: EchoCNN with the scan's evidence (default), EchoCNN alone, "
                        "or the scene's truth")
    r.add_argument("--variant", choices=("simplified", "per_vertex"), default="simplified",
                   help="Algorithm 1's fill: a new convex face, or the scan's own rim vertices moved (default: simplified)")
    r.add_argument("--frames", type=int, default=60, help="walkthrough frames of a simulated scan (default: 60)")
    r.add_argument("--seed", type=int, default=0, help="seed of the simulated recordings (default: 0)")
    r.add_argument("--save-scan", action="store_true", help="also write the scan (OUT/scan, the scan-folder format)")
    r.add_argument("--quiet", action="store_true", help="no progress bars")
    r.set_defaults(func=_reconstruct)

    x = sub.add_parser("export", help="reconstruct and repair a scene, and write it as OpenUSD (.usda/.usdc/.usdz)",
                       description="The repaired room as an OpenUSD stage: the mesh, each glass, mirror and opening "
                                   "with vrecho's labels, materials, and the sound sources as spatial audio (WAVs "
                                   "beside a .usda, inside a .usdz). Refuses to succeed while OpenUSD's validators "
                                   "report an error; a failed export writes nothing.")
    x.add_argument("scene", help="'builtin', a scene JSON file, or a scan folder (as for reconstruct)")
    x.add_argument("--out", required=True, type=Path, help="the stage: a .usda, .usdc, .usd or .usdz path")
    x.add_argument("--labels", choices=("echocnn", "echocnn-only", "oracle"), default="echocnn",
                   help="who decides what each hole is (as for reconstruct; default: echocnn)")
    x.add_argument("--variant", choices=("simplified", "per_vertex"), default="simplified",
                   help="Algorithm 1's fill (default: simplified)")
    x.add_argument("--sources", default="none",
                   help="sound sources: 'none' (default), 'truth' (a scene's own sources where they are), "
                        "'heard' (a scene's sources recorded by the headset's 4 microphones along the walkthrough, "
                        "located and separated by localization.place_sources) or a JSON file of placed sources "
                        "(see usd_export.sources_from_json)")
    x.add_argument("--frames", type=int, default=60, help="walkthrough frames of a simulated scan (default: 60)")
    x.add_argument("--seed", type=int, default=0, help="seed of the simulated recordings (default: 0)")
    x.add_argument("--quiet", action="store_true", help="no progress bars")
    x.set_defaults(func=_export)

    c = sub.add_parser("capture", help="a phone's capture (video, or sound file): pulses, frames, EchoCNN's answers, "
                                       "and the repair of its mesh",
                       description="Decode a capture (PyAV), find vrecho's pulses in its sound, cut PROTOCOL.md's "
                                   "1 s frames and ask EchoCNN about each; writes frames.csv, capture.png and the "
                                   "picture at each frame (images.npz). With --poses and --mesh, also repairs the "
                                   "mesh (initial.ply, repaired.ply, report.json, before_after.png, scan/ for "
                                   "`vrecho export`). The pulse train for the second phone to play: "
                                   "vrecho/assets/pulse_train.wav (python3 -c 'import vrecho.capture as c; "
                                   "print(c.PULSE_TRAIN_WAV)').")
    c.add_argument("video", type=Path, nargs="?", default=None, help="the video (MP4, MOV, MKV) with its sound")
    c.add_argument("--audio", type=Path, default=None, help="a sound file (WAV, FLAC) instead of a video")
    c.add_argument("--images", type=Path, default=None,
                   help="with --audio: a folder of the capture's pictures, numbered in order (ffmpeg's %%06d.png)")
    c.add_argument("--image-fps", type=float, default=None,
                   help="the rate the pictures were extracted at, numbered from 1 (ffmpeg -vf fps=N); "
                        "needed by --images and --poses")
    c.add_argument("--poses", type=Path, default=None,
                   help="a folder with COLMAP's text model of the pictures (cameras.txt, images.txt): metric, z up")
    c.add_argument("--mesh", type=Path, default=None, help="with --poses: the scan's mesh (.ply or .obj) to repair")
    c.add_argument("--labels", choices=("echocnn", "echocnn-only"), default="echocnn",
                   help="who decides what each hole is (as for reconstruct; default: echocnn)")
    c.add_argument("--emitter-distance", type=float, default=None, metavar="M",
                   help="metres from the playing loudspeaker to the filming microphone (default 0.07, "
                        "PROTOCOL.md's device: the second phone held against the first)")
    c.add_argument("--out", type=Path, required=True, help="output folder")
    c.add_argument("--quiet", action="store_true", help="no progress bars")
    c.set_defaults(func=_capture)

    d = sub.add_parser("demo", help="the whole run on the built-in living room, as a meshcat walkthrough",
                       description="Simulate the built-in scene (or --scene FILE) and run all of vrecho on it: the "
                                   "phone's scan and its repair with EchoCNN, the sources heard, separated and placed, "
                                   "the headset call on walks toward each surface, the USD export; print each decision "
                                   "against the truth, write figures and the walkthrough page, and open it.")
    d.add_argument("--out", type=Path, default=Path("vrecho-out"), help="output folder (default: ./vrecho-out)")
    d.add_argument("--html", type=Path, default=None,
                   help="the self-contained walkthrough page (default: OUT/walkthrough.html)")
    d.add_argument("--no-browser", action="store_true", help="do not open the walkthrough in a browser")
    d.add_argument("--serve", action="store_true",
                   help="also keep the walkthrough on a live meshcat server (its address printed) until Ctrl-C")
    d.add_argument("--scene", type=Path, default=None, help="a scene JSON file instead of the built-in one")
    d.add_argument("--seed", type=int, default=0, help="seed of the simulated recordings (default: 0)")
    d.add_argument("--quiet", action="store_true", help="no progress bars or step lines (the table is printed)")
    d.set_defaults(func=_demo)
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return args.func(args)
    except VrechoError as e:
        print(f"vrecho: error: {e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("vrecho: interrupted; finished work is kept: rerun the same command to resume", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
