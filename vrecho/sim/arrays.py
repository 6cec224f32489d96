"""Sound sources heard across PROTOCOL.md's operating envelope: any array, few poses, any room.

The project's own benchmark hears shoebox rooms with the headset's 16 cm array at 8 poses of
1.5 s. A user brings another array (2 to 8 microphones of any geometry, flat or not, aperture 5
to 25 cm), 2 to 10 poses along a walk with the head turning, nodding and tilting, captures of 1
to 4 s at 16, 44.1 or 48 kHz, polygon rooms with furniture, RT60 0.2 to 1.0 s, and 1 to 4
sources (speech, music, hum, a fan, a television, a talker who speaks now and then) 0 to 20 dB
apart. :func:`envelope_walk` draws such a recording; each of :data:`CONDITIONS` takes one
property to its extreme and leaves the rest as the reference benchmark has them, so that a
benchmark reports each on its own row (``"envelope"``: all at once; ``"user"``: the issue's
flat 9 x 5 cm headset, 3 to 5 poses of 2 s, the head turning, polygon rooms, two or three of
speech, music and hum).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.signal

from localization.capture import FS

from ..device import MIC_ARRAYS, DevicePose, MicArray
from ..errors import VrechoError
from ..geometry import signed_area
from ..materials import Material
from ..scene import Room, Scene
from ..signals import colored_noise
from .ambient import AMBIENT_KINDS, PROTOCOL_SOUNDS, AmbientSource, Shoebox, SimulatedCapture, random_walk, simulate_walk_capture
from .scenes import CEILING_MATERIALS, FLOOR_MATERIALS, WALL_MATERIALS, random_furniture
from .sounds import ambient_sound, radiated

CONDITIONS = ("reference", "flat 9x5", "any array", "two mics", "eight mics", "few poses", "head turning",
              "capture length", "44.1/48 kHz", "polygon room", "RT60 to 1 s", "one source", "four sources",
              "levels apart", "music", "hum", "tv and fan", "now and then", "user", "envelope")
"""What :func:`envelope_walk` draws: ``"reference"`` is the project's benchmark (headset4, 8
poses of 1.5 s along an arc, yaw only, shoebox RT60 0.2 to 0.8 s, 2 or 3 sources at one level,
16 kHz); every other condition changes one thing (``"user"`` and ``"envelope"`` several)."""

FLAT_9X5 = MicArray("flat9x5", ((0.0, 0.045, 0.025), (0.0, -0.045, 0.025), (0.0, -0.045, -0.025), (0.0, 0.045, -0.025)))
"""The issue's other headset: four microphones on a flat 9 x 5 cm rectangle facing forward."""

TRAINING = "training"
"""The condition the mask network is trained on (:func:`envelope_walk`; not a benchmark row):
random arrays of 2 to 7 microphones (never 8, never :data:`FLAT_9X5`), shoebox rooms of RT60
0.2 to 0.8 s, 4 poses of 1.5 s with the head turning, nodding and tilting, 2 to 4 sources of
speech, music, hum and PROTOCOL.md's sounds 0 to 20 dB apart, 16 kHz. What it leaves out (8
microphones, the flat 9 x 5 cm headset, polygon rooms with furniture, RT60 above 0.8 s, 44.1
and 48 kHz, televisions, fans and a talker who pauses) is the benchmark's held-out part."""

KINDS = ("speech", "music", "hum", "tv", "fan", "now_and_then")
"""The sources a walk of the envelope may hold (besides :data:`~vrecho.sim.ambient.AMBIENT_KINDS`'
PROTOCOL.md sounds)."""


@dataclass
class EnvelopeWalk:
    """A recording of the envelope (:func:`envelope_walk`).

    Parameters
    ----------
    room : Scene or Shoebox
        The room.
    sim : SimulatedCapture
        The captures and each source's image at every microphone.
    array : MicArray
        The microphones, in the device frame.
    condition : str
        One of :data:`CONDITIONS`.
    bounds : tuple of numpy.ndarray
        The room's box (lowest corner, highest corner) in metres: what a user gives
        :func:`localization.locate`.
    """

    room: Scene | Shoebox
    sim: SimulatedCapture
    array: MicArray
    condition: str
    bounds: tuple


