"""The ``vrecho`` command: its arguments (argparse), and one call into :mod:`vrecho.app` per
subcommand.

Bad input ends with one line on stderr (``vrecho: error: ...``) and exit status 2, as does a
refusal of the operating system (a full disk, a file that cannot be read) or a lack of memory; an
interrupt with status 130 and one line: ``generate`` and ``train`` keep what was finished and
resume from it when rerun, the other commands leave their output as it was.
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

from . import app
from .app.scans import LABEL_CHOICES
from .errors import VrechoError
from .learn import cluster
from .reconstruct import LABELS, VARIANTS


def _whole(lo: int, hi: int):
    """An argparse type: a whole number from ``lo`` to ``hi``, refused by argparse otherwise."""
    def parse(text: str) -> int:
        try:
            v = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected a whole number, got {text!r}") from None
        if not lo <= v <= hi:
            raise argparse.ArgumentTypeError(f"expected {lo} to {hi}, got {v}")
        return v
    return parse


SEED = _whole(0, 2**32 - 1)


def _finite(text: str) -> float:
    """An argparse type: a finite number (``float`` alone takes 'nan' and 'inf')."""
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not math.isfinite(v):
        raise argparse.ArgumentTypeError(f"expected a finite number, got {text!r}")
    return v


def build_parser() -> argparse.ArgumentParser:
    """The ``vrecho`` command's parser: one subcommand per function of :mod:`vrecho.app`.

    Returns
    -------
    argparse.ArgumentParser
        Parsed arguments carry ``func``, which runs the subcommand on them.

    Examples
    --------
    >>> args = build_parser().parse_args(["generate", "--out", "data"])
    >>> args.command, args.preset, args.seed
    ('generate', 'tiny', 0)
    """
    parser = argparse.ArgumentParser(prog="vrecho", description="Audio-augmented 3D scene reconstruction.")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    g = sub.add_parser("generate", help="simulate a labelled dataset of echo frames",
                       description="Simulate rooms, render every emitted sound and store frames, images, "
                                   "impulse responses and labels. Resumable: rerun to finish an interrupted run.")
    g.add_argument("--out", required=True, type=Path, help="dataset folder (created; must be empty or this dataset)")
    g.add_argument("--preset", choices=("tiny", "small", "default", "devices"), default="tiny",
                   help="dataset size: 384, 2 560 or 25 600 frames (default: tiny); devices: echo frames of other "
                        "devices of the operating envelope, for `vrecho train --devices`")
    g.add_argument("--frames", type=_whole(1, 1_000_000), default=2000,
                   help="frames of the devices preset (default: 2000)")
    g.add_argument("--conditions", choices=("tuning", "all"), default="tuning",
                   help="the conditions the devices preset draws in turn: those tuning and training use (default), "
                        "or all of them, a test set for `vrecho evaluate --devices`")
    g.add_argument("--seed", type=SEED, default=0, help="random seed (default: 0)")
    g.add_argument("--workers", type=_whole(1, 256), default=None, help="processes (default: one per core)")
    g.add_argument("--cache", type=Path, default=None, help="impulse-response cache folder (default: ~/.cache/vrecho/ir)")
    g.add_argument("--force", action="store_true",
                   help="generate into a non-empty folder that holds no dataset, beside its files")
    cluster.add_argument(g, "rooms as Ray tasks")
    g.add_argument("--quiet", action="store_true", help="no progress bar")
    g.set_defaults(resumable=True, func=lambda a: app.generate(a.out, preset=a.preset, seed=a.seed,
                                                               workers=a.workers, cache=a.cache, force=a.force,
                                                               progress=not a.quiet, ray=a.ray, frames=a.frames,
                                                               conditions=a.conditions))

    t = sub.add_parser("train", help="train EchoCNN and every baseline on a dataset",
                       description="Train every method of the benchmark (EchoCNN variants and baselines) on a dataset "
                                   "made by `vrecho generate`, with early stopping on the validation rooms. Resumable: "
                                   "rerun to continue from the last finished epoch. Writes OUT/classifier.pt.")
    t.add_argument("--data", required=True, type=Path, help="dataset folder")
    t.add_argument("--out", required=True, type=Path, help="run folder for checkpoints and models")
    t.add_argument("--method", action="append", default=None, help="train only this method (repeatable; default: all)")
    t.add_argument("--seed", type=SEED, default=0, help="random seed (default: 0)")
    t.add_argument("--epochs", type=_whole(1, 10000), default=40, help="most epochs per model (default: 40)")
    t.add_argument("--patience", type=_whole(1, 10000), default=6, help="epochs without improvement before stopping (default: 6)")
    t.add_argument("--force", action="store_true",
                   help="train into a non-empty folder that holds no run, beside its files")
    cluster.add_argument(t, "train the CNNs with Ray Train (distributed data parallel)")
    t.add_argument("--workers", type=_whole(1, 1024), default=1, help="Ray Train workers (with --ray; default: 1)")
    t.add_argument("--gpus-per-worker", type=_finite, default=0.0, help="GPUs per Ray Train worker (with --ray; default: 0)")
    t.add_argument("--devices", type=Path, default=None,
                   help="a folder of `vrecho generate --preset devices`: other devices' echo frames added to "
                        "EchoCNN-E's training and validation")
    t.add_argument("--base", type=Path, default=None,
                   help="a classifier.pt (or vrecho/assets/echocnn.pt) whose models OUT/classifier.pt keeps where "
                        "a shipped method is not trained in OUT: one model retrained, the others as shipped")
    t.add_argument("--quiet", action="store_true", help="no progress bars")
    t.set_defaults(resumable=True, func=lambda a: app.train(a.data, a.out, methods=a.method, seed=a.seed,
                                                            epochs=a.epochs, patience=a.patience, force=a.force,
                                                            progress=not a.quiet, ray=a.ray, workers=a.workers,
                                                            gpus_per_worker=a.gpus_per_worker, devices=a.devices,
                                                            base=a.base))

    e = sub.add_parser("evaluate", help="the paper's tables for every trained method",
                       description="Judge every method trained in RUN on the test rooms: the paper's two tables "
                                   "(1/2/3 ft and 0.5 m depth classes) for both protocols, a per-sound breakdown, "
                                   "confusion matrices and the activation-maximisation figure.")
    e.add_argument("--data", required=True, type=Path, help="dataset folder")
    e.add_argument("--run", required=True, type=Path, help="run folder written by `vrecho train`")
    e.add_argument("--out", type=Path, default=None, help="output folder (default: RUN/evaluation)")
    e.add_argument("--method", action="append", default=None, help="evaluate only this method (repeatable)")
    e.add_argument("--seed", type=SEED, default=0, help="seed of the product protocol's probes (default: 0)")
    e.add_argument("--force", action="store_true",
                   help="write into a folder holding files vrecho evaluate did not write")
    e.add_argument("--devices", type=Path, default=None,
                   help="a folder of `vrecho generate --preset devices --conditions all`: EchoCNN-E judged on other "
                        "devices too, each condition on its own row")
    e.add_argument("--quiet", action="store_true", help="no progress bars")
    e.set_defaults(func=lambda a: app.evaluate(a.data, a.run, a.out, methods=a.method, seed=a.seed,
                                                force=a.force, progress=not a.quiet, devices=a.devices))

    r = sub.add_parser("reconstruct", help="scan a scene, find its glass, mirrors and openings, and repair the scan",
                       description="The initial reconstruction (a walkthrough fused by TSDF, with the camera's glass and "
                                   "mirror failures), its discontinuities (wall planes, holes, phantom geometry) and the "
                                   "repair of the paper's Algorithm 1 with EchoCNN's answers (or the truth).")
    r.add_argument("scene", help="'builtin' (the living room), a scene JSON file, or a scan folder (frames.npz, "
                                 "optional mesh.ply and echoes.npz; see vrecho.reconstruct.load_scan)")
    r.add_argument("--out", required=True, type=Path, help="output folder")
    r.add_argument("--labels", choices=LABEL_CHOICES, default="echocnn",
                   help="who decides what each hole is: EchoCNN with the scan's evidence (default), EchoCNN alone, "
                        "or the scene's truth")
    r.add_argument("--variant", choices=VARIANTS, default="simplified",
                   help="Algorithm 1's fill: a new convex face, or the scan's own rim vertices moved (default: simplified)")
    r.add_argument("--frames", type=_whole(2, 1000), default=60, help="walkthrough frames of a simulated scan (default: 60)")
    r.add_argument("--seed", type=SEED, default=0, help="seed of the simulated recordings (default: 0)")
    r.add_argument("--save-scan", action="store_true", help="also write the scan (OUT/scan, the scan-folder format)")
    r.add_argument("--force", action="store_true",
                   help="write into a folder holding files vrecho reconstruct did not write")
    r.add_argument("--quiet", action="store_true", help="no progress bars")
    r.set_defaults(func=lambda a: app.reconstruct(a.scene, a.out, labels=a.labels, variant=a.variant,
                                                   n_frames=a.frames, seed=a.seed, save_scan=a.save_scan,
                                                   force=a.force, progress=not a.quiet))

    x = sub.add_parser("export", help="reconstruct and repair a scene, and write it as OpenUSD (.usda/.usdc/.usdz)",
                       description="The repaired room as an OpenUSD stage: the mesh, each glass, mirror and opening "
                                   "with vrecho's labels, materials, and the sound sources as spatial audio (WAVs "
                                   "beside a .usda, inside a .usdz). Refuses to succeed while OpenUSD's validators "
                                   "report an error; a failed export writes nothing.")
    x.add_argument("scene", help="'builtin', a scene JSON file, or a scan folder (as for reconstruct)")
    x.add_argument("--out", required=True, type=Path, help="the stage: a .usda, .usdc, .usd or .usdz path")
    x.add_argument("--labels", choices=LABEL_CHOICES, default="echocnn",
                   help="who decides what each hole is (as for reconstruct; default: echocnn)")
    x.add_argument("--variant", choices=VARIANTS, default="simplified",
                   help="Algorithm 1's fill (default: simplified)")
    x.add_argument("--sources", default="none",
                   help="sound sources: 'none' (default), 'truth' (a scene's own sources where they are), "
                        "'heard' (a scene's sources recorded by the headset's 4 microphones along the walkthrough, "
                        "located and separated by localization.place_sources) or a JSON file of placed sources "
                        "(see usd_export.sources_from_json)")
    x.add_argument("--frames", type=_whole(2, 1000), default=60, help="walkthrough frames of a simulated scan (default: 60)")
    x.add_argument("--seed", type=SEED, default=0, help="seed of the simulated recordings (default: 0)")
    x.add_argument("--force", action="store_true",
                   help="replace a file (and its _audio folder) at --out that vrecho did not write")
    x.add_argument("--quiet", action="store_true", help="no progress bars")
    x.set_defaults(func=lambda a: app.export(a.scene, a.out, labels=a.labels, variant=a.variant, sources=a.sources,
                                              n_frames=a.frames, seed=a.seed, force=a.force, progress=not a.quiet))

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
    c.add_argument("--image-fps", type=_finite, default=None,
                   help="the rate the pictures were extracted at, numbered from 1 (ffmpeg -vf fps=N); "
                        "needed by --images and --poses")
    c.add_argument("--poses", type=Path, default=None,
                   help="a folder with COLMAP's text model of the pictures (cameras.txt, images.txt): metric, z up")
    c.add_argument("--mesh", type=Path, default=None, help="with --poses: the scan's mesh (.ply or .obj) to repair")
    c.add_argument("--labels", choices=tuple(LABELS), default="echocnn",
                   help="who decides what each hole is (as for reconstruct; default: echocnn)")
    c.add_argument("--emitter-distance", type=_finite, default=None, metavar="M",
                   help="metres from the playing loudspeaker to the filming microphone (default 0.07, "
                        "PROTOCOL.md's device: the second phone held against the first)")
    c.add_argument("--out", type=Path, required=True, help="output folder")
    c.add_argument("--force", action="store_true",
                   help="write into a folder holding files vrecho capture did not write")
    c.add_argument("--quiet", action="store_true", help="accepted for scripts: capture shows no progress bars")
    c.set_defaults(func=lambda a: app.capture(a.out, a.video, a.audio, a.images, a.poses, a.mesh,
                                               image_fps=a.image_fps, labels=a.labels,
                                               emitter_distance_m=a.emitter_distance, force=a.force))

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
    d.add_argument("--seed", type=SEED, default=0, help="seed of the simulated recordings (default: 0)")
    d.add_argument("--force", action="store_true",
                   help="write into a folder holding files vrecho demo did not write")
    d.add_argument("--quiet", action="store_true", help="no progress bars or step lines (the table is printed)")
    d.set_defaults(func=lambda a: app.demo(a.out, scene=a.scene, html=a.html, browser=not a.no_browser,
                                            seed=a.seed, serve=a.serve, force=a.force, progress=not a.quiet))

    w = sub.add_parser("watch", help="the headset call live on this computer's sound card",
                       description="Play the headset call's probe on the loudspeaker and listen on the microphone "
                                   "(a full-duplex stream): print each change of the alert (clear, caution, stop) with "
                                   "the distance and the surface, and the stream's round trip once found. Ctrl-C stops.")
    w.add_argument("--device", default=None,
                   help="the sound device: a number or part of its name (default: the system's default device)")
    w.add_argument("--samplerate", type=int, default=48000, help="44100 or 48000 Hz (default: 48000)")
    w.add_argument("--blocksize", type=int, default=0,
                   help="frames per callback, up to 4096 (default: 0, the audio system's choice)")
    w.add_argument("--mic-offset", type=_finite, default=0.07, metavar="M",
                   help="loudspeaker to microphone in metres, as the maker gives it (default 0.07; a laptop: 0.1 to 0.3)")
    w.add_argument("--seconds", type=_finite, default=None, help="stop after this long (default: until Ctrl-C)")
    w.add_argument("--list-devices", action="store_true", help="list the sound devices and exit")
    w.set_defaults(func=lambda a: print(app.list_devices()) if a.list_devices else app.watch(
        device=int(a.device) if a.device is not None and a.device.isdigit() else a.device, samplerate=a.samplerate,
        blocksize=a.blocksize, mic_offset_m=a.mic_offset, seconds=a.seconds))
    return parser


def main(argv: list[str] | None = None) -> int:
    """Run the ``vrecho`` command.

    Parameters
    ----------
    argv : list of str, optional
        The arguments (default: the command line's). Arguments argparse refuses, and
        ``--help``, end in its own :class:`SystemExit`.

    Returns
    -------
    int
        The exit status: 0, 2 after bad input, an operating system's refusal or a lack of memory
        (one line on stderr), or 130 after an interrupt.

    Examples
    --------
    A scene that is not there: ``vrecho: error: scene: ...`` on stderr, and status 2.

    >>> main(["reconstruct", "no-such-scene.json", "--out", "out"])
    2
    """
    args = build_parser().parse_args(argv)
    status = 2
    try:
        args.func(args)
        return 0
    except VrechoError as e:
        line = f"vrecho: error: {e}"
    except OSError as e:  # what no check can foresee: a file that vanished, a disk that filled meanwhile
        where = f"{e.filename}: " if e.filename else ""
        line = f"vrecho: error: {where}{e.strerror or e}"
    except MemoryError:
        line = "vrecho: error: out of memory (a smaller scene, fewer frames or a machine with more memory)"
    except KeyboardInterrupt:
        status = 130
        line = "vrecho: interrupted; " + ("finished work is kept: rerun the same command to resume"
                                          if getattr(args, "resumable", False) else "nothing was written")
    cluster.disconnect()  # Ray's shutdown lines, if any, before vrecho's own last line
    print(line, file=sys.stderr)
    return status


if __name__ == "__main__":
    sys.exit(main())
