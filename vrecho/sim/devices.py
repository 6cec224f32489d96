"""Devices of PROTOCOL.md's operating envelope, and echo frames they record.

The reference device (a loudspeaker firing forward, the microphone 7 cm above it) is one of
many. :class:`Device` describes another: its loudspeaker's directivity (omnidirectional to
cardioid) and axis (anywhere relative to the camera: many phones fire out of their bottom
edge), where its microphone sits (1 to 15 cm from the loudspeaker, any direction), its
transducers' response (little output below 200 to 400 Hz, a resonance), automatic gain with a
limiter, and AAC at 128 kbps. :func:`echo_frame` puts such a device in front of a
discontinuity of a random room at any height from 0.4 to 2.6 m, tilted and turned up to 30
degrees, and records one frame of the user's own broadband probe; :func:`echo_frames` records
several as the device steps about in front of the same surface. Each frame carries the room's
other echoes that could share its surface's delay (:func:`clutter_paths`).

The named :data:`CONDITIONS` draw one property from its extreme and the rest as the reference
device has them, so that a benchmark reports each on its own row; ``"envelope"`` draws all at
once.
"""

from __future__ import annotations

import dataclasses
import io
from dataclasses import dataclass

import numpy as np
import scipy.signal

from ..device import MIC_ABOVE_EMITTER_M
from ..errors import VrechoError
from ..signals import FS, random_probe
from .acoustics import Simulation, build_room, direct_amplitude, impulse_responses, record_pulse, recording_conditions
from .scenes import face, random_scene

CONDITIONS = ("reference", "omni", "bottom-firing", "offset", "near floor", "near ceiling", "tilted", "transducer",
              "limiter", "AAC", "48 kHz", "envelope")
"""The conditions :func:`echo_frame` draws: one property at its extreme each, all at once
(``"envelope"``), or none (``"reference"``: the reference device, upright, at the surface's
height)."""
TUNING = ("reference", "omni", "bottom-firing", "offset", "near floor", "near ceiling", "tilted", "transducer", "limiter")
"""The conditions tuning and training draw from (:data:`vrecho.planes.SURFACE_WEIGHTS`,
EchoCNN-E's device frames): all but AAC, 48 kHz and all at once, which the benchmarks hold out."""


HEADROOM = 0.9
"""The peak a device's input gain allows a frame (a microphone a centimetre from the
loudspeaker would clip otherwise)."""


@dataclass(frozen=True)
class Device:
    """A capture device of the operating envelope.

    Parameters
    ----------
    emitter_p : float
        The loudspeaker's pattern, p + (1 - p) cos(angle off its axis): 1 omnidirectional, 0.5
        a cardioid.
    axis : tuple of 3 float
        The loudspeaker's axis in the device's frame (forward, left, up), unit length.
    mic_m : tuple of 3 float
        The microphone from the loudspeaker in the device's frame (forward, left, up), metres.
    low_cut_hz : float
        The transducers' output falls off below this (second-order high-pass); 0 for none.
    resonance_hz, resonance_db : float
        A resonance peak (Q 3) of that gain; 0 dB for none.
    limiter : bool
        Automatic gain (the recording's peak raised to 2x full scale) into a soft limiter.
    aac : bool
        The recording goes through AAC at 128 kbps and back.
    fs : int
        The rate it records at, 44 100 or 48 000 Hz (the room is simulated at 44.1 kHz; a 48 kHz
        device's frame and probe are resampled to its rate before its gain, limiter and codec).
    """

    emitter_p: float = 0.7
    axis: tuple = (1.0, 0.0, 0.0)
    mic_m: tuple = (0.0, 0.0, MIC_ABOVE_EMITTER_M)
    low_cut_hz: float = 0.0
    resonance_hz: float = 0.0
    resonance_db: float = 0.0
    limiter: bool = False
    aac: bool = False
    fs: int = FS