def random_array(rng: np.random.Generator, n_mics: int | None = None, *, flat: bool | None = None) -> MicArray:
    """Microphones of any geometry: 2 to 8, aperture 5 to 25 cm, flat or not.

    Parameters
    ----------
    rng : numpy.random.Generator
    n_mics : int, optional
        How many (drawn from 2 to 8 when None).
    flat : bool, optional
        All in the device's forward-facing plane (drawn, half the time, when None).

    Returns
    -------
    MicArray
        Channel 0 first; its largest pairwise distance (the aperture) 5 to 25 cm, no two
        microphones closer than 1 cm.
    """
    n = int(rng.integers(2, 9)) if n_mics is None else int(n_mics)
    flat = bool(rng.random() < 0.5) if flat is None else flat
    aperture = rng.uniform(0.05, 0.25)
    while True:
        p = rng.uniform(-1, 1, (n, 3)) * [0.3 * (not flat), 1.0, 0.6]
        if n == 2:
            p[1] = -p[0]
        span = np.max(np.linalg.norm(p[:, None] - p[None], axis=-1))
        if span < 1e-6:
            continue
        p *= aperture / span
        i, j = np.triu_indices(n, 1)
        if np.min(np.linalg.norm(p[i] - p[j], axis=1)) >= 0.01:
            return MicArray(f"random{n}{'flat' if flat else ''}", tuple(map(tuple, np.round(p + [0, 0, 0.07], 4))))


def head_pose(position: np.ndarray, yaw: float, pitch: float, roll: float) -> DevicePose:
    """A device pose from the head's yaw, pitch and roll.

    Parameters
    ----------
    position : numpy.ndarray [shape=(3,)]
        The emitter's world position in metres.
    yaw : float
        Where it looks, radians from the world's +x toward +y.
    pitch : float
        How far it nods up (radians).
    roll : float
        How far it tilts about where it looks (radians).

    Returns
    -------
    DevicePose
    """
    f = np.array([np.cos(pitch) * np.cos(yaw), np.cos(pitch) * np.sin(yaw), np.sin(pitch)])
    left = np.array([-np.sin(yaw), np.cos(yaw), 0.0])
    up = np.cross(f, left)
    up = np.cos(roll) * up + np.sin(roll) * left
    return DevicePose(position, f, up / np.linalg.norm(up))


RT60_BANDS = (1, 2, 3, 4, 5, 6)
"""The octave bands of :data:`~vrecho.materials.BANDS_HZ` (250 Hz to 8 kHz, where the sources
and the direction finding have their power) whose reverberation :func:`eyring_rt60` reads."""


def eyring_rt60(room: Room) -> float:
    """A room's reverberation time by Eyring's formula, 0.161 V / (-S ln(1 - a)), a the
    surfaces' absorption weighed by their areas: the longest over the octave bands of
    :data:`RT60_BANDS` (hard walls ring longest high, carpets and plasterboard low).

    Parameters
    ----------
    room : Room

    Returns
    -------
    float
        Seconds; furniture (more absorption) only shortens it. What the simulator makes of such
        a room (:func:`~vrecho.sim.acoustics.impulse_responses`) decays some 25 % faster to 50 %
        slower: 11 rooms of :func:`polygon_room`, 0.59 to 0.73 s by this formula, gave a
        broadband T20 of 0.51 to 1.11 s (2026-12-06), as a shoebox of
        :func:`~vrecho.sim.ambient.random_walk` runs longer than the Sabine time it was made for.
    """
    area = signed_area(room.footprint)
    surfaces = [(length * room.height_m, m) for length, m in zip(room.wall_lengths, room.walls)]
    surfaces += [(area, room.floor), (area, room.ceiling)]
    total = sum(s for s, _ in surfaces)
    a = np.array([sum(s * m.absorption[b] for s, m in surfaces) / total for b in RT60_BANDS])
    return float(np.max(0.161 * area * room.height_m / (-total * np.log1p(-np.minimum(a, 1 - 1e-9)))))


