"""Captures as a phone makes them: a recording of the pulse train through a room
(:func:`simulate_recording`), and a whole capture for ``vrecho capture`` (:func:`simulate_capture`:
the video with its sound, COLMAP's poses of its pictures and the depth camera's mesh).
"""

from __future__ import annotations

import dataclasses

import numpy as np
from PIL import Image
from tqdm import tqdm

from .. import colmap
from ..camera import Camera, View, camera_pose, device_pose
from ..capture.media import write_video
from ..errors import VrechoError
from ..io import ensure_writable_dir, write_mesh
from ..reconstruct.scan import fuse
from ..signals import FS, PERIOD_S, parabolic_peaks, probe
from .acoustics import device_impulse_response, through_microphone
from .render import World, render_view
from .scenes import walkthrough_path


def simulate_recording(ir: np.ndarray, n_pulses: int, rng: np.random.Generator, *, fs: int = FS, emitted=None,
                       snr_db: float = 30.0, drift: float = 0.0, clip: float | None = None,
                       dropped: tuple[int, ...] = (), lead_s: float = 0.3,
                       pauses: dict[int, float] | None = None) -> tuple[np.ndarray, np.ndarray]:
    """A recording of the pulse train as a phone makes it, with the truth.

    Pulses come every ``PERIOD_S * (1 + drift)`` s from ``lead_s`` plus a random fraction of a
    sample (the two clocks are not aligned), pulses in ``dropped`` are not played, and the train
    is held back by ``pauses[k]`` seconds from pulse k on (the player paused, or looping its file
    with a gap at the seam). Pink noise ``snr_db`` below the direct sound and white self-noise
    80 dB below it are added, and the microphone's sensitivity applied
    (:func:`~vrecho.sim.acoustics.through_microphone`); then the signal is clipped at ``clip``
    times the direct sound's peak (if given). That peak is taken before the microphone's
    sensitivity (0.05), so the rail lies at 20 x ``clip`` times the direct sound's peak as
    recorded (``clip`` = 0.3 puts it at 6 times that peak).

    Parameters
    ----------
    ir : numpy.ndarray [shape=(n,) or (n_pulses, n)]
        The room's impulse response from the loudspeaker to the microphone (sample 0: the
        emission; :func:`~vrecho.sim.acoustics.device_impulse_response`), whose first arrival is
        the direct sound; or one per pulse, the device moving.
    n_pulses : int
        Number of pulses in the train.
    rng : numpy.random.Generator
        Source of the sub-sample offset and the noise.
    fs : int
        Sample rate in Hz (default 44 100).
    emitted : numpy.ndarray [shape=(k,)], optional
        The emitted sound (vrecho's probe at ``fs`` by default).
    snr_db : float
        Pink noise level in dB below the direct sound (default 30).
    drift : float
        Relative error of the player's clock: the period is ``PERIOD_S * (1 + drift)`` s
        (default 0).
    clip : float, optional
        Where the signal clips, in times the direct sound's peak (see above); None for no
        clipping.
    dropped : tuple of int
        Indices of pulses not played.
    lead_s : float
        Time before the first pulse in seconds (default 0.3).
    pauses : dict of int to float, optional
        Delay in seconds added from pulse k on, keyed by k.

    Returns
    -------
    audio : numpy.ndarray [shape=(N,)], float32
        The microphone's signal.
    onsets : numpy.ndarray [shape=(n_pulses,)], float64
        Where each pulse's direct sound begins, in fractional samples; NaN for a dropped pulse.

    Raises
    ------
    VrechoError
        If ``ir`` is 2-D with other than ``n_pulses`` rows.

    Examples
    --------
    >>> import numpy as np
    >>> ir = np.zeros(4410)
    >>> ir[0], ir[900] = 14.3, 0.5  # the direct sound and one echo
    >>> audio, onsets = simulate_recording(ir, 3, np.random.default_rng(0), dropped=(1,))
    >>> audio.shape, onsets.shape, bool(np.isnan(onsets[1]))
    ((171990,), (3,), True)
    """
    s = probe(fs) if emitted is None else np.asarray(emitted, dtype=np.float64)
    irs = np.asarray(ir, dtype=np.float64)
    irs = np.broadcast_to(irs, (n_pulses, irs.shape[-1])) if irs.ndim == 1 else irs
    if irs.shape[0] != n_pulses:
        raise VrechoError(f"ir: expected one response, or one per pulse ({n_pulses}), got shape {np.shape(ir)}")
    period = PERIOD_S * (1 + drift) * fs
    n = int(lead_s * fs + (n_pulses + 0.5) * period) + irs.shape[1]
    starts = lead_s * fs + rng.uniform(0, 1) + np.arange(n_pulses) * period
    for k, pause in (pauses or {}).items():
        starts[k:] += pause * fs
    n += int(sum((pauses or {}).values()) * fs)
    x = np.zeros(n)
    m = 1 << int(np.ceil(np.log2(s.size + irs.shape[1] + 64)))
    spectrum = np.fft.rfft(s, m)
    freqs = np.fft.rfftfreq(m)
    shared = np.fft.rfft(irs[0], m) if np.ndim(ir) == 1 else None
    for k, t in enumerate(starts):
        if k in dropped:
            continue
        i = int(np.floor(t))  # the pulse delayed by its fraction of a sample, through its response
        heard = np.fft.irfft(spectrum * np.exp(-2j * np.pi * freqs * (t - i))
                             * (shared if shared is not None else np.fft.rfft(irs[k], m)), m)
        x[i:i + m] += heard[:n - i]
    a = np.abs(irs)
    direct = np.argmax(a > 0.5 * a.max(axis=1, keepdims=True), axis=1)  # each response's first strong arrival
    offset = np.array([parabolic_peaks(r, np.array([d]))[0] for r, d in zip(a, direct)])  # its sub-sample time
    amp = float(a.max())
    x = through_microphone(x, s, amp, rng, snr_db, 80.0, 0.0).astype(np.float64)
    if clip is not None:
        rail = clip * amp * np.abs(s).max()
        x = np.clip(x, -rail, rail)
    truth = starts + offset
    truth[list(dropped)] = np.nan
    return x.astype(np.float32), truth