@dataclass
class EchoFrame:
    """One frame of a device facing a discontinuity (:func:`echo_frame`).

    Parameters
    ----------
    audio : numpy.ndarray, shape (device.fs,), float32
        The frame, starting at the pulse's onset, at the device's rate.
    emitted : numpy.ndarray, shape (device.fs // 10,), float32
        The probe the user sent (as sent: the transducers' colouring is not in it), at the
        device's rate.
    is_open : bool
    material : str
        "open", "glass" or "mirror".
    depth_m : float
        Emitter to the discontinuity's plane along its normal.
    height_m : float
        The emitter above the floor.
    ceiling_m : float
        The emitter below the ceiling.
    paths_m : tuple of float
        The room's echoes that never touch the discontinuity: the path, loudspeaker to
        microphone, of each image source of order 1 to :data:`CLUTTER_ORDER` (pyroomacoustics'
        image-source model of this room with the discontinuity made an opening) that keeps at
        least :data:`CLUTTER_DAMPING` of its sound, sorted. One microphone cannot tell one of
        these from the discontinuity's own echo where they share its delay (a corner of the
        discontinuity's wall with the floor, the ceiling or a side wall echoes back almost as
        the wall would).
    condition : str
        Of :data:`CONDITIONS`.
    device : Device
    mic_toward_m : float
        How far the microphone sits from the loudspeaker toward the discontinuity's plane
        (along its normal): what a scan that knows the device's pose and geometry passes as
        ``mic_toward_surface_m``.
    """

    audio: np.ndarray
    emitted: np.ndarray
    is_open: bool
    material: str
    depth_m: float
    height_m: float
    ceiling_m: float
    paths_m: tuple
    condition: str
    device: Device
    mic_toward_m: float = 0.0


def random_device(rng: np.random.Generator, condition: str = "envelope") -> Device:
    """A device as ``condition`` draws it (see :data:`CONDITIONS`).

    Parameters
    ----------
    rng : numpy.random.Generator
    condition : str
        One of :data:`CONDITIONS` (default ``"envelope"``: every property drawn).

    Returns
    -------
    Device

    Raises
    ------
    VrechoError
        For an unknown condition.
    """
    if condition not in CONDITIONS:
        raise VrechoError(f"condition: expected one of {CONDITIONS}, got {condition!r}")
    every = condition == "envelope"
    kw = {}
    if every or condition == "omni":
        kw["emitter_p"] = 1.0 if condition == "omni" else rng.uniform(0.55, 1.0)  # 0.55: never a perfect null
    if every or condition == "bottom-firing":
        kw["axis"] = (0.0, 0.0, -1.0) if condition == "bottom-firing" or rng.random() < 0.4 else tuple(_unit(rng))
        if condition == "bottom-firing":
            kw["mic_m"] = (0.0, rng.uniform(-0.03, 0.03), -rng.uniform(0.01, 0.02))  # beside it, at the bottom edge
    if every or condition == "offset":
        r = rng.uniform(0.01, 0.15) if every else rng.uniform(0.10, 0.15)
        kw["mic_m"] = tuple(r * _unit(rng))
    if every or condition == "transducer":
        kw.update(low_cut_hz=rng.uniform(200, 400), resonance_hz=rng.uniform(800, 6000), resonance_db=rng.uniform(3, 10))
    if every or condition == "limiter":
        kw["limiter"] = condition == "limiter" or rng.random() < 0.5
    if every or condition == "AAC":
        kw["aac"] = condition == "AAC" or rng.random() < 0.5
    if condition == "48 kHz" or (every and rng.random() < 0.5):
        kw["fs"] = 48_000
    return Device(**kw)


def echo_frame(rng: np.random.Generator, condition: str = "envelope", *, cache=None, tries: int = 20) -> EchoFrame:
    """A device of ``condition`` facing a discontinuity of a random room, and the frame it records.

    The room is :func:`~vrecho.sim.scenes.random_scene`'s; the device stands 0.25 to 3 m from
    the discontinuity, its perpendicular's foot in it (the discontinuity is stretched in
    height, within PROTOCOL.md's 2.5 m, to reach the device where needed), 0.4 to 2.6 m above
    the floor (``"near floor"``: 0.4 to 0.6 m; ``"near ceiling"``: 0.2 to 0.4 m below it),
    turned up to 30 degrees off the normal and tilted up to 10 (``"tilted"``: 20 to 30)
    degrees. The probe is the user's own (:func:`~vrecho.signals.random_probe`). The room's
    noise is at PROTOCOL.md's levels below the direct sound of the reference device (the
    microphone 7 cm off the loudspeaker's side), whatever this device's microphone hears of
    its own loudspeaker.

    Parameters
    ----------
    rng : numpy.random.Generator
    condition : str
        One of :data:`CONDITIONS`.
    cache : path, bool or None
        The impulse-response cache (:func:`~vrecho.sim.acoustics.impulse_responses`).
    tries : int
        Draws of the room and pose before giving up (a device must fit in the room).

    Returns
    -------
    EchoFrame

    Raises
    ------
    VrechoError
        For an unknown condition, or no room and pose that fit after ``tries`` draws.
    """
    return echo_frames(rng, condition, 1, cache=cache, tries=tries)[0]