def polygon_room(rng: np.random.Generator, rt60_s: tuple[float, float] = (0.2, 0.8), tries: int = 200) -> Room:
    """An L, a pentagon or a hexagon of 3 to 7 m with walls, floor and ceiling of the database,
    their materials drawn again until the room's reverberation time (:func:`eyring_rt60`) lies
    within ``rt60_s``: drawn freely, the database's materials give 1.1 s in the median and up to
    2.8 s (2 000 draws; the benchmark's polygon rooms simulated at 0.5 to 2.3 s, 22 of 39 over
    1 s, before 2026-12-06), beyond PROTOCOL.md's envelope (0.2 to 1.0 s).

    Parameters
    ----------
    rng : numpy.random.Generator
    rt60_s : tuple of two float
        The reverberation times allowed, seconds (default 0.2 to 0.8, the reference benchmark's).
    tries : int
        Draws of the materials before giving up.

    Returns
    -------
    Room

    Raises
    ------
    VrechoError
        Where no draw fits ``rt60_s``.
    """
    lx, ly = rng.uniform(3.5, 7.0), rng.uniform(3.0, 6.0)
    shape = rng.integers(3)
    if shape == 0:  # an L
        cx, cy = rng.uniform(0.3, 0.5) * lx, rng.uniform(0.3, 0.5) * ly
        fp = [(0, 0), (lx, 0), (lx, ly - cy), (lx - cx, ly - cy), (lx - cx, ly), (0, ly)]
    elif shape == 1:  # a corner cut
        cx, cy = rng.uniform(0.2, 0.4) * lx, rng.uniform(0.2, 0.4) * ly
        fp = [(0, 0), (lx, 0), (lx, ly - cy), (lx - cx, ly), (0, ly)]
    else:  # two corners cut
        c = rng.uniform(0.15, 0.3, 4) * [lx, ly, lx, ly]
        fp = [(c[0], 0), (lx, 0), (lx, ly - c[3]), (lx - c[2], ly), (0, ly), (0, c[1])]
    fp, height = np.round(np.array(fp, float), 3), round(float(rng.uniform(2.4, 3.0)), 3)
    for _ in range(tries):
        scat = float(rng.uniform(0.05, 0.3))
        walls = [Material.from_database(str(rng.choice(WALL_MATERIALS)), scattering=scat) for _ in fp]
        room = Room(fp, height, walls,
                    Material.from_database(str(rng.choice(FLOOR_MATERIALS)), scattering=scat),
                    Material.from_database(str(rng.choice(CEILING_MATERIALS)), scattering=scat))
        if rt60_s[0] <= eyring_rt60(room) <= rt60_s[1]:
            return room
    raise VrechoError(f"no materials give the room a reverberation time of {rt60_s[0]} to {rt60_s[1]} s "
                      f"after {tries} draws")


def source_sound(kind: str, duration_s: float, fs: int, rng: np.random.Generator) -> np.ndarray:
    """What a source of ``kind`` plays.

    Parameters
    ----------
    kind : str
        One of :data:`KINDS` (``"tv"``: a voice over music through a television's band;
        ``"fan"``: air noise with its blades' tone; ``"now_and_then"``: a talker who pauses) or
        of :func:`~vrecho.sim.sounds.ambient_sound`'s.
    duration_s : float
        Length in seconds.
    fs : int
        Sample rate in Hz.
    rng : numpy.random.Generator

    Returns
    -------
    numpy.ndarray [shape=(round(duration_s * fs),)], float32
    """
    if kind == "tv":  # a voice over music, band-limited as a television's speaker
        x = ambient_sound("speech", duration_s, fs, rng) + rng.uniform(0.2, 0.6) * ambient_sound("music", duration_s, fs, rng)
        sos = scipy.signal.butter(2, [120 / (fs / 2), min(0.95, 7000 / (fs / 2))], "band", output="sos")
        return scipy.signal.sosfilt(sos, x).astype(np.float32)
    if kind == "fan":
        n = int(round(duration_s * fs))
        t = np.arange(n) / fs
        blade = rng.uniform(20, 60)  # the blades' pass: a low tone and its harmonics over the air's noise
        x = colored_noise(n, rng.uniform(0.5, 1.2), rng) * (1 + 0.1 * np.sin(2 * np.pi * blade * t))
        x += sum(0.3 / k * np.sin(2 * np.pi * blade * k * t + rng.uniform(0, 6.3)) for k in range(1, 6)) * np.std(x)
        return radiated(x, fs)
    if kind == "now_and_then":  # a talker: bursts of 0.4 to 1.2 s, silences of 0.5 to 2.5 s
        x = ambient_sound("speech", duration_s, fs, rng)
        gate, t = np.zeros(len(x), np.float32), int(rng.uniform(0, 0.8) * fs)
        while t < len(x):
            on = int(rng.uniform(0.4, 1.2) * fs)
            gate[t:t + on] = 1
            t += on + int(rng.uniform(0.5, 2.5) * fs)
        return x * gate
    return ambient_sound(kind, duration_s, fs, rng)