def simulate_capture(scene, folder, *, n_pulses: int = 20, fps: float = 4.0, camera=None, seed: int = 0,
                     audio_codec: str = "flac", snr_db: float = 30.0, video: tuple[int, int, float] | None = None,
                     progress: bool = False) -> dict:
    """A phone capture of a scene as a user brings it to ``vrecho capture``, made by the simulator.

    The device walks the scene's path (:func:`~vrecho.sim.scenes.walkthrough_path` if it has
    none) for ``n_pulses`` seconds playing the pulse train; ``capture.mkv`` (H.264 pictures at
    ``fps`` and the microphone's sound, scaled to peak 0.5; ``audio_codec`` "flac", or "aac" in
    ``capture.mp4``), the pictures' poses as COLMAP's text model in ``poses/`` (numbered from 1
    at ``fps``, as ffmpeg extracts them), and the depth camera's scan fused into ``mesh.ply``.
    Each pulse is heard through the room's response where the device is when it plays.

    Parameters
    ----------
    scene : Scene
        The scene to capture.
    folder : str or pathlib.Path
        Where the files go (created if needed).
    n_pulses : int
        Number of pulses, one a second (default 20).
    fps : float
        Rate of the rendered pictures in frames per second (default 4).
    camera : vrecho.camera.Camera, optional
        The phone's camera (``Camera()`` by default).
    seed : int
        Seed of the recording's noise and the video's sensor noise (default 0).
    audio_codec : str
        "flac" (in ``capture.mkv``, the default) or "aac" (in ``capture.mp4``).
    snr_db : float
        Pink noise level in dB below the direct sound (default 30).
    video : tuple of (int, int, float), optional
        (width, height, rate): the video as a phone writes it instead, each rendered picture
        scaled up to width x height pixels and shown until the next at ``rate`` frames per
        second, with a little sensor noise.
    progress : bool
        Whether to show progress bars.

    Returns
    -------
    dict
        "video", "poses" and "mesh": the paths; "fps"; "onsets_s": the true onsets of the
        pulses (n_pulses,) in seconds; "pulse_poses": the device's camera-to-world poses at the
        pulses (n_pulses, 4, 4).

    Raises
    ------
    VrechoError
        If ``folder`` cannot be written.
    """
    camera = Camera() if camera is None else camera
    if scene.camera_path is None:
        scene = dataclasses.replace(scene, camera_path=walkthrough_path(scene))
    folder = ensure_writable_dir(folder)
    rng = np.random.default_rng(seed)
    lead_s = 0.3
    walk = lambda t: np.clip((np.asarray(t, float) - lead_s) / max(n_pulses - 1, 1), 0, 1)  # noqa: E731 (pulse k at k/(n-1))
    pulse_t = lead_s + np.arange(n_pulses) * PERIOD_S
    pos, fwd = scene.camera_path.at(walk(pulse_t))
    poses = [camera_pose(p, f) for p, f in zip(pos, fwd)]
    irs = np.stack([device_impulse_response(scene, device_pose(View(None, None, None, q)))[0]
                    for q in tqdm(poses, desc="simulate pulses", unit="pulse", disable=not progress)])
    x, onsets = simulate_recording(irs, n_pulses, rng, snr_db=snr_db, lead_s=lead_s)
    x = 0.5 * x / np.abs(x).max()
    duration = len(x) / FS
    pic_t = np.arange(int(duration * fps)) / fps
    pos, fwd = scene.camera_path.at(walk(pic_t))
    world = World(scene)
    views = [render_view(world, camera_pose(p, f), camera=camera)
             for p, f in tqdm(list(zip(pos, fwd)), desc="render pictures", unit="picture", disable=not progress)]
    path = folder / ("capture.mkv" if audio_codec == "flac" else "capture.mp4")
    gray = [np.round(255 * v.gray).astype(np.uint8) for v in views]
    if video is None:
        write_video(path, np.stack(gray), fps, x, FS, audio_codec=audio_codec)
    else:
        width, height, rate = video
        big = [np.asarray(Image.fromarray(g).resize((width, height), Image.BILINEAR), np.int16) for g in gray]

        def frames():
            for i in range(int(duration * rate)):
                noise = rng.integers(-2, 3, (height, width), dtype=np.int16)
                yield np.clip(big[min(int(i / rate * fps), len(big) - 1)] + noise, 0, 255).astype(np.uint8)

        write_video(path, tqdm(frames(), total=int(duration * rate), desc="encode video", unit="frame",
                               disable=not progress), rate, x, FS, audio_codec=audio_codec)
    names = [f"{k + 1:06d}.png" for k in range(len(views))]
    colmap.write_model(folder / "poses", colmap.pinhole(camera.intrinsics, camera.width, camera.height), names,
                       np.stack([v.pose for v in views]))
    write_mesh(folder / "mesh.ply", fuse(views, progress=progress))
    return {"video": path, "poses": folder / "poses", "mesh": folder / "mesh.ply", "fps": fps,
            "onsets_s": onsets / FS, "pulse_poses": np.stack(poses)}