STEP_M = 0.4
"""The most a walk of :func:`echo_frames` moves toward or away from its surface between frames."""


def echo_frames(rng: np.random.Generator, condition: str = "envelope", n: int = 1, *, cache=None,
                tries: int = 20) -> list[EchoFrame]:
    """``n`` frames of one device walking about in front of one discontinuity.

    The first frame is :func:`echo_frame`'s (the same draws: ``n=1`` is it). Each next one is
    taken after a step of up to :data:`STEP_M` toward or away from the surface (its distance
    kept within 0.25 to 3 m), up to 10 cm along it and 5 cm up or down, the device turned and
    tilted afresh within the condition's range: the same room, device and probe, the room's
    noise drawn anew. So a surface's echo moves with the device while the floor's, the
    ceiling's and the other walls' move otherwise.

    Parameters
    ----------
    rng : numpy.random.Generator
    condition : str
        One of :data:`CONDITIONS`.
    n : int
        Frames (at least 1).
    cache : path, bool or None
        The impulse-response cache (:func:`~vrecho.sim.acoustics.impulse_responses`).
    tries : int
        Draws of the room and first pose before giving up (a device must fit in the room).

    Returns
    -------
    list of EchoFrame
        ``n`` of them, in the walk's order.

    Raises
    ------
    VrechoError
        For an unknown condition, ``n`` below 1, or no room and pose that fit after ``tries``
        draws.
    """
    if int(n) != n or n < 1:
        raise VrechoError(f"n: expected a whole number of frames, at least 1, got {n!r}")
    device = random_device(rng, condition)
    reference = condition == "reference"
    for _ in range(tries):
        scene = random_scene(rng, n_poses=1, n_sources=0)
        scene = dataclasses.replace(scene, emitter_p=device.emitter_p)
        index = int(rng.integers(len(scene.discontinuities)))
        d = scene.discontinuities[index]
        top = scene.room.height_m
        if condition == "near floor":
            z = rng.uniform(0.4, 0.6)
        elif condition == "near ceiling":
            z = top - rng.uniform(0.2, 0.4)
        elif reference:
            z = rng.uniform(max(0.4, d.center_z_m - d.height_m / 2 + 0.1), min(2.6, d.center_z_m + d.height_m / 2 - 0.1, top - 0.2))
        else:
            z = rng.uniform(0.4, min(2.6, top - 0.2))
        lo, hi = min(d.center_z_m - d.height_m / 2, z - 0.2), max(d.center_z_m + d.height_m / 2, z + 0.2)
        lo, hi = max(lo, 0.01), min(hi, top - 0.01)
        if hi - lo > 2.5:  # keep PROTOCOL.md's size: cut the side away from the device
            lo, hi = (lo, lo + 2.5) if z - lo < hi - z else (hi - 2.5, hi)
        d = dataclasses.replace(d, center_z_m=(lo + hi) / 2, height_m=hi - lo)
        discs = list(scene.discontinuities)
        discs[index] = d
        scene = dataclasses.replace(scene, discontinuities=discs)
        tilt = _tilt(rng, condition)
        half = max(d.width_m / 2 - 0.1, 0)
        dist, u = rng.uniform(0.25, 3.0), rng.uniform(-1, 1) * half
        frame, probe = _record(rng, scene, index, device, condition, None, cache, dist, u, z - d.center_z_m,
                               rng.uniform(-30, 30), tilt)
        if frame is None:
            continue  # the device would stand outside the room
        frames = [frame]
        while len(frames) < n:
            for _ in range(tries):
                step = float(np.clip(dist + rng.uniform(-STEP_M, STEP_M), 0.25, 3.0))
                along = float(np.clip(u + rng.uniform(-0.1, 0.1), -half, half))
                height = float(np.clip(z + rng.uniform(-0.05, 0.05), max(lo + 0.1, 0.3), min(hi - 0.1, top - 0.15)))
                tilt = _tilt(rng, condition)
                frame, _ = _record(rng, scene, index, device, condition, probe, cache, step, along,
                                   height - d.center_z_m, rng.uniform(-30, 30), tilt)
                if frame is not None:
                    frames.append(frame)
                    dist, u, z = step, along, height
                    break
            else:
                raise VrechoError(f"echo_frames: no pose of the walk fits after {tries} draws")
        return frames
    raise VrechoError(f"echo_frame: no room and pose fit after {tries} draws")