def envelope_walk(rng: np.random.Generator, condition: str = "envelope", *, cache=None, tries: int = 200) -> EnvelopeWalk:
    """A walk of ``condition`` (:data:`CONDITIONS`) through a room with sound sources, recorded.

    Shoebox rooms take :func:`~vrecho.sim.ambient.random_walk`'s room and arc (the head turned
    up to 46 degrees from the path); where the condition turns the head (``"head turning"``: up
    to 60 degrees either way, nodded 30 and tilted 25; ``"user"``, ``"envelope"`` and
    :data:`TRAINING`: 45, 20 and 20) each pose is turned so. Polygon rooms (an L, or one or two
    corners cut, with furniture four times in five; reverberation times by Eyring's formula of
    0.2 to 0.8 s as the reference's, 0.2 to 1.0 s for ``"envelope"``) are walked along a random heading, poses
    0.3 to 0.8 m apart, 1.2 to 1.8 m high, 0.3 m from the walls. The sources stand at least 1 m
    apart, 0.8 m from every pose and 0.3 m inside the room, and play continuously (``"now and
    then"``: a talker with pauses) at one level or, where ``"levels apart"``, 0 to 20 dB apart.
    Pink noise 30 dB under the sources at the reference microphone.

    Parameters
    ----------
    rng : numpy.random.Generator
    condition : str
        One of :data:`CONDITIONS`.
    cache : path, bool or None
        The impulse-response cache (polygon rooms: :func:`~vrecho.sim.acoustics.impulse_responses`).
    tries : int
        Draws of the room, walk and sources before giving up (a polygon room's walk of 8 poses
        fits one draw in 11: 50 draws left one seed in 100 without a walk).

    Returns
    -------
    EnvelopeWalk

    Raises
    ------
    VrechoError
        For an unknown condition, or nothing that fits after ``tries`` draws.
    """
    if condition not in CONDITIONS + (TRAINING,):
        raise VrechoError(f"condition: expected one of {CONDITIONS}, got {condition!r}")
    every, user, train = condition == "envelope", condition == "user", condition == TRAINING
    if condition == "flat 9x5" or user:
        array = FLAT_9X5
    elif condition == "two mics":
        array = random_array(rng, 2)
    elif condition == "eight mics":
        array = random_array(rng, 8)
    elif condition == "any array" or every:
        array = random_array(rng)
    elif train:
        array = random_array(rng, int(rng.integers(2, 8)))
    else:
        array = MIC_ARRAYS["headset4"]
    n_poses = int(rng.integers(3, 6)) if condition == "few poses" or user else int(rng.integers(2, 11)) if every else \
        4 if train else 8
    segment = 2.0 if user else round(float(rng.uniform(1.0, 4.0)), 2) if condition == "capture length" or every else 1.5
    fs = int(rng.choice([44_100, 48_000])) if condition == "44.1/48 kHz" else int(rng.choice([16_000, 44_100, 48_000])) if every else FS
    turn = (np.radians(60), np.radians(30), np.radians(25)) if condition == "head turning" else \
        (np.radians(45), np.radians(20), np.radians(20)) if user or every or train else (0.8, 0.1, 0.0)
    n_src = 1 if condition == "one source" else 4 if condition == "four sources" else \
        int(rng.integers(1, 5)) if every else int(rng.integers(2, 5)) if train else int(rng.integers(2, 4))
    if condition in ("music", "hum"):
        kinds = (condition,)
    elif condition == "tv and fan":
        kinds = ("tv", "fan")
    elif condition == "now and then":
        kinds = ("now_and_then", "speech", "music", "hum")
    elif user:
        kinds = ("speech", "music", "hum")
    elif every:
        kinds = KINDS + ("protocol",)
    else:
        kinds = AMBIENT_KINDS
    if condition == "reference":
        room, sources, poses = random_walk(rng, n_src, float(rng.uniform(0.2, 0.8)), n_poses=n_poses, segment_s=segment)
        sim = simulate_walk_capture(room, sources, poses, rng, array=array, fs=fs, segment_s=segment)
        return EnvelopeWalk(room, sim, array, condition, (np.zeros(3), np.asarray(room.dims)))
    polygon = condition == "polygon room" or user or (every and rng.random() < 0.5)
    for _ in range(tries):
        if polygon:
            room = Scene("envelope", polygon_room(rng, (0.2, 1.0) if every else (0.2, 0.8)))
            lo, hi = room.room.box
            inside = room.room.contains
            poses = _walk(rng, inside, lo, hi, n_poses, turn, array)
        else:  # random_walk's room and arc, the head turned further where the condition turns it
            rt60 = rng.uniform(0.8, 1.0) if condition == "RT60 to 1 s" else rng.uniform(0.2, 1.0) if every else rng.uniform(0.2, 0.8)
            room, _, poses = random_walk(rng, 0, float(rt60), n_poses=n_poses, segment_s=segment)
            lo, hi, inside = np.zeros(3), np.asarray(room.dims), room.contains
            if turn[1] > 0.1:
                poses = [_turned(p, rng, turn) for p in poses]
            if not all(inside(p.microphones(array), margin_m=0.05).all() for p in poses):
                continue
        if poses is None:
            continue
        if polygon and rng.random() < 0.8:  # furniture, clear of the walk
            room.furniture = random_furniture(room.room, rng, int(rng.integers(1, 5)),
                                              keep_clear=[(p.emitter[:2], 0.5) for p in poses])
        sources = _sources(rng, inside, lo, hi, poses, n_src, kinds, n_poses * segment + 0.01, fs,
                           condition == "levels apart" or every or train, getattr(room, "furniture", []))
        if sources is None:
            continue
        sim = simulate_walk_capture(room, sources, poses, rng, array=array, fs=fs, segment_s=segment, cache=cache)
        return EnvelopeWalk(room, sim, array, condition, (lo, hi))
    raise VrechoError(f"envelope_walk: no room, walk and sources fit after {tries} draws")


