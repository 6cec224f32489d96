"""``vrecho capture``: a phone's capture in, its pulses, frames, EchoCNN's answers (and a repaired
scan) out."""

from __future__ import annotations

import csv
import io
from pathlib import Path

import numpy as np

from ..capture import analyse, open_capture
from ..io import OutputFolder, atomic_write_text
from .figures import capture_figure
from .scans import summary, write

FIELDS = ("frame", "time_s", "x_m", "y_m", "z_m", "hole", "model", "open", "material", "depth_m", "p_open",
          "p_mirror", "confidence", "flags")
"""The columns of ``frames.csv`` (``x_m`` to ``hole`` only for a posed capture)."""


def capture(out: str | Path, video=None, audio=None, images=None, poses=None, mesh=None, *,
            image_fps: float | None = None, labels: str = "echocnn", emitter_distance_m: float | None = None,
            classifier=None, force: bool = False) -> dict:
    """``vrecho capture``: a phone's capture in, EchoCNN's answers (and a repaired scan) out.

    The pulses of the recording (a video's sound, or ``audio``) are found and cut into frames,
    and EchoCNN answers each, the probe known (EchoCNN-E) (:func:`vrecho.capture.analyse`).
    Written to ``out``: ``frames.csv`` (one row per frame: its time in the recording, the
    answers and their probabilities), ``capture.png`` (the recording, the pulses found and the
    answers) and ``images.npz`` (the picture at each frame's time, from the video or the
    numbered pictures in ``images``).

    With ``poses`` (COLMAP's text model of the pictures, numbered at ``image_fps``) and the
    user's ``mesh`` (.ply or .obj, in the poses' world; a y-up world is turned z up, and the
    meshes written are in that z-up world): each frame takes the pose of its pulse, the frames
    that face a hole of the mesh are asked again with the camera's crop around it (EchoCNN-EV,
    PROTOCOL.md's 64 x 25), and the reconstruction's repair runs on the mesh (``labels`` as
    :func:`vrecho.reconstruct.reconstruct`): ``initial.ply``, ``repaired.ply``,
    ``report.json``, ``before_after.png`` and ``scan/`` (which ``vrecho export`` turns into
    USD). ``emitter_distance_m``: from the loudspeaker to the microphone (default PROTOCOL.md's
    7 cm; a second phone held elsewhere, measured), which places each frame's start, the
    emission, before the direct sound's arrival. Every input is checked before ``out`` is made.

    Parameters
    ----------
    out : str or path
        Output folder; created if missing. New, empty, or an earlier capture's
        (:class:`vrecho.io.OutputFolder`); all files appear at once, when all are written.
    video : path, optional
        A video with its sound (MP4, MOV, MKV); give it or ``audio``, not both.
    audio : path, optional
        A sound file (WAV, FLAC) instead of a video.
    images : path, optional
        With ``audio``: a folder of the capture's pictures, numbered in order.
    poses : path, optional
        A folder with COLMAP's text model of the pictures; with ``mesh``.
    mesh : path, optional
        With ``poses``: the scan's mesh (.ply or .obj) to repair.
    image_fps : float, optional
        The rate in pictures per second the pictures were extracted at; needed by ``images``
        and ``poses``.
    labels : {"echocnn", "echocnn-only"}
        Who decides what each hole is (default ``echocnn``).
    emitter_distance_m : float, optional
        Metres from the loudspeaker to the microphone, 0 to 3 (default 0.07).
    classifier : Classifier, optional
        The EchoCNN to ask (default: the shipped weights, :func:`vrecho.load_classifier`).
    force : bool
        Write into a folder that holds files this command did not write.

    Returns
    -------
    dict
        ``{"rows": [...], "result": Reconstruction or None}``: one dict per frame (the columns of
        :data:`FIELDS`), and the repair of a posed capture.

    Raises
    ------
    VrechoError
        For inputs that do not go together (a video and a sound file, ``poses`` without
        ``mesh``, pictures without ``image_fps``, ...), unknown ``labels``, an emitter distance
        outside 0 to 3 m, a file that cannot be read, or an ``out`` that cannot be written (a full
        disk: nothing is written) or holds files this command did not write (without ``force``).
    """
    rec = open_capture(video, audio, images, poses, mesh, image_fps=image_fps, labels=labels,
                       emitter_distance_m=emitter_distance_m)
    with OutputFolder(out, "capture", force=force) as folder:
        found = analyse(rec, classifier=classifier)
        rows, result = found.rows, found.result
        posed = rec.poses is not None
        table = io.StringIO(newline="")
        w = csv.DictWriter(table, FIELDS if posed else [c for c in FIELDS if c not in ("x_m", "y_m", "z_m", "hole")],
                           restval="")
        w.writeheader()
        w.writerows(rows)
        with folder.writing() as stage:
            if result is not None:
                write(result, stage, save_scan=True)
            atomic_write_text(stage / "frames.csv", table.getvalue())
            if found.frame_pictures is not None:
                np.savez_compressed(stage / "images.npz", time_s=found.times, gray=found.frame_pictures)
            capture_figure(rec.audio, rec.fs, found.onsets, rows, stage / "capture.png",
                           None if result is None else result.decisions)
    out = folder.path
    n_open = sum(r["open"] for r in rows)
    print(f"{len(rows)} frames: {n_open} open, {len(rows) - n_open} closed "
          f"({sum(r['material'] == 'mirror' for r in rows)} mirror)")
    files = "frames.csv, capture.png" + (", images.npz" if found.frame_pictures is not None else "")
    if result is not None:
        print(f"{sum('x_m' in r for r in rows)} frames posed; {len(result.holes)} holes in the mesh, "
              f"{len(result.surfaces)} surfaces added")
        if result.holes:
            print(summary(result))
        files += ", initial.ply, repaired.ply, report.json, before_after.png, scan/ (vrecho export takes it)"
    print(f"written to {out}: {files}")
    return {"rows": rows, "result": result}