def _tilt(rng: np.random.Generator, condition: str) -> float:
    """A pose's tilt up or down in degrees: 20 to 30 for ``"tilted"``, up to 10 otherwise."""
    return rng.uniform(20, 30) * rng.choice([-1, 1]) if condition == "tilted" else rng.uniform(-10, 10)


def _record(rng, scene, index, device: Device, condition: str, probe, cache, dist: float, u: float, dz: float,
            yaw: float, tilt: float) -> tuple[EchoFrame | None, np.ndarray | None]:
    """The frame ``device`` records at a pose facing discontinuity ``index`` (:func:`~.scenes.face`'s
    arguments), and its probe at 44.1 kHz (drawn where ``probe`` is None); (None, None) where the
    device would stand outside the room."""
    try:
        pose = face(scene, index, dist, offset_u_m=u, offset_z_m=dz, yaw_deg=yaw, pitch_deg=tilt)
    except VrechoError:
        return None, None
    left = np.cross(pose.up, pose.forward)
    axes = np.stack([pose.forward, left, pose.up])  # device axes, one per row
    mic = pose.emitter + np.asarray(device.mic_m) @ axes
    if not scene.room.contains(np.stack([pose.emitter, mic])).all():
        return None, None
    d = scene.discontinuities[index]
    ir = impulse_responses(scene, pose.emitter, mic[None], facing=np.asarray(device.axis) @ axes, cache=cache)[0]
    probe = random_probe(rng) if probe is None else probe
    sent = _transducer(probe, device)
    # The room's noise is the room's: PROTOCOL.md's levels below the direct sound the
    # reference device would hear (7 cm off the loudspeaker's side), whichever the microphone
    # this device has; one a centimetre from its loudspeaker hears the room no louder.
    audio = record_pulse(ir, sent, direct_amplitude(MIC_ABOVE_EMITTER_M, device.emitter_p), rng,
                         *recording_conditions(rng))
    audio = _at_rate(audio, device.fs)
    audio = audio * min(1.0, HEADROOM / float(np.abs(audio).max()))  # the input gain a device sets: no clipping
    audio = _limit(audio) if device.limiter else audio
    audio = _aac(audio, device.fs) if device.aac else audio
    top = scene.room.height_m
    _, _, normal = scene.room.wall_frame(d.wall)  # out of the room: toward the plane
    return EchoFrame(audio.astype(np.float32), _at_rate(probe, device.fs), d.kind == "open", d.kind, scene.depth_m(pose),
                     float(pose.emitter[2]), float(top - pose.emitter[2]), clutter_paths(scene, index, pose.emitter, mic),
                     condition, device, float(np.dot(mic - pose.emitter, normal))), probe


CLUTTER_ORDER = 3
"""The highest reflection order :attr:`EchoFrame.paths_m` holds (the simulator's image sources
go as far: :class:`~vrecho.sim.acoustics.Simulation`)."""
CLUTTER_DAMPING = 0.3
"""The least share of its sound (mean over the bands) an echo keeps to count in
:attr:`EchoFrame.paths_m`."""


