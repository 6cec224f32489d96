"""The room's sound sources heard by a microphone array along a walk: the simulator of
:mod:`localization`'s captures.

:func:`simulate_walk_capture` records a room's ambient sources (:mod:`vrecho.sim.sounds`) with
the foundation's acoustics: a :class:`vrecho.scene.Scene`'s room (image sources plus ray
tracing, :func:`vrecho.sim.acoustics.impulse_responses`) or a :class:`Shoebox` of a chosen
reverberation time (pyroomacoustics' image sources, absorption from Sabine's formula). Each
source plays continuously; capture ``k`` hears the stretch of it from ``k * segment_s``, with
the room's reverberation of what came before. Pink background noise and microphone self-noise
are added (PROTOCOL.md). The per-source images at every microphone come back too: they are the
reference for separation metrics. :func:`hear_scene` hears a scene's own sources along its
walkthrough; :func:`random_walk` draws the benchmark's and the mask network's rooms.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from localization.capture import FS, Capture

from ..device import MIC_ABOVE_EMITTER_M, MIC_ARRAYS, DevicePose, MicArray
from ..errors import VrechoError
from ..scene import Scene
from ..signals import check_fs, colored_noise
from .acoustics import Simulation, impulse_responses
from .scenes import walkthrough_path
from .sounds import ambient_sound


@dataclass(frozen=True)
class Shoebox:
    """A rectangular room whose walls share one frequency-flat absorption.

    The absorption is chosen for the reverberation time ``rt60_s`` (Sabine).

    Parameters
    ----------
    dims : tuple of float
        The room's size (x, y, z) in metres, corner at the origin.
    rt60_s : float
        Reverberation time in seconds.
    """

    dims: tuple[float, float, float]
    rt60_s: float

    def contains(self, p: np.ndarray, *, margin_m: float = 0.0) -> np.ndarray:
        """Whether points lie strictly inside the room (as :meth:`vrecho.scene.Room.contains`).

        Parameters
        ----------
        p : numpy.ndarray [shape=(N, 3) or (3,)]
            Points in metres.
        margin_m : float
            Least distance from every wall, the floor and the ceiling, in metres; 0 by default.

        Returns
        -------
        numpy.ndarray [shape=(N,)], bool
            True for each point inside.
        """
        p = np.atleast_2d(p)
        return np.all((p > margin_m) & (p < np.asarray(self.dims) - margin_m), axis=1)


@dataclass
class AmbientSource:
    """A source at ``position`` playing ``signal`` from time 0.

    Parameters
    ----------
    position : numpy.ndarray [shape=(3,)]
        Where the source is, in metres.
    signal : numpy.ndarray [shape=(n,)]
        What it plays (1-D, at the capture's rate).
    name : str
        A label (default "source").
    """

    position: np.ndarray
    signal: np.ndarray
    name: str = "source"


@dataclass
class SimulatedCapture:
    """A simulated capture along a walk, with the separation reference.

    Parameters
    ----------
    captures : list of localization.capture.Capture
        One per pose: (mics, samples) audio with the microphones' world positions.
    images : numpy.ndarray [shape=(poses, sources, mics, samples)], float64
        What each source alone contributes to each microphone (the separation reference).
    sources : list of AmbientSource
        The sources heard.
    poses : list of DevicePose
        The device's poses, one per capture.
    """

    captures: list[Capture]
    images: np.ndarray
    sources: list[AmbientSource]
    poses: list[DevicePose] = field(default_factory=list)


def _rirs(room, sources: list[np.ndarray], mics: np.ndarray, fs: int, cache) -> list[np.ndarray]:
    """Impulse responses (mics, n) from each source, sample 0 the emission instant."""
    if isinstance(room, Scene):
        sim = Simulation(length_s=1.5)
        return [impulse_responses(room, s, mics, fs, sim=sim, cache=cache).astype(np.float64) for s in sources]
    import pyroomacoustics as pra  # heavy (1.4 s to import): only where it simulates or analyses

    absorption, max_order = pra.inverse_sabine(room.rt60_s, room.dims)
    shoebox = pra.ShoeBox(list(room.dims), fs=fs, materials=pra.Material(absorption), max_order=min(max_order, 40),
                          air_absorption=False)
    for s in sources:
        shoebox.add_source(s)
    shoebox.add_microphone_array(pra.MicrophoneArray(mics.T, fs))
    shoebox.compute_rir()
    lag = pra.constants.get("frac_delay_length") // 2
    out = []
    for k in range(len(sources)):
        n = max(len(shoebox.rir[m][k]) for m in range(len(mics))) - lag
        h = np.zeros((len(mics), n))
        for m in range(len(mics)):
            r = np.asarray(shoebox.rir[m][k], dtype=np.float64)[lag:]
            h[m, :len(r)] = r
        out.append(h)
    return out


def simulate_walk_capture(room: Scene | Shoebox, sources: list[AmbientSource], poses: list[DevicePose],
                          rng: np.random.Generator, *, array: MicArray | str = "headset4", fs: int = FS,
                          segment_s: float = 2.0, snr_db: float = 30.0, self_noise_db: float = 60.0,
                          cache=None) -> SimulatedCapture:
    """Record ``sources`` at each of ``poses`` (see the module's docstring).

    Capture ``k`` hears each source's signal from ``k * segment_s``, with the room's
    reverberation of what came before.

    Parameters
    ----------
    room : Scene or Shoebox
        The room: a scene's (image sources plus ray tracing) or a shoebox (image sources).
    sources : list of AmbientSource
        The sources; each signal must last at least ``len(poses) * segment_s`` seconds.
    poses : list of DevicePose
        Where the device is for each capture.
    rng : numpy.random.Generator
        Source of the noise.
    array : MicArray or str
        The microphones, or the name of one of :data:`vrecho.scene.MIC_ARRAYS` (default
        "headset4").
    fs : int
        Sample rate in Hz (default :data:`localization.capture.FS`, 16 000).
    segment_s : float
        Length of each capture in seconds (default 2).
    snr_db : float
        The sources' summed power at the reference microphone over pink background noise, in dB
        (default 30).
    self_noise_db : float
        The same over white self-noise on every channel, in dB (default 60).
    cache : str, pathlib.Path, bool or None
        The impulse response cache of :func:`vrecho.sim.acoustics.impulse_responses` (Scene
        rooms only).

    Returns
    -------
    SimulatedCapture
        One capture of ``round(segment_s * fs)`` samples per pose, starting at ``k * segment_s``
        seconds, and each source's image at every microphone.

    Raises
    ------
    VrechoError
        If there is no source, a signal is not 1-D or too short, a source or a microphone is
        outside the room, or ``fs`` is not a whole number of hertz from 8000 to 384 000.
    """
    fs = check_fs(fs)
    array = MIC_ARRAYS[array] if isinstance(array, str) else array
    if not sources:
        raise VrechoError("sources: a capture needs at least one source")
    n = int(round(segment_s * fs))
    need = n * len(poses)
    for k, s in enumerate(sources):
        if np.asarray(s.signal).ndim != 1 or len(s.signal) < need:
            raise VrechoError(f"sources[{k}].signal: expected 1-D with at least {need} samples "
                              f"({len(poses)} poses x {segment_s} s), got shape {np.shape(s.signal)}")
    positions = [np.asarray(s.position, float) for s in sources]
    contains = room.room.contains if isinstance(room, Scene) else room.contains
    inside = contains(np.array(positions))
    if not np.all(inside):
        raise VrechoError(f"sources[{int(np.argmin(inside))}] at {positions[int(np.argmin(inside))].tolist()} is outside the room")
    captures, images = [], np.zeros((len(poses), len(sources), array.n_mics, n))
    for p, pose in enumerate(poses):
        mics = pose.microphones(array)
        if not np.all(contains(mics)):
            raise VrechoError(f"poses[{p}]: a microphone is outside the room")
        start = p * n
        for k, (s, h) in enumerate(zip(sources, _rirs(room, positions, mics, fs, cache))):
            lead = min(start, h.shape[1])  # the reverberation of what the source played before
            x = np.asarray(s.signal[start - lead:start + n], dtype=np.float64)
            m = len(x) + h.shape[1]
            y = np.fft.irfft(np.fft.rfft(h, m) * np.fft.rfft(x, m), m)
            images[p, k] = y[:, lead:lead + n]
        clean = images[p].sum(axis=0)
        power = np.mean(clean[0] ** 2)
        noise = np.stack([colored_noise(n, 1.0, rng) for _ in range(array.n_mics)])
        noise *= np.sqrt(power * 10 ** (-snr_db / 10) / np.mean(noise ** 2))
        noise += rng.standard_normal(noise.shape) * np.sqrt(power * 10 ** (-self_noise_db / 10))
        captures.append(Capture(clean + noise, fs, mics, start / fs))
    return SimulatedCapture(captures, images, list(sources), list(poses))


def hear_scene(scene: Scene, rng: np.random.Generator, *, n_poses: int = 8, segment_s: float = 1.5,
               array: MicArray | str = "headset4", fs: int = FS, cache=None) -> SimulatedCapture:
    """The scene's own sources heard along its walkthrough.

    The walkthrough is the scene's ``camera_path``, or :func:`vrecho.sim.scenes.walkthrough_path`:
    ``n_poses`` captures of ``segment_s`` each, the headset looking where the camera looks (its
    emitter 7 cm below the path); each source plays its sound repeated at random intervals
    (:func:`vrecho.sim.sounds.ambient_sound`) at its gain.

    Parameters
    ----------
    scene : Scene
        The scene, with at least one sound source.
    rng : numpy.random.Generator
        Source of the sounds and the noise.
    n_poses : int
        Number of captures, evenly spaced along the path (default 8).
    segment_s : float
        Length of each capture in seconds (default 1.5).
    array : MicArray or str
        The microphones, or the name of one of :data:`vrecho.scene.MIC_ARRAYS` (default
        "headset4").
    fs : int
        Sample rate in Hz (default 16 000).
    cache : str, pathlib.Path, bool or None
        The impulse response cache of :func:`vrecho.sim.acoustics.impulse_responses`.

    Returns
    -------
    SimulatedCapture
        As :func:`simulate_walk_capture`.

    Raises
    ------
    VrechoError
        If the scene has no sound sources, or as :func:`simulate_walk_capture`.
    """
    if not scene.sources:
        raise VrechoError(f"scene {scene.name!r} has no sound sources to hear")
    path = scene.camera_path or walkthrough_path(scene)
    positions, forwards = path.sample(n_poses)
    poses = [DevicePose(p - [0.0, 0.0, MIC_ABOVE_EMITTER_M], f, [0.0, 0.0, 1.0]) for p, f in zip(positions, forwards)]
    duration = n_poses * segment_s
    sources = [AmbientSource(np.asarray(s.position, float), ambient_sound(s.sound, duration, fs, rng) * 10 ** (s.gain_db / 20),
                             f"{s.sound}_{k}") for k, s in enumerate(scene.sources)]
    return simulate_walk_capture(scene, sources, poses, rng, array=array, fs=fs, segment_s=segment_s, cache=cache)


AMBIENT_KINDS = ("speech", "music", "hum", "protocol")


PROTOCOL_SOUNDS = ("clap", "voice", "whistle", "chirp", "white_noise", "pink_noise", "tone_1000")
"""The PROTOCOL.md sounds a random room's source may repeat."""


def random_walk(rng: np.random.Generator, n_sources: int, rt60_s: float, *, n_poses: int = 8,
                segment_s: float = 1.5) -> tuple[Shoebox, list[AmbientSource], list[DevicePose]]:
    """A random shoebox room, a walk through it and sources around it.

    A room 3.5-7 x 3-6 x 2.4-3 m of reverberation time ``rt60_s``, a walk of ``n_poses`` headset
    poses along an arc through it (head turned up to 46 degrees from the path, 1.45 to 1.7 m
    high) and ``n_sources`` sources at least 1 m apart and 1 m from the walk, each playing
    speech, music, appliance hum or one of PROTOCOL.md's sounds repeated, long enough for
    ``n_poses`` captures of ``segment_s``: the benchmark's rooms and the mask network's training
    rooms (different seeds). The signals are at 16 kHz (:data:`localization.capture.FS`).

    Parameters
    ----------
    rng : numpy.random.Generator
        Source of the draw.
    n_sources : int
        Number of sources.
    rt60_s : float
        Reverberation time in seconds.
    n_poses : int
        Number of poses along the walk (default 8).
    segment_s : float
        Length of each capture in seconds (default 1.5).

    Returns
    -------
    room : Shoebox
        The room.
    sources : list of AmbientSource
        The sources, each signal ``n_poses * segment_s`` seconds long.
    poses : list of DevicePose
        The walk.

    Examples
    --------
    >>> import numpy as np
    >>> room, sources, poses = random_walk(np.random.default_rng(0), 2, 0.5)
    >>> room.rt60_s, len(sources), len(poses)
    (0.5, 2, 8)
    >>> sources[0].signal.shape
    (192000,)
    """
    dims = (rng.uniform(3.5, 7), rng.uniform(3, 6), rng.uniform(2.4, 3.0))
    c = np.array(dims[:2]) / 2
    rx, ry = c[0] - rng.uniform(0.9, 1.3), c[1] - rng.uniform(0.9, 1.3)
    a0, span = rng.uniform(0, 2 * np.pi), rng.uniform(np.pi, 1.6 * np.pi)
    poses = []
    for t in np.linspace(0, 1, n_poses):
        a = a0 + span * t
        tangent = np.array([-rx * np.sin(a), ry * np.cos(a)])
        tangent /= np.linalg.norm(tangent)
        yaw = rng.uniform(-0.8, 0.8)
        forward = [np.cos(yaw) * tangent[0] - np.sin(yaw) * tangent[1],
                   np.sin(yaw) * tangent[0] + np.cos(yaw) * tangent[1], rng.uniform(-0.15, 0.1)]
        poses.append(DevicePose([c[0] + rx * np.cos(a), c[1] + ry * np.sin(a), rng.uniform(1.45, 1.7)], forward, [0, 0, 1]))
    sources = []
    while len(sources) < n_sources:
        q = np.array([rng.uniform(0.4, dims[0] - 0.4), rng.uniform(0.4, dims[1] - 0.4), rng.uniform(0.3, 2.0)])
        if min(np.linalg.norm(q - p.emitter) for p in poses) < 1.0 or any(np.linalg.norm(q - s.position) < 1.0 for s in sources):
            continue
        kind = AMBIENT_KINDS[int(rng.integers(len(AMBIENT_KINDS)))]
        sound = PROTOCOL_SOUNDS[int(rng.integers(len(PROTOCOL_SOUNDS)))] if kind == "protocol" else kind
        sources.append(AmbientSource(q, ambient_sound(sound, n_poses * segment_s, FS, rng), sound))
    return Shoebox(dims, rt60_s), sources, poses
