"""Room acoustics: pyroomacoustics rooms from scenes, cached impulse responses, recordings.

An impulse response does not depend on the emitted sound, so it is simulated once per scene and
source/microphone positions (image sources plus ray tracing, so a 1 s frame carries the whole
reverberant tail), cached on disk under a hash of everything that shapes it, and convolved with
each sound. Sample 0 of every impulse response returned here is the emission instant
(pyroomacoustics' fractional-delay lag is removed).

The device's loudspeaker radiates forward with the scene's directivity (``Scene.emitter_p``,
pyroomacoustics' cardioid family) in the image-source part; the microphone is omnidirectional
(pyroomacoustics allows no directive microphone with ray tracing).

Recordings follow PROTOCOL.md: a frame is 1 s of microphone signal from the pulse onset, in the
steady state of the pulse train (the previous pulses' tails fold into the frame), plus pink
background noise 20 to 40 dB below the direct sound and white microphone self-noise
(:func:`recording_conditions`).
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import os
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from ..device import DevicePose, MicArray
from ..errors import VrechoError
from ..io import atomic_save_npy
from ..materials import BANDS_HZ
from ..scene import Scene
from ..signals import FS, SPEED_OF_SOUND, check_fs, colored_noise

__all__ = ["DEFAULT_SIMULATION", "MIC_SENSITIVITY", "SPEED_OF_SOUND", "Simulation", "build_room",
           "default_cache_dir", "device_direct_amplitude", "device_impulse_response", "direct_amplitude",
           "echo_delay_s", "emitter_directivity", "impulse_responses", "record_pulse", "record_source",
           "recording_conditions", "through_microphone"]


MIC_SENSITIVITY = 0.05
"""Microphone gain: the direct sound of a 0.8-peak pulse 7 cm away peaks near 0.57 full scale."""


@dataclass(frozen=True)
class Simulation:
    """Settings of the hybrid simulator (image sources up to ``max_order``, then ray tracing).

    Parameters
    ----------
    max_order : int
        Highest image-source reflection order (default 3).
    n_rays : int
        Rays traced for the diffuse tail (default 3000); 0 for image sources only.
    receiver_radius_m : float
        Radius of the ray tracer's receiving sphere in metres (default 0.5).
    energy_thres : float
        Energy below which a ray stops being traced (pyroomacoustics' ``energy_thres``,
        default 1e-7).
    length_s : float
        Length of the impulse responses in seconds, and the ray tracer's time limit
        (default 1.0: one pulse-train period).
    air_absorption : bool
        Whether air absorbs sound (default True).
    """

    max_order: int = 3
    n_rays: int = 3000
    receiver_radius_m: float = 0.5
    energy_thres: float = 1e-7
    length_s: float = 1.0
    air_absorption: bool = True


DEFAULT_SIMULATION = Simulation()


def default_cache_dir() -> Path:
    """The folder of cached impulse responses: ``$VRECHO_CACHE/ir``, or ``~/.cache/vrecho/ir``.

    Returns
    -------
    pathlib.Path
        The folder (not created here).
    """
    return Path(os.environ.get("VRECHO_CACHE", Path.home() / ".cache" / "vrecho")) / "ir"


def _octave_bands(fs: int):
    import pyroomacoustics as pra  # heavy (1.4 s to import): only where it simulates or analyses

    return pra.acoustics.OctaveBandsFactory(fs=fs, n_fft=512, keep_dc=True, base_frequency=BANDS_HZ[0])


def build_room(scene: Scene, fs: int = FS, *, sim: Simulation = DEFAULT_SIMULATION):
    """A ``pyroomacoustics.Room`` of the scene's patches.

    Each patch has its own frequency-dependent material (resampled to the simulator's bands so
    every wall has the same ones). Ray tracing is set up only when ``sim.n_rays`` > 0.

    Parameters
    ----------
    scene : Scene
        The scene whose room, glass, mirrors and openings become walls.
    fs : int
        Sample rate in Hz (default :data:`vrecho.signals.FS`, 44 100).
    sim : Simulation
        Simulator settings.

    Returns
    -------
    pyroomacoustics.Room
        The room, with no source or microphone yet.

    Raises
    ------
    VrechoError
        If ``fs`` is not a whole number of hertz from 8000 to 384 000.
    """
    import pyroomacoustics as pra  # heavy (1.4 s to import): only where it simulates or analyses

    fs = check_fs(fs)
    bands = _octave_bands(fs)
    walls = []

    def wall(corners, material, name):
        m = pra.Material({"coeffs": list(material.absorption), "center_freqs": list(BANDS_HZ)}, material.scattering)
        m.resample(bands)
        walls.append(pra.wall_factory(corners.T, m.absorption_coeffs, m.scattering_coeffs, name=name))

    for i, patch in enumerate(scene.patches()):
        wall(patch.corners, patch.material, f"{patch.kind}{i}")
    for i, f in enumerate(scene.furniture):
        # pyroomacoustics tells a point inside the room by counting a ray's crossings of the walls:
        # a piece standing on the floor (no underside of its own: the floor covers it) must be
        # closed for that count, or a ray up through the floor beneath it counts one crossing short
        # and a point in the room's air reads as outside ("The source must be added inside the room").
        if f.on_floor:
            wall(f.underside(), f.material, f"underside{i}")
    room = pra.Room(walls, fs=fs, max_order=sim.max_order, ray_tracing=sim.n_rays > 0,
                    air_absorption=sim.air_absorption)
    if sim.n_rays > 0:
        room.set_ray_tracing(n_rays=sim.n_rays, receiver_radius=sim.receiver_radius_m,
                             energy_thres=sim.energy_thres, time_thres=sim.length_s)
    return room


@contextlib.contextmanager
def _dense_tail():
    """Work around pyroomacoustics 0.10.1's synthesis of the ray-traced tail.

    It shapes a sequence of random-sign impulses with the rays' energy histogram, one unit of
    energy per 4 ms bin, and draws the impulses at the reflection density of the image-source
    model, 4 pi c^3 t^2 / V from the direct path's time t0. With the emitter 7 cm from the
    microphone t0 is 0.2 ms, the density almost zero, and the first gap typically 0.4 s: the tail
    is silent until then (checked: -170 dB at 0.45 s, then back). Early on, even where impulses
    do come, a bin holds one or two, so the diffuse energy of the first reflections lands in a
    single spike as strong as a specular echo (checked: 0.17 at an opening's echo time, where the
    image sources give 0.008). The diffuse part is noise-like, so here the impulses come at a
    constant 10 000 per second from t0: every bin holds about 40, and the histogram's energy is
    spread as it should be.
    """
    from pyroomacoustics import random as pra_random  # heavy (1.4 s to import): only where it simulates or analyses
    from pyroomacoustics.simulation import rt  # heavy (1.4 s to import): only where it simulates or analyses

    original = rt.poisson_sequence

    def poisson_sequence(volume, duration, c, max_rate=10000, t0=None):
        t0 = 0.0 if t0 is None else t0
        gaps = pra_random.get_rng().exponential(1.0 / max_rate, int(1.2 * duration * max_rate) + 16)
        times = t0 + np.cumsum(gaps)
        last = int(np.searchsorted(times, t0 + duration))  # like pyroomacoustics: one past the end
        return t0, np.concatenate([[t0], times[:last + 1]])

    rt.poisson_sequence = poisson_sequence
    try:
        yield
    finally:
        rt.poisson_sequence = original


def _cache_key(scene: Scene, source: np.ndarray, mics: np.ndarray, fs: int, sim: Simulation,
               facing: np.ndarray | None) -> str:
    import pyroomacoustics as pra  # heavy (1.4 s to import): only where it simulates or analyses

    d = scene.to_dict()
    payload = {"room": d["room"], "discontinuities": d["discontinuities"], "source": np.round(source, 6).tolist(),
               "mics": np.round(mics, 6).tolist(), "fs": fs,
               "facing": None if facing is None else [np.round(facing, 6).tolist(), scene.emitter_p], "sim": asdict(sim), "pra": pra.__version__, "v": 4}
    if d["furniture"]:  # (only then: the keys of rooms without furniture stay what they were)
        payload["furniture"] = d["furniture"]
        payload["closed"] = True  # (pieces on the floor closed beneath since: their rooms simulated anew)
    return hashlib.sha256(json.dumps(payload, sort_keys=True).encode()).hexdigest()[:32]


def impulse_responses(scene: Scene, source: np.ndarray, mics: np.ndarray, fs: int = FS,
                      *, sim: Simulation = DEFAULT_SIMULATION, cache: str | Path | bool | None = None,
                      facing: np.ndarray | None = None) -> np.ndarray:
    """Simulated impulse responses from one source to each microphone.

    Simulated once per scene, source, microphones, sample rate, settings and facing, then read
    back from the cache (a damaged entry is simulated again and replaced). The ray tracer's
    random numbers are seeded from the cache key, so the same inputs give the same responses.

    Parameters
    ----------
    scene : Scene
        The scene whose room is simulated.
    source : numpy.ndarray [shape=(3,)]
        Source position in metres.
    mics : numpy.ndarray [shape=(M, 3)]
        Microphone positions in metres (a single (3,) position is taken as M = 1).
    fs : int
        Sample rate in Hz (default 44 100).
    sim : Simulation
        Simulator settings.
    cache : str, pathlib.Path, bool or None
        Folder of cached responses; None or True for :func:`default_cache_dir`, False for none.
    facing : numpy.ndarray [shape=(3,)], optional
        The device's forward axis when the source is its emitter: the emitter then radiates with
        the scene's ``emitter_p`` directivity (omnidirectional without it). Applies to the image
        sources; the diffuse ray-traced tail stays omnidirectional.

    Returns
    -------
    numpy.ndarray [shape=(M, round(sim.length_s * fs))], float32
        Sample 0 is the emission instant; the tail beyond ``length_s`` is folded in modulo the
        length, as in the steady state of a pulse train with that period.

    Raises
    ------
    VrechoError
        If ``source`` or ``mics`` has the wrong shape, if the source or a microphone is outside
        the room, or if ``fs`` is not a whole number of hertz from 8000 to 384 000.
    """
    import pyroomacoustics as pra  # heavy (1.4 s to import): only where it simulates or analyses

    fs = check_fs(fs)
    source = np.asarray(source, dtype=float)
    mics = np.atleast_2d(np.asarray(mics, dtype=float))
    if source.shape != (3,) or mics.ndim != 2 or mics.shape[1] != 3:
        raise VrechoError(f"source/mics: expected shapes (3,) and (M, 3), got {source.shape} and {mics.shape}")
    points = np.vstack([source, mics])
    outside = ~scene.room.contains(points)
    if outside.any():
        k = int(np.argmax(outside))
        what = "source" if k == 0 else f"microphone {k - 1}"
        raise VrechoError(f"{what} at {np.round(points[k], 3).tolist()} is outside the room")
    directive = facing is not None and scene.emitter_p < 1.0
    key = _cache_key(scene, source, mics, fs, sim, np.asarray(facing, float) if directive else None)
    folder = None if cache is False else Path(default_cache_dir() if cache in (None, True) else cache)
    if folder is not None:
        path = folder / key[:2] / f"{key}.npy"
        if path.exists():
            try:
                return np.load(path)
            except (OSError, ValueError):
                pass  # a damaged cache entry is simulated again and replaced
    pra.random.seed(int(key[:8], 16))  # ray tracing repeatable for the same key
    room = build_room(scene, fs, sim=sim)
    if directive:
        room.add_source(source, directivity=emitter_directivity(facing, scene.emitter_p))
    else:
        room.add_source(source)
    room.add_microphone_array(pra.MicrophoneArray(mics.T, fs))
    with _dense_tail():
        room.compute_rir()
    lag = pra.constants.get("frac_delay_length") // 2
    n = int(round(sim.length_s * fs))
    out = np.zeros((len(mics), n), dtype=np.float64)
    for m, rir in enumerate(room.rir):
        h = np.asarray(rir[0], dtype=np.float64)[lag:]
        h = np.pad(h, (0, -len(h) % n))
        out[m] = h.reshape(-1, n).sum(axis=0)
    out = out.astype(np.float32)
    if folder is not None:
        path.parent.mkdir(parents=True, exist_ok=True)
        atomic_save_npy(path, out)
    return out


def emitter_directivity(facing: np.ndarray, p: float):
    """The device's loudspeaker as pyroomacoustics sees it: a cardioid-family pattern.

    Parameters
    ----------
    facing : numpy.ndarray [shape=(3,)]
        Direction the loudspeaker points (any length; normalised here).
    p : float
        The pattern's parameter: 1 omnidirectional, 0.5 cardioid.

    Returns
    -------
    pyroomacoustics.directivities.CardioidFamily
        The pattern, pointing along ``facing``.
    """
    from pyroomacoustics.directivities import (  # heavy (1.4 s to import): only where it simulates or analyses
        CardioidFamily,
        DirectionVector,
    )

    f = np.asarray(facing, float) / np.linalg.norm(facing)
    direction = DirectionVector(np.degrees(np.arctan2(f[1], f[0])), np.degrees(np.arccos(np.clip(f[2], -1, 1))))
    return CardioidFamily(direction, p)


def device_impulse_response(scene: Scene, pose: DevicePose, *, array: MicArray | None = None, fs: int = FS,
                            sim: Simulation = DEFAULT_SIMULATION, cache=None) -> np.ndarray:
    """Impulse responses from the device's emitter to its microphones.

    The emitter radiates along ``pose.forward`` with the scene's directivity
    (:func:`impulse_responses` with ``facing``).

    Parameters
    ----------
    scene : Scene
        The scene whose room is simulated.
    pose : DevicePose
        Where the device stands and faces.
    array : MicArray, optional
        The microphones (the scene's array by default; channel 0 is the protocol's microphone
        7 cm above the emitter).
    fs : int
        Sample rate in Hz (default 44 100).
    sim : Simulation
        Simulator settings.
    cache : str, pathlib.Path, bool or None
        The response cache, as in :func:`impulse_responses`.

    Returns
    -------
    numpy.ndarray [shape=(M, n)], float32
        One response per microphone, n = ``round(sim.length_s * fs)`` samples, sample 0 the
        emission instant.

    Raises
    ------
    VrechoError
        As :func:`impulse_responses` (a microphone outside the room, a bad ``fs``).
    """
    array = scene.mic_array if array is None else array
    return impulse_responses(scene, pose.emitter, pose.microphones(array), fs, sim=sim, cache=cache, facing=pose.forward)


def direct_amplitude(distance_m: float, gain: float = 1.0) -> float:
    """Amplitude of the direct path at ``distance_m`` for a unit source.

    gain / r, the convention of pyroomacoustics 0.10 (checked: 14.2 at 7 cm, not 1 / 4 pi r);
    distances under 1 mm count as 1 mm.

    Parameters
    ----------
    distance_m : float
        Distance from the source to the microphone in metres.
    gain : float
        The source's directivity gain toward the microphone (default 1, omnidirectional).

    Returns
    -------
    float
        The direct sound's amplitude in the impulse response.

    Examples
    --------
    >>> round(direct_amplitude(0.07), 1)
    14.3
    """
    return gain / max(distance_m, 1e-3)


def device_direct_amplitude(scene: Scene, pose: DevicePose) -> float:
    """Amplitude of the device's own direct sound at its microphone.

    The loudspeaker's directivity (the scene's ``emitter_p``) toward the microphone, 7 cm above
    it, is included.

    Parameters
    ----------
    scene : Scene
        The scene, for the loudspeaker's directivity.
    pose : DevicePose
        The device's pose.

    Returns
    -------
    float
        :func:`direct_amplitude` of the microphone's distance, with that gain.
    """
    offset = pose.microphone - pose.emitter
    r = float(np.linalg.norm(offset))
    cos = float(np.dot(pose.forward, offset)) / r
    return direct_amplitude(r, scene.emitter_p + (1 - scene.emitter_p) * cos)


def recording_conditions(rng: np.random.Generator) -> tuple[float, float, float]:
    """One recording's noise levels and gain, drawn within PROTOCOL.md's ranges.

    Parameters
    ----------
    rng : numpy.random.Generator
        Source of the draw.

    Returns
    -------
    snr_db : float
        Pink background noise, 20 to 40 dB below the direct sound.
    self_noise_db : float
        White microphone self-noise, 55 to 70 dB below the direct sound.
    gain_db : float
        Recording gain, -6 to 0 dB.
    """
    return rng.uniform(20, 40), rng.uniform(55, 70), rng.uniform(-6, 0)


def through_microphone(x: np.ndarray, sound: np.ndarray, direct_amp: float, rng: np.random.Generator, snr_db: float,
                self_noise_db: float, gain_db: float) -> np.ndarray:
    """What the microphone adds to the sound field ``x``.

    Pink background noise and white self-noise, ``snr_db`` and ``self_noise_db`` below the
    direct sound (``direct_amp`` times the RMS of ``sound``), then its sensitivity
    (:data:`MIC_SENSITIVITY`) and the recording gain.

    Parameters
    ----------
    x : numpy.ndarray [shape=(..., n)]
        The sound field at the microphones; every channel gets its own noise.
    sound : numpy.ndarray [shape=(k,)]
        The emitted sound, for the direct sound's level.
    direct_amp : float
        Amplitude of the direct path.
    rng : numpy.random.Generator
        Source of the noise.
    snr_db, self_noise_db : float
        Pink background noise and white self-noise, in dB below the direct sound.
    gain_db : float
        Recording gain in dB.

    Returns
    -------
    numpy.ndarray [shape=x.shape], float32
        The recording.
    """
    level = direct_amp * np.sqrt(np.mean(np.asarray(sound, dtype=np.float64) ** 2))
    n = x.shape[-1]
    pink = np.stack([colored_noise(n, 1.0, rng) for _ in range(int(np.prod(x.shape[:-1])))]).reshape(x.shape)
    white = rng.standard_normal(x.shape)
    x = x + level * (10 ** (-snr_db / 20) * pink + 10 ** (-self_noise_db / 20) * white)
    return (x * MIC_SENSITIVITY * 10 ** (gain_db / 20)).astype(np.float32)


def record_pulse(ir: np.ndarray, sound: np.ndarray, direct_amp: float, rng: np.random.Generator,
                 snr_db: float = 30.0, self_noise_db: float = 60.0, gain_db: float = 0.0) -> np.ndarray:
    """One 1 s frame of the device hearing its own pulse train.

    The frame is one period of ``ir`` long (1 s with the default :class:`Simulation`).

    Parameters
    ----------
    ir : numpy.ndarray [shape=(n,) or (M, n)]
        Impulse responses from :func:`impulse_responses` (n samples = one period).
    sound : numpy.ndarray [shape=(k,)]
        The emitted sound (k <= n).
    direct_amp : float
        Amplitude of the direct path (:func:`device_direct_amplitude`): the noise levels are
        relative to the direct sound.
    rng : numpy.random.Generator
        Source of the noise.
    snr_db, self_noise_db : float
        Pink background noise and white self-noise, in dB below the direct sound (defaults 30
        and 60 dB).
    gain_db : float
        Recording gain in dB (default 0).

    Returns
    -------
    numpy.ndarray [shape=ir.shape], float32
        Steady state of the pulse train: circular convolution of the folded response with the sound.

    Raises
    ------
    VrechoError
        If ``sound`` is not 1-D or is longer than the frame.

    Examples
    --------
    >>> import numpy as np
    >>> from vrecho.signals import probe
    >>> ir = np.zeros(44100)
    >>> ir[0] = 14.3  # the direct sound alone
    >>> frame = record_pulse(ir, probe(), 14.3, np.random.default_rng(0))
    >>> frame.shape, frame.dtype
    ((44100,), dtype('float32'))
    """
    ir = np.asarray(ir, dtype=np.float64)
    n = ir.shape[-1]
    sound = np.asarray(sound, dtype=np.float64)
    if sound.ndim != 1 or sound.size > n:
        raise VrechoError(f"sound: must be 1-D and at most {n} samples, got shape {sound.shape}")
    x = np.fft.irfft(np.fft.rfft(ir, n) * np.fft.rfft(sound, n), n)
    return through_microphone(x, sound, direct_amp, rng, snr_db, self_noise_db, gain_db)


def record_source(ir: np.ndarray, sound: np.ndarray, onset_s: float, direct_amp: float,
                  rng: np.random.Generator, fs: int = FS, snr_db: float = 30.0, self_noise_db: float = 60.0,
                  gain_db: float = 0.0) -> np.ndarray:
    """1 s of microphone signal while an ambient source plays ``sound`` once.

    The sound starts ``onset_s`` into the frame (linear convolution: the source is not periodic);
    what would sound past the frame's end is cut. The frame is one period of ``ir`` long (1 s
    with the default :class:`Simulation`).

    Parameters
    ----------
    ir : numpy.ndarray [shape=(n,) or (M, n)]
        Impulse responses from the source to the microphones (:func:`impulse_responses`).
    sound : numpy.ndarray [shape=(k,)]
        What the source plays.
    onset_s : float
        When it starts, in seconds from the frame's start.
    direct_amp : float
        As in :func:`record_pulse` (:func:`direct_amplitude` of the source's distance).
    rng : numpy.random.Generator
        Source of the noise.
    fs : int
        Sample rate in Hz (default 44 100).
    snr_db, self_noise_db : float
        Pink background noise and white self-noise, in dB below the direct sound (defaults 30
        and 60 dB).
    gain_db : float
        Recording gain in dB (default 0).

    Returns
    -------
    numpy.ndarray [shape=ir.shape], float32
        The recording.

    Raises
    ------
    VrechoError
        If ``onset_s`` lies outside the frame, or ``fs`` is not a whole number of hertz of at
        least 8000.
    """
    ir = np.asarray(ir, dtype=np.float64)
    n = ir.shape[-1]
    start = int(round(onset_s * check_fs(fs)))
    if not 0 <= start < n:
        raise VrechoError(f"onset_s: must lie within the frame (0 to {n / fs} s), got {onset_s}")
    excitation = np.zeros(n)
    k = min(len(sound), n - start)
    excitation[start:start + k] = sound[:k]
    m = 2 * n
    x = np.fft.irfft(np.fft.rfft(ir, m) * np.fft.rfft(excitation, m), m)[..., :n]
    return through_microphone(x, sound, direct_amp, rng, snr_db, self_noise_db, gain_db)


def echo_delay_s(scene: Scene, pose: DevicePose, index: int | None = None) -> float:
    """Time from the direct sound to the specular echo off a discontinuity's plane.

    The image-source path through the plane minus the direct path, at
    :data:`~vrecho.signals.SPEED_OF_SOUND`.

    Parameters
    ----------
    scene : Scene
        The scene.
    pose : DevicePose
        The device's pose.
    index : int, optional
        The discontinuity (the pose's target by default).

    Returns
    -------
    float
        The delay in seconds.
    """
    index = pose.target if index is None else index
    _, _, normal = scene.room.wall_frame(scene.discontinuities[index].wall)
    depth = scene.depth_m(pose, index)
    image = pose.emitter + 2 * depth * normal
    return float((np.linalg.norm(pose.microphone - image) - np.linalg.norm(pose.microphone - pose.emitter))
                 / SPEED_OF_SOUND)