def clutter_paths(scene, index: int, emitter, mic) -> tuple:
    """The echoes of a scene that never touch discontinuity ``index`` (:attr:`EchoFrame.paths_m`).

    The image sources of order 1 to :data:`CLUTTER_ORDER` of the room with the discontinuity
    made an opening (absorbing all), as pyroomacoustics finds them (each reflection point within
    its patch), that keep at least :data:`CLUTTER_DAMPING` of their sound.

    Parameters
    ----------
    scene : vrecho.scene.Scene
    index : int
        The discontinuity.
    emitter, mic : array_like, shape (3,)
        The loudspeaker and the microphone, metres.

    Returns
    -------
    tuple of float
        The paths, loudspeaker to microphone, metres, sorted.
    """
    emitter, mic = np.asarray(emitter, np.float64), np.asarray(mic, np.float64)
    discs = list(scene.discontinuities)
    discs[index] = dataclasses.replace(discs[index], kind="open", absorption=(1.0,) * len(discs[index].absorption))
    room = build_room(dataclasses.replace(scene, discontinuities=discs), sim=Simulation(max_order=CLUTTER_ORDER, n_rays=0))
    room.add_source(emitter)
    room.add_microphone(mic)
    room.image_source_model()
    src = room.sources[0]
    keep = (src.orders > 0) & (src.damping.mean(axis=0) >= CLUTTER_DAMPING)
    return tuple(sorted(float(v) for v in np.linalg.norm(src.images[:, keep] - mic[:, None], axis=0)))


def _unit(rng: np.random.Generator) -> np.ndarray:
    v = rng.standard_normal(3)
    return v / np.linalg.norm(v)


def _transducer(sound: np.ndarray, device: Device) -> np.ndarray:
    """The sound as the loudspeaker puts it out (its high-pass and resonance)."""
    x = np.asarray(sound, np.float64)
    if device.low_cut_hz > 0:
        x = scipy.signal.sosfilt(scipy.signal.butter(2, device.low_cut_hz, "highpass", fs=FS, output="sos"), x)
    if device.resonance_db:
        b, a = _peaking(device.resonance_hz, device.resonance_db, 3.0)
        x = scipy.signal.lfilter(b, a, x)
    return x.astype(np.float32)


def _peaking(f0: float, gain_db: float, q: float) -> tuple[np.ndarray, np.ndarray]:
    """A peaking equaliser's coefficients (the Audio EQ Cookbook's)."""
    a_gain, w0 = 10 ** (gain_db / 40), 2 * np.pi * f0 / FS
    alpha = np.sin(w0) / (2 * q)
    b = np.array([1 + alpha * a_gain, -2 * np.cos(w0), 1 - alpha * a_gain])
    a = np.array([1 + alpha / a_gain, -2 * np.cos(w0), 1 - alpha / a_gain])
    return b / a[0], a / a[0]


def _limit(x: np.ndarray) -> np.ndarray:
    """Automatic gain (the peak to twice full scale) into a soft limiter (tanh)."""
    return np.tanh(2.0 * x / max(float(np.abs(x).max()), 1e-9)).astype(np.float32)


def _at_rate(x: np.ndarray, fs: int) -> np.ndarray:
    """``x`` (at :data:`~vrecho.signals.FS`) at ``fs``: as is, or resampled (polyphase), float32."""
    if fs == FS:
        return np.asarray(x, np.float32)
    g = int(np.gcd(fs, FS))
    return scipy.signal.resample_poly(np.asarray(x, np.float64), fs // g, FS // g).astype(np.float32)


def _aac(x: np.ndarray, fs: int = FS, bit_rate: int = 128_000) -> np.ndarray:
    """``x`` at ``fs`` through AAC at ``bit_rate`` and back (PyAV, in memory), aligned to its input."""
    import av  # heavy (PyAV): only where a device encodes

    buf = io.BytesIO()
    with av.open(buf, "w", format="adts") as out:
        stream = out.add_stream("aac", rate=fs, layout="mono")
        stream.bit_rate = bit_rate
        pad = np.concatenate([x, np.zeros(4096, np.float32)]).astype(np.float32)
        for i in range(0, len(pad), 1024):
            chunk = av.AudioFrame.from_ndarray(pad[None, i:i + 1024], format="flt", layout="mono")
            chunk.sample_rate = fs
            for packet in stream.encode(chunk):
                out.mux(packet)
        for packet in stream.encode(None):
            out.mux(packet)
    buf.seek(0)
    with av.open(buf, "r") as src:
        y = np.concatenate([f.to_ndarray().reshape(-1) for f in src.decode(audio=0)]).astype(np.float32)
    lag = int(np.argmax(scipy.signal.correlate(y[:8192], x[:4096], mode="valid")))  # the codec's delay
    y = y[lag:lag + len(x)]
    return np.pad(y, (0, len(x) - len(y)))