def _turned(pose: DevicePose, rng, turn) -> DevicePose:
    """``pose`` turned by up to ``turn`` (yaw, pitch, roll limits in radians) further."""
    yaw = np.arctan2(pose.forward[1], pose.forward[0]) + rng.uniform(-0.5, 0.5) * (turn[0] - 0.8)
    return head_pose(pose.emitter, yaw, rng.uniform(-turn[1], turn[1]), rng.uniform(-turn[2], turn[2]))


def _walk(rng, inside, lo, hi, n_poses: int, turn, array: MicArray) -> list[DevicePose] | None:
    """Poses along a walk (see :func:`envelope_walk`), or None where one leaves the room (its
    microphones 0.3 m inside)."""
    p = np.r_[rng.uniform(lo[:2] + 0.6, hi[:2] - 0.6), rng.uniform(1.2, 1.8)]
    heading = rng.uniform(0, 2 * np.pi)
    poses = []
    for _ in range(n_poses):
        pose = head_pose(p, heading + rng.uniform(-turn[0], turn[0]), rng.uniform(-turn[1], turn[1]), rng.uniform(-turn[2], turn[2]))
        if not inside(np.vstack([pose.microphones(array), p]), margin_m=0.3).all():
            return None
        poses.append(pose)
        heading += rng.uniform(-0.6, 0.6)
        p = p + rng.uniform(0.3, 0.8) * np.r_[np.cos(heading), np.sin(heading), 0.0]
        p[2] = np.clip(p[2] + rng.uniform(-0.05, 0.05), 1.2, 1.8)
    return poses


def _sources(rng, inside, lo, hi, poses, n: int, kinds, duration_s: float, fs: int, apart: bool, furniture
             ) -> list[AmbientSource] | None:
    """``n`` sources (see :func:`envelope_walk`), or None where they do not fit."""
    out = []
    for _ in range(200 * n):
        if len(out) == n:
            break
        q = np.r_[rng.uniform(lo[:2] + 0.3, hi[:2] - 0.3), rng.uniform(0.3, 2.0)]
        if not inside(q[None]).all() or any(f.contains(q[None], margin_m=0.1).any() for f in furniture):
            continue
        if min(np.linalg.norm(q - p.emitter) for p in poses) < 0.8 or any(np.linalg.norm(q - s.position) < 1.0 for s in out):
            continue
        kind = str(kinds[int(rng.integers(len(kinds)))])
        sound = PROTOCOL_SOUNDS[int(rng.integers(len(PROTOCOL_SOUNDS)))] if kind == "protocol" else kind
        gain = 10 ** (-rng.uniform(0, 20) / 20) if apart and out else 1.0
        out.append(AmbientSource(q, source_sound(sound, duration_s, fs, rng) * gain, sound))
    return out if len(out) == n else None
