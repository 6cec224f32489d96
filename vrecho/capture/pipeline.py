"""A real capture from files to answers: :func:`open_capture` reads and checks what the user gives
(a video or a sound file, pictures, COLMAP's poses, the mesh), :func:`analyse` finds the pulses,
cuts PROTOCOL.md's frames, asks EchoCNN about each (the probe known) and, with poses and a mesh,
repairs the mesh as ``vrecho reconstruct`` does. ``vrecho capture`` (:func:`vrecho.app.capture`)
writes what they find.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..camera import crop_view
from ..colmap import image_times
from ..errors import VrechoError, check_number
from ..io import read_mesh
from ..reconstruct import LABELS, SCAN_TOLERANCE_M, Reconstruction, facing, reconstruct, scan_distance
from ..signals import FS, probe
from .media import check_pictures, image_files, load_pictures, read_audio, read_video, video_images
from .onsets import Onsets, cut_frames, find_onsets, frame_flags
from .posing import VIEW_WIDTH, Poses, posed_scan, read_poses


@dataclass
class Recording:
    """A capture as read by :func:`open_capture`.

    Parameters
    ----------
    audio : numpy.ndarray [shape=(n,)], float32
        The sound, mono.
    fs : int
        Its sample rate in Hz.
    video : pathlib.Path, optional
        The video it came from (None for a sound file).
    video_start_s : float
        When the video's first picture shows, in seconds from the sound's start (default 0).
    files : list of pathlib.Path, optional
        The pictures' files (with a sound file).
    image_fps : float, optional
        The rate the pictures were extracted at, in pictures per second.
    poses : :class:`~.posing.Poses`, optional
        COLMAP's poses of the pictures.
    mesh : open3d.geometry.TriangleMesh, optional
        The user's mesh, in the poses' z-up world.
    labels : str
        The analysis's decider, a name of :data:`vrecho.reconstruct.LABELS` (default
        ``"echocnn"``).
    emitter_distance_m : float, optional
        From the loudspeaker to the microphone, in metres (PROTOCOL.md's 7 cm when None).
    """

    audio: np.ndarray
    fs: int
    video: Path | None = None
    video_start_s: float = 0.0
    files: list[Path] | None = None
    image_fps: float | None = None
    poses: Poses | None = None
    mesh: object = None  # open3d.geometry.TriangleMesh
    labels: str = "echocnn"
    emitter_distance_m: float | None = None


@dataclass
class Analysis:
    """What :func:`analyse` found.

    Parameters
    ----------
    onsets : :class:`~.onsets.Onsets`
        The pulses found.
    frames : numpy.ndarray [shape=(K, 44100)], float32
        The frames cut, at 44.1 kHz.
    times : numpy.ndarray [shape=(K,)], float
        Their pulses' onsets, in seconds from the recording's start.
    rows : list of dict
        One answer per frame (the columns of ``frames.csv``; see :func:`analyse`).
    frame_pictures : numpy.ndarray [shape=(K, H, W)], uint8, or None
        The picture at each frame, or None without pictures.
    result : :class:`vrecho.reconstruct.Reconstruction` or None
        The repair, with poses and a mesh.
    """

    onsets: Onsets
    frames: np.ndarray
    times: np.ndarray
    rows: list[dict]
    frame_pictures: np.ndarray | None
    result: Reconstruction | None


def open_capture(video=None, audio=None, images=None, poses=None, mesh=None, *, image_fps: float | None = None,
                 labels: str = "echocnn", emitter_distance_m: float | None = None) -> Recording:
    """Read and check a capture (every check before any work; see :func:`vrecho.app.capture`).

    Parameters
    ----------
    video : str or pathlib.Path, optional
        A video with its sound (PyAV: MP4, MOV, MKV); or ``audio``, a sound file, with its
        pictures in the folder ``images`` (optional). One of ``video`` and ``audio`` is given.
    audio : str or pathlib.Path, optional
        A sound file (WAV, FLAC).
    images : str or pathlib.Path, optional
        The folder of pictures, with ``audio``.
    poses : str or pathlib.Path, optional
        COLMAP's text model of the pictures, numbered from 1 at ``image_fps`` (pictures per
        second); with ``mesh`` (.ply or .obj, in the poses' world; a y-up world is turned z up).
    mesh : str or pathlib.Path, optional
        The user's mesh, with ``poses``.
    image_fps : float, optional
        The rate the pictures were extracted at, in pictures per second; needed with ``poses``
        or ``images``.
    labels : {"echocnn", "echocnn-only"}
        Who decides what each hole of the mesh is (default ``"echocnn"``).
    emitter_distance_m : float, optional
        From the loudspeaker to the microphone, in metres, 0 to 3 (PROTOCOL.md's 7 cm by
        default).

    Returns
    -------
    Recording
        The sound, the pictures' files or video, the poses and mesh, and the options.

    Raises
    ------
    VrechoError
        For options that do not go together (a video and a sound file, or neither; ``images``
        with a video; ``poses`` without ``mesh`` or the reverse; ``poses`` or ``images``
        without ``image_fps``; ``poses`` without pictures), an unknown ``labels``, an
        ``emitter_distance_m`` outside 0 to 3 m, and for any file that cannot be read or does
        not match the recording (:func:`~.media.read_video`, :func:`~.media.read_audio`,
        :func:`~.posing.read_poses`, :func:`vrecho.io.read_mesh`, :func:`~.media.image_files`,
        :func:`~.media.check_pictures`).
    """
    if (video is None) == (audio is None):
        raise VrechoError("capture: give a video, or --audio with a sound file (not both)")
    if images is not None and video is not None:
        raise VrechoError("capture: --images goes with --audio (a video's pictures are its own)")
    if (poses is None) != (mesh is None):
        raise VrechoError("capture: --poses and --mesh go together (COLMAP's poses of the pictures, and the mesh)")
    if (poses is not None or images is not None) and image_fps is None:
        raise VrechoError("capture: --poses and --images need --image-fps, the rate the pictures were extracted at")
    if poses is not None and video is None and images is None:
        raise VrechoError("capture: --poses needs the pictures: a video, or --audio with --images")
    if not isinstance(labels, str) or labels not in LABELS:
        raise VrechoError(f"labels: expected one of {tuple(LABELS)}, got {labels!r}")
    if emitter_distance_m is not None:
        check_number(emitter_distance_m, "emitter-distance (m from the loudspeaker to the microphone)", lo=0, hi=3)
    if audio is not None:
        x, fs = read_audio(audio)
        video_start = 0.0
    else:
        x, fs, vtimes = read_video(video)
        video_start = float(vtimes[0]) if len(vtimes) else 0.0
    posed = user_mesh = None
    if poses is not None:
        posed = read_poses(poses, image_fps, x.size / fs, video_start_s=video_start)
        user_mesh = read_mesh(mesh).transform(posed.to_z_up)
    files = image_files(Path(images), None if posed is None else posed.names) if images is not None else None
    if files is not None:
        check_pictures(files)
        if posed is None:  # the pictures' times come from their names
            image_times([f.name for f in files], image_fps)
    return Recording(x, fs, None if video is None else Path(video), video_start, files, image_fps, posed, user_mesh,
                     labels, emitter_distance_m)


def answers(classifier, frames: np.ndarray, emitted: np.ndarray, *, images=None, flags=None, surface_m=None,
            mic_toward_surface_m=None) -> list[dict]:
    """EchoCNN's answers for frames at 44.1 kHz, the probe ``emitted`` known (and the crops
    ``images`` and the mesh's distance to the surface, if given), as ``frames.csv``'s columns.

    Parameters
    ----------
    classifier : vrecho.classifier.Classifier
        EchoCNN.
    frames : numpy.ndarray [shape=(K, 44100)], float32
        1 s frames at 44.1 kHz from the pulses' emission.
    emitted : numpy.ndarray [shape=(k,)], float
        The probe played, at 44.1 kHz.
    images : numpy.ndarray [shape=(K, 64, 25)], uint8, optional
        The camera's crop around the surface in each frame.
    flags : sequence of K sequences of str, optional
        What is known of each frame's recording (:func:`~.onsets.frame_flags`), for EchoCNN to
        flag the answer with (:meth:`~vrecho.classifier.Classifier.predict_batch`).
    surface_m, mic_toward_surface_m : float, optional
        The distance from the loudspeaker to the surface's plane and the microphone's offset
        toward it, as the mesh and the pose give them (:func:`vrecho.reconstruct.scan_distance`):
        open/closed then by the echo there (within :data:`vrecho.reconstruct.SCAN_TOLERANCE_M`).

    Returns
    -------
    list of dict
        One per frame: ``model``, ``open``, ``material`` ("-" when open), ``depth_m``
        (metres), ``p_open``, ``p_mirror``, ``confidence`` (rounded to 4 decimals; at most 0.5
        for a flagged answer) and ``flags`` (space-separated: ``clipped``, ``low_rate``,
        ``no_pulse``, ``narrowband_emitted``; :mod:`vrecho.classifier`).

    Raises
    ------
    VrechoError
        From EchoCNN, for frames or crops it cannot take (a silent frame, say).
    """
    scan = {} if surface_m is None else {"surface_m": surface_m, "mic_toward_surface_m": mic_toward_surface_m,
                                         "surface_tolerance_m": SCAN_TOLERANCE_M}
    preds = classifier.predict_batch(frames, FS, images=images, emitted=emitted, flags=flags, **scan) if len(frames) else []
    return [{"model": p.model, "open": p.is_open, "material": "-" if p.is_open else p.material,
             "depth_m": round(float(p.depth_m), 4), "p_open": round(p.probabilities["open"], 4),
             "p_mirror": round(p.probabilities["mirror"], 4), "confidence": round(p.confidence, 4),
             "flags": " ".join(p.flags)} for p in preds]


def analyse(rec: Recording, *, classifier=None) -> Analysis:
    """The pulses of a capture (:func:`~.onsets.find_onsets`), its frames
    (:func:`~.onsets.cut_frames`) and EchoCNN's answer to each, the probe known (EchoCNN-E);
    with poses and a mesh, each frame takes the pose of its pulse, the frames that face a hole
    of the mesh are asked again with the camera's crop around it (EchoCNN-EV, PROTOCOL.md's
    64 x 25) and, where the device's specular point falls in the hole, with the mesh's distance
    to its plane (``surface_m``, :func:`vrecho.reconstruct.scan_distance`), and the mesh is repaired (:func:`vrecho.reconstruct.reconstruct`).

    Parameters
    ----------
    rec : Recording
        The capture (:func:`open_capture`).
    classifier : vrecho.classifier.Classifier, optional
        EchoCNN (the shipped weights by default).

    Returns
    -------
    Analysis
        Its ``rows`` hold each frame's ``frame`` and ``time_s`` (seconds) and :func:`answers`'
        columns (a frame cut from a clipped stretch of the recording, or from a recording
        below 40 kHz, is answered flagged and at most 0.5 confident:
        :func:`~.onsets.frame_flags`); with poses, a posed frame also has its position
        ``x_m``, ``y_m``, ``z_m`` (metres), and a frame facing a hole the ``hole``'s index and the answers asked again.

    Raises
    ------
    VrechoError
        When no pulse train is found (speech, noise: :func:`~.onsets.find_onsets`), no pulse
        has a whole second of recording after it, the poses or mesh do not match the recording
        (:func:`~.posing.posed_scan`), or the mesh has holes and no pulse was played facing
        one.
    """
    if classifier is None:
        from ..classifier import load_classifier  # torch-bound (1.7 s): only when EchoCNN is asked

        classifier = load_classifier()
    x, fs, posed = rec.audio, rec.fs, rec.poses
    onsets = find_onsets(x, fs)
    frames, kept = cut_frames(x, onsets, mic_offset_m=rec.emitter_distance_m, return_index=True)
    if not len(frames):
        raise VrechoError("capture: no pulse has a whole second of recording after it")
    flags = frame_flags(x, onsets, kept, mic_offset_m=rec.emitter_distance_m)
    times = onsets.seconds[kept]  # a pulse too near either end of the recording has no frame
    width = VIEW_WIDTH if posed is not None else None
    if rec.video is not None:
        shots = video_images(rec.video, np.r_[times, posed.time_s if posed is not None else []], width=width)
        frame_pictures, pictures = shots[:len(times)], shots[len(times):]
    elif rec.files is not None:
        file_times = posed.time_s if posed is not None else image_times([f.name for f in rec.files], rec.image_fps)
        pictures = load_pictures(rec.files, width)
        frame_pictures = pictures[np.argmin(np.abs(times[:, None] - file_times[None]), axis=1)]
    else:
        pictures = frame_pictures = None
    emitted = probe(FS)
    rows = [{"frame": k, "time_s": round(float(t), 6)} | a
            for k, (t, a) in enumerate(zip(times, answers(classifier, frames, emitted, flags=flags)))]
    result = None
    if posed is not None:
        scan, ok = posed_scan(rec.mesh, posed, pictures, frames, times, frame_pictures, emitted)
        result = reconstruct(scan, decide=rec.labels, classifier=classifier)
        if result.holes and not any(d.frames for d in result.decisions):  # only pulses' views have echoes
            raise VrechoError(f"capture: the mesh has {len(result.holes)} hole(s) and no pulse was played facing one "
                              "(within 25 degrees of its normal, 0.25 to 3.5 m away); film each glass, mirror or "
                              "opening from in front while the pulses play")
        views, first = scan.views, len(posed.pose)
        frame_of = dict(zip(range(first, len(views)), np.flatnonzero(ok)))
        for k, v in zip(np.flatnonzero(ok), views[first:]):
            rows[k].update(x_m=round(float(v.pose[0, 3]), 4), y_m=round(float(v.pose[1, 3]), 4),
                           z_m=round(float(v.pose[2, 3]), 4))
        for h, hole in enumerate(result.holes):  # frames facing a hole: asked again with the crop and the distance
            for i in facing(views, hole):
                if i in frame_of and "hole" not in rows[frame_of[i]]:
                    crop, inside = crop_view(views[i], hole.corners())
                    surface, toward = scan_distance(views[i], hole)
                    a = answers(classifier, frames[frame_of[i]][None], emitted,
                                images=crop[None] if inside >= 0.98 else None, flags=[flags[frame_of[i]]],
                                surface_m=surface, mic_toward_surface_m=toward)[0]
                    rows[frame_of[i]].update(a, hole=h)
    return Analysis(onsets, frames, times, rows, frame_pictures, result)
