"""Scenes: rooms, surfaces, discontinuities, the capture device and sound sources.

A :class:`Scene` is plain data that travels: JSON in (:func:`load_scene`, validated, one error
naming the bad field) and out (:meth:`Scene.save`). World frame: right-handed, Z up, metres.
A room is a counter-clockwise polygon footprint extruded to a height; wall ``i`` runs from corner
``i`` to corner ``i + 1``. A discontinuity is a rectangle on one wall, placed by the distance of
its centre along the wall (``center_u_m``) and its centre height (``center_z_m``).

:func:`builtin_scene` is the demo's living room; :mod:`vrecho.sim.scenes` draws random scenes as
PROTOCOL.md allows.
"""

from __future__ import annotations

import dataclasses
import json
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path

import numpy as np
from scipy.interpolate import CubicSpline

from .errors import VrechoError
from .geometry import distance_to_polygon, point_in_polygon, segments_cross, signed_area
from .io import atomic_write_text
from .signals import SOUNDS

BANDS_HZ = (125, 250, 500, 1000, 2000, 4000, 8000)
"""Octave-band centres (Hz) of every absorption coefficient in a scene."""
KINDS = ("open", "glass", "mirror")
MIC_ABOVE_EMITTER_M = 0.07
DEPTH_RANGE_M = (0.25, 3.0)
MAX_INCIDENCE_DEG = 15.0

HEAVY_GLASS = (0.18, 0.06, 0.04, 0.03, 0.02, 0.02, 0.02)
WINDOW_GLASS = (0.35, 0.25, 0.18, 0.12, 0.07, 0.04, 0.04)
MIRROR = (0.03, 0.03, 0.03, 0.03, 0.02, 0.02, 0.02)


# ----------------------------------------------------------------------------- validation helpers

def _field(d: dict, key: str, where: str, default=dataclasses.MISSING):
    if not isinstance(d, dict):
        raise VrechoError(f"{where}: expected an object, got {type(d).__name__}")
    if key not in d:
        if default is dataclasses.MISSING:
            raise VrechoError(f"{where}.{key}: missing")
        return default
    return d[key]


def check_number(x, where: str, *, lo: float | None = None, hi: float | None = None) -> float:
    if isinstance(x, bool) or not isinstance(x, (int, float, np.integer, np.floating)) or not np.isfinite(x):
        raise VrechoError(f"{where}: expected a finite number, got {x!r}")
    if lo is not None and x < lo:
        raise VrechoError(f"{where}: must be at least {lo}, got {x}")
    if hi is not None and x > hi:
        raise VrechoError(f"{where}: must be at most {hi}, got {x}")
    return float(x)


def _vector(x, where: str, n: int = 3) -> np.ndarray:
    try:
        v = np.asarray(x, dtype=float)
    except (TypeError, ValueError):
        raise VrechoError(f"{where}: expected {n} numbers, got {x!r}") from None
    if v.shape != (n,) or not np.all(np.isfinite(v)):
        raise VrechoError(f"{where}: expected {n} finite numbers, got {x!r}")
    return v


def _unit(x, where: str) -> np.ndarray:
    v = _vector(x, where)
    norm = np.linalg.norm(v)
    if norm < 1e-9:
        raise VrechoError(f"{where}: must not be the zero vector")
    return v if abs(norm - 1.0) < 1e-12 else v / norm  # idempotent, so JSON round trips are exact


# ----------------------------------------------------------------------------- materials

@dataclass(frozen=True)
class Material:
    """Acoustic material: energy absorption per octave band of :data:`BANDS_HZ`, and scattering."""

    name: str
    absorption: tuple[float, ...]
    scattering: float = 0.1

    def __post_init__(self):
        a = tuple(float(v) for v in self.absorption)
        if len(a) != len(BANDS_HZ) or not all(np.isfinite(v) and 0.0 <= v <= 1.0 for v in a):
            raise VrechoError(f"material {self.name!r}: absorption needs {len(BANDS_HZ)} values in [0, 1], got {self.absorption!r}")
        if not 0.0 <= self.scattering <= 1.0:
            raise VrechoError(f"material {self.name!r}: scattering must be in [0, 1], got {self.scattering}")
        object.__setattr__(self, "absorption", a)

    @classmethod
    def from_database(cls, name: str, *, scattering: float = 0.1) -> "Material":
        """A material of pyroomacoustics' database, its bands padded to the seven of the protocol."""
        import pyroomacoustics as pra  # heavy (1.4 s): its database only where a material is named

        for entries in pra.materials_data["absorption"].values():
            if name in entries:
                coeffs = list(entries[name]["coeffs"])
                coeffs += [coeffs[-1]] * (len(BANDS_HZ) - len(coeffs))  # 6-band entries end at 4 kHz
                return cls(name, tuple(coeffs), scattering)
        raise VrechoError(f"material: {name!r} is not in pyroomacoustics' materials database")

    def to_dict(self) -> dict:
        return {"name": self.name, "absorption": list(self.absorption), "scattering": self.scattering}

    @classmethod
    def from_dict(cls, d, where: str) -> "Material":
        if isinstance(d, str):
            return cls.from_database(d)
        name = str(_field(d, "name", where, "custom"))
        absorption = _field(d, "absorption", where)
        if not isinstance(absorption, (list, tuple)) or len(absorption) != len(BANDS_HZ):
            raise VrechoError(f"{where}.absorption: expected {len(BANDS_HZ)} values (bands {BANDS_HZ} Hz), got {absorption!r}")
        vals = tuple(check_number(v, f"{where}.absorption[{i}]", lo=0.0, hi=1.0) for i, v in enumerate(absorption))
        return cls(name, vals, check_number(_field(d, "scattering", where, 0.1), f"{where}.scattering", lo=0.0, hi=1.0))


@dataclass(frozen=True)
class Patch:
    """A planar rectangle or polygon of the room's boundary, wound so its normal points out."""

    corners: np.ndarray  # (K, 3)
    kind: str  # wall | floor | ceiling | open | glass | mirror
    material: Material
    surface: int  # wall index; -1 floor, -2 ceiling
    discontinuity: int | None = None

    @property
    def normal(self) -> np.ndarray:
        c = self.corners
        n = np.cross(c[1] - c[0], c[-1] - c[0])
        return n / np.linalg.norm(n)


@dataclass
class Room:
    """A polygon footprint (counter-clockwise, metres) extruded from z = 0 to ``height_m``."""

    footprint: np.ndarray
    height_m: float
    walls: list[Material]
    floor: Material
    ceiling: Material

    def __post_init__(self):
        self.footprint = np.asarray(self.footprint, dtype=float)
        fp = self.footprint
        if fp.ndim != 2 or fp.shape[1] != 2 or fp.shape[0] < 3 or not np.all(np.isfinite(fp)):
            raise VrechoError(f"room.footprint: expected at least 3 finite [x, y] corners, got shape {fp.shape}")
        if not self.height_m > 0:
            raise VrechoError(f"room.height_m: must be positive, got {self.height_m}")
        if len(self.walls) != len(fp):
            raise VrechoError(f"room.walls: expected one material per wall ({len(fp)}), got {len(self.walls)}")
        if np.min(self.wall_lengths) < 0.05:
            raise VrechoError(f"room.footprint: wall {int(np.argmin(self.wall_lengths))} is shorter than 5 cm")
        if signed_area(fp) <= 0:
            raise VrechoError("room.footprint: corners must run counter-clockwise seen from above (+z)")
        n = len(fp)
        for i in range(n):
            for j in range(i + 2, n):
                if (j + 1) % n == i:
                    continue
                if segments_cross(fp[i], fp[(i + 1) % n], fp[j], fp[(j + 1) % n]):
                    raise VrechoError(f"room.footprint: walls {i} and {j} cross; the footprint must be a simple polygon")

    @property
    def wall_lengths(self) -> np.ndarray:
        return np.linalg.norm(np.roll(self.footprint, -1, axis=0) - self.footprint, axis=1)

    @property
    def box(self) -> tuple[np.ndarray, np.ndarray]:
        """The room's bounding box: its low and high corners (3,), floor to ceiling."""
        return (np.r_[self.footprint.min(axis=0), 0.0], np.r_[self.footprint.max(axis=0), self.height_m])

    def wall_frame(self, i: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Origin (corner ``i`` at floor level), unit direction along the wall, outward normal."""
        p0, p1 = self.footprint[i], self.footprint[(i + 1) % len(self.footprint)]
        u = (p1 - p0) / np.linalg.norm(p1 - p0)
        return np.array([p0[0], p0[1], 0.0]), np.array([u[0], u[1], 0.0]), np.array([u[1], -u[0], 0.0])

    def contains(self, points: np.ndarray, *, margin_m: float = 0.0) -> np.ndarray:
        """Whether 3-D points (N, 3) lie inside the room, at least ``margin_m`` from every surface."""
        p = np.atleast_2d(points)
        inside = point_in_polygon(p[:, :2], self.footprint) & (p[:, 2] > margin_m) & (p[:, 2] < self.height_m - margin_m)
        if margin_m > 0:
            inside &= distance_to_polygon(p[:, :2], self.footprint) >= margin_m
        return inside

    def to_dict(self) -> dict:
        return {"footprint": self.footprint.tolist(), "height_m": self.height_m,
                "walls": [m.to_dict() for m in self.walls], "floor": self.floor.to_dict(),
                "ceiling": self.ceiling.to_dict()}

    @classmethod
    def from_dict(cls, d, where: str = "room") -> "Room":
        footprint = _field(d, "footprint", where)
        try:
            fp = np.asarray(footprint, dtype=float)
        except (TypeError, ValueError):
            raise VrechoError(f"{where}.footprint: expected a list of [x, y] corners") from None
        height = check_number(_field(d, "height_m", where), f"{where}.height_m")
        walls = _field(d, "walls", where)
        if isinstance(walls, (str, dict)):
            walls = [walls] * len(fp)
        if not isinstance(walls, list):
            raise VrechoError(f"{where}.walls: expected a material or a list of them")
        return cls(fp, height, [Material.from_dict(w, f"{where}.walls[{i}]") for i, w in enumerate(walls)],
                   Material.from_dict(_field(d, "floor", where), f"{where}.floor"),
                   Material.from_dict(_field(d, "ceiling", where), f"{where}.ceiling"))


@dataclass
class Discontinuity:
    """A rectangle on a wall that a camera leaves as a hole or fills wrongly.

    ``kind`` is ``open`` (an opening: absorbs everything), ``glass`` or ``mirror``.
    ``depth_sensor_sees_through``: for glass, whether a depth camera returns what lies beyond
    (True) or nothing (False).
    """

    wall: int
    center_u_m: float
    center_z_m: float
    width_m: float
    height_m: float
    kind: str
    absorption: tuple[float, ...] = (1.0,) * 7
    scattering: float = 0.02
    depth_sensor_sees_through: bool = True

    @property
    def is_open(self) -> bool:
        return self.kind == "open"

    @property
    def material(self) -> str | None:
        """``glass`` or ``mirror`` for a closed surface, None for an opening."""
        return None if self.is_open else self.kind

    @property
    def acoustic_material(self) -> Material:
        return Material(self.kind, self.absorption, self.scattering)

    def bounds(self) -> tuple[float, float, float, float]:
        """(u0, u1, z0, z1) of the rectangle in its wall's coordinates."""
        return (self.center_u_m - self.width_m / 2, self.center_u_m + self.width_m / 2,
                self.center_z_m - self.height_m / 2, self.center_z_m + self.height_m / 2)

    def to_dict(self) -> dict:
        return {"wall": self.wall, "center_u_m": self.center_u_m, "center_z_m": self.center_z_m,
                "width_m": self.width_m, "height_m": self.height_m, "kind": self.kind,
                "absorption": list(self.absorption), "scattering": self.scattering,
                "depth_sensor_sees_through": self.depth_sensor_sees_through}

    @classmethod
    def from_dict(cls, d, where: str) -> "Discontinuity":
        kind = _field(d, "kind", where)
        if kind not in KINDS:
            raise VrechoError(f"{where}.kind: expected one of {KINDS}, got {kind!r}")
        wall = _field(d, "wall", where)
        if isinstance(wall, bool) or not isinstance(wall, int):
            raise VrechoError(f"{where}.wall: expected a wall index, got {wall!r}")
        default_abs = {"open": (1.0,) * 7, "glass": WINDOW_GLASS, "mirror": MIRROR}[kind]
        absorption = _field(d, "absorption", where, list(default_abs))
        if not isinstance(absorption, (list, tuple)) or len(absorption) != len(BANDS_HZ):
            raise VrechoError(f"{where}.absorption: expected {len(BANDS_HZ)} values, got {absorption!r}")
        return cls(wall,
                   check_number(_field(d, "center_u_m", where), f"{where}.center_u_m"),
                   check_number(_field(d, "center_z_m", where), f"{where}.center_z_m"),
                   check_number(_field(d, "width_m", where), f"{where}.width_m", lo=0.01),
                   check_number(_field(d, "height_m", where), f"{where}.height_m", lo=0.01),
                   kind,
                   tuple(check_number(a, f"{where}.absorption[{i}]", lo=0.0, hi=1.0) for i, a in enumerate(absorption)),
                   check_number(_field(d, "scattering", where, 0.02), f"{where}.scattering", lo=0.0, hi=1.0),
                   bool(_field(d, "depth_sensor_sees_through", where, True)))


@dataclass(frozen=True)
class MicArray:
    """Microphone positions in the device frame (forward, left, up), metres from the emitter."""

    name: str
    offsets: tuple[tuple[float, float, float], ...]

    @property
    def n_mics(self) -> int:
        return len(self.offsets)


MIC_ARRAYS = {
    "phone": MicArray("phone", ((0.0, 0.0, MIC_ABOVE_EMITTER_M),)),
    # Four microphones on the front corners of a headset visor, 16 cm wide and 6 cm tall, plus
    # the protocol's microphone position as the reference channel 0.
    "headset4": MicArray("headset4", ((0.0, 0.0, MIC_ABOVE_EMITTER_M), (0.03, 0.08, 0.03),
                                      (0.03, -0.08, 0.03), (0.0, 0.0, 0.13))),
}


@dataclass
class DevicePose:
    """The capture device: emitter position, forward and up axes (unit, orthogonal).

    The microphone sits 7 cm above the emitter along ``up``; the camera is at the microphone,
    looking along ``forward``. ``target`` is the index of the discontinuity the device faces.
    """

    emitter: np.ndarray
    forward: np.ndarray
    up: np.ndarray
    target: int | None = None

    def __post_init__(self):
        self.emitter = _vector(self.emitter, "pose.emitter")
        self.forward = _unit(self.forward, "pose.forward")
        up = _vector(self.up, "pose.up")
        if abs(np.dot(up, self.forward)) > 1e-12:
            up = up - np.dot(up, self.forward) * self.forward
        if np.linalg.norm(up) < 1e-6:
            raise VrechoError("pose.up: must not be parallel to pose.forward")
        self.up = _unit(up, "pose.up")

    @property
    def rotation(self) -> np.ndarray:
        """3 x 3 matrix whose columns are forward, left, up in the world frame."""
        return np.stack([self.forward, np.cross(self.up, self.forward), self.up], axis=1)

    @property
    def microphone(self) -> np.ndarray:
        return self.emitter + MIC_ABOVE_EMITTER_M * self.up

    camera = microphone

    def microphones(self, array: MicArray) -> np.ndarray:
        """World positions (M, 3) of an array's microphones."""
        return self.emitter + np.asarray(array.offsets) @ self.rotation.T

    def to_dict(self) -> dict:
        return {"emitter": self.emitter.tolist(), "forward": self.forward.tolist(), "up": self.up.tolist(),
                "target": self.target}

    @classmethod
    def from_dict(cls, d, where: str) -> "DevicePose":
        target = _field(d, "target", where, None)
        if target is not None and (isinstance(target, bool) or not isinstance(target, int)):
            raise VrechoError(f"{where}.target: expected a discontinuity index or null, got {target!r}")
        try:
            return cls(_vector(_field(d, "emitter", where), f"{where}.emitter"),
                       _field(d, "forward", where), _field(d, "up", where, [0.0, 0.0, 1.0]), target)
        except VrechoError as e:
            raise VrechoError(str(e).replace("pose.", f"{where}.", 1)) from None


@dataclass
class SoundSource:
    """An ambient sound source in the room playing one of the emitted sounds."""

    position: np.ndarray
    sound: str
    gain_db: float = 0.0

    def to_dict(self) -> dict:
        return {"position": np.asarray(self.position).tolist(), "sound": self.sound, "gain_db": self.gain_db}

    @classmethod
    def from_dict(cls, d, where: str) -> "SoundSource":
        sound = _field(d, "sound", where)
        if sound not in SOUNDS:
            raise VrechoError(f"{where}.sound: expected one of {SOUNDS}, got {sound!r}")
        return cls(_vector(_field(d, "position", where), f"{where}.position"), sound,
                   check_number(_field(d, "gain_db", where, 0.0), f"{where}.gain_db", lo=-60, hi=40))


@dataclass
class CameraPath:
    """A smooth walkthrough: keyframe camera positions and look-at points over ``duration_s``."""

    positions: np.ndarray
    look_at: np.ndarray
    duration_s: float = 30.0

    def __post_init__(self):
        self.positions = np.asarray(self.positions, dtype=float)
        self.look_at = np.asarray(self.look_at, dtype=float)
        if self.positions.ndim != 2 or self.positions.shape[1] != 3 or len(self.positions) < 2:
            raise VrechoError(f"camera_path.positions: expected at least 2 [x, y, z] keyframes, got shape {self.positions.shape}")
        if self.look_at.shape != self.positions.shape:
            raise VrechoError("camera_path.look_at: expected one look-at point per keyframe")
        if not self.duration_s > 0:
            raise VrechoError(f"camera_path.duration_s: must be positive, got {self.duration_s}")

    def sample(self, n: int) -> tuple[np.ndarray, np.ndarray]:
        """``n`` positions (n, 3) and unit forward axes (n, 3), evenly spaced in time."""
        return self.at(np.linspace(0.0, 1.0, n))

    def at(self, t) -> tuple[np.ndarray, np.ndarray]:
        """Positions (n, 3) and unit forward axes (n, 3) at fractions ``t`` (n,) of the walk."""
        k = np.linspace(0.0, 1.0, len(self.positions))
        t = np.clip(np.asarray(t, float), 0.0, 1.0)
        bc = "natural" if len(k) > 2 else "not-a-knot"
        pos = CubicSpline(k, self.positions, bc_type=bc)(t)
        tgt = CubicSpline(k, self.look_at, bc_type=bc)(t)
        fwd = tgt - pos
        return pos, fwd / np.linalg.norm(fwd, axis=1, keepdims=True)

    def to_dict(self) -> dict:
        return {"positions": self.positions.tolist(), "look_at": self.look_at.tolist(), "duration_s": self.duration_s}

    @classmethod
    def from_dict(cls, d, where: str = "camera_path") -> "CameraPath":
        return cls(np.asarray(_field(d, "positions", where), dtype=float),
                   np.asarray(_field(d, "look_at", where), dtype=float),
                   check_number(_field(d, "duration_s", where, 30.0), f"{where}.duration_s"))


@dataclass
class Scene:
    """A room with its discontinuities, device poses, sound sources and camera path."""

    name: str
    room: Room
    discontinuities: list[Discontinuity] = field(default_factory=list)
    poses: list[DevicePose] = field(default_factory=list)
    sources: list[SoundSource] = field(default_factory=list)
    camera_path: CameraPath | None = None
    mic_array: MicArray = MIC_ARRAYS["phone"]
    emitter_p: float = 0.7
    """The device's loudspeaker directivity, pyroomacoustics' cardioid family: gain
    p + (1 - p) cos(angle off the forward axis); 1 is omnidirectional, 0.5 a cardioid. A phone's
    speaker in its body radiates forward: 0.7 is about 3 dB down at 90 degrees, 8 dB behind."""

    def __post_init__(self):
        self.validate()

    # -- checks ---------------------------------------------------------------------------------
    def validate(self) -> None:
        """Raise :class:`VrechoError` naming the first field that is impossible."""
        check_number(self.emitter_p, "scene.emitter_p", lo=0.0, hi=1.0)
        room = self.room
        lengths = room.wall_lengths
        spans: dict[int, list] = {}
        for i, d in enumerate(self.discontinuities):
            where = f"discontinuities[{i}]"
            if not 0 <= d.wall < len(lengths):
                raise VrechoError(f"{where}.wall: no wall {d.wall}; the room has walls 0 to {len(lengths) - 1}")
            u0, u1, z0, z1 = d.bounds()
            eps = 1e-6
            if u0 < -eps or u1 > lengths[d.wall] + eps:
                raise VrechoError(f"{where}: spans {u0:.3f} to {u1:.3f} m along wall {d.wall}, which is {lengths[d.wall]:.3f} m long")
            if z0 < -eps or z1 > room.height_m + eps:
                raise VrechoError(f"{where}: spans heights {z0:.3f} to {z1:.3f} m, outside the wall (0 to {room.height_m} m)")
            if d.kind == "open" and min(d.absorption) < 1.0:
                raise VrechoError(f"{where}.absorption: an opening absorbs everything (1.0 in every band)")
            for j, (v0, v1, w0, w1) in spans.get(d.wall, []):
                if u0 < v1 - eps and v0 < u1 - eps and z0 < w1 - eps and w0 < z1 - eps:
                    raise VrechoError(f"{where}: overlaps discontinuities[{j}] on wall {d.wall}")
            spans.setdefault(d.wall, []).append((i, (u0, u1, z0, z1)))
        for i, p in enumerate(self.poses):
            where = f"poses[{i}]"
            if not room.contains(p.emitter[None])[0]:
                raise VrechoError(f"{where}.emitter: {np.round(p.emitter, 3).tolist()} is outside the room")
            mics = p.microphones(self.mic_array)
            outside = ~room.contains(mics)
            if outside.any():
                k = int(np.argmax(outside))
                raise VrechoError(f"{where}: microphone {k} at {np.round(mics[k], 3).tolist()} is outside the room")
            if p.target is not None and not 0 <= p.target < len(self.discontinuities):
                raise VrechoError(f"{where}.target: no discontinuity {p.target}")
        for i, s in enumerate(self.sources):
            if not room.contains(np.asarray(s.position)[None])[0]:
                raise VrechoError(f"sources[{i}].position: {np.round(s.position, 3).tolist()} is outside the room")
        if self.camera_path is not None:
            outside = ~room.contains(self.camera_path.positions)
            if outside.any():
                raise VrechoError(f"camera_path.positions[{int(np.argmax(outside))}]: outside the room")

    # -- geometry -------------------------------------------------------------------------------
    def discontinuity_corners(self, index: int) -> np.ndarray:
        """World corners (4, 3) of a discontinuity, wound like its wall (normal out of the room)."""
        d = self.discontinuities[index]
        return _rect(self.room, d.wall, *d.bounds())

    def discontinuity_center(self, index: int) -> np.ndarray:
        return self.discontinuity_corners(index).mean(axis=0)

    def depth_m(self, pose: DevicePose, index: int | None = None) -> float:
        """Distance from the emitter to the plane of a discontinuity (the pose's target by default),
        along the plane's normal; negative when the emitter is behind the plane."""
        index = pose.target if index is None else index
        if index is None:
            raise VrechoError("pose.target: the pose faces no discontinuity")
        origin, _, normal = self.room.wall_frame(self.discontinuities[index].wall)
        return float(np.dot(origin - pose.emitter, normal))

    def incidence_deg(self, pose: DevicePose, index: int | None = None) -> float:
        """Angle in degrees between the device's forward axis and the wall's outward normal
        (0 when the device faces the surface squarely)."""
        index = pose.target if index is None else index
        _, _, normal = self.room.wall_frame(self.discontinuities[index].wall)
        return float(np.degrees(np.arccos(np.clip(np.dot(pose.forward, normal), -1, 1))))

    def patches(self) -> list[Patch]:
        """The room's boundary as planar patches: walls cut around each discontinuity, the
        discontinuities themselves, floor and ceiling. Every patch's normal points out."""
        room = self.room
        out: list[Patch] = []
        for w, (length, material) in enumerate(zip(room.wall_lengths, room.walls)):
            holes = [(i, d.bounds()) for i, d in enumerate(self.discontinuities) if d.wall == w]
            for u0, u1, z0, z1 in _wall_minus_holes(length, room.height_m, [b for _, b in holes]):
                out.append(Patch(_rect(room, w, u0, u1, z0, z1), "wall", material, w))
            for i, b in holes:
                d = self.discontinuities[i]
                out.append(Patch(_rect(room, w, *b), d.kind, d.acoustic_material, w, i))
        fp = room.footprint
        out.append(Patch(np.c_[fp[::-1], np.zeros(len(fp))], "floor", room.floor, -1))
        out.append(Patch(np.c_[fp, np.full(len(fp), room.height_m)], "ceiling", room.ceiling, -2))
        return out

    # -- JSON -----------------------------------------------------------------------------------
    def to_dict(self) -> dict:
        return {"format": "vrecho-scene", "version": 1, "name": self.name, "room": self.room.to_dict(),
                "discontinuities": [d.to_dict() for d in self.discontinuities],
                "poses": [p.to_dict() for p in self.poses], "sources": [s.to_dict() for s in self.sources],
                "camera_path": None if self.camera_path is None else self.camera_path.to_dict(),
                "mic_array": self.mic_array.name, "emitter_p": self.emitter_p}

    def to_json(self) -> str:
        return json.dumps(self.to_dict(), indent=1)

    def save(self, path: str | Path) -> Path:
        """Write the scene as JSON, atomically (a temporary file renamed into place)."""
        return atomic_write_text(Path(path), self.to_json())

    @classmethod
    def from_dict(cls, d) -> "Scene":
        if not isinstance(d, dict):
            raise VrechoError(f"scene: expected a JSON object, got {type(d).__name__}")
        if d.get("format", "vrecho-scene") != "vrecho-scene":
            raise VrechoError(f"scene.format: expected 'vrecho-scene', got {d.get('format')!r}")
        mic = d.get("mic_array", "phone")
        if mic not in MIC_ARRAYS:
            raise VrechoError(f"scene.mic_array: expected one of {tuple(MIC_ARRAYS)}, got {mic!r}")

        def items(key):
            v = d.get(key, []) or []
            if not isinstance(v, list):
                raise VrechoError(f"scene.{key}: expected a list")
            return v

        cp = d.get("camera_path")
        return cls(str(_field(d, "name", "scene", "scene")), Room.from_dict(_field(d, "room", "scene")),
                   [Discontinuity.from_dict(x, f"discontinuities[{i}]") for i, x in enumerate(items("discontinuities"))],
                   [DevicePose.from_dict(x, f"poses[{i}]") for i, x in enumerate(items("poses"))],
                   [SoundSource.from_dict(x, f"sources[{i}]") for i, x in enumerate(items("sources"))],
                   None if cp is None else CameraPath.from_dict(cp), MIC_ARRAYS[mic],
                   check_number(d.get("emitter_p", 0.7), "scene.emitter_p", lo=0.0, hi=1.0))


def load_scene(path: str | Path) -> Scene:
    """Read and validate a scene JSON file; one :class:`VrechoError` names what is wrong."""
    path = Path(path)
    try:
        text = path.read_text()
    except OSError as e:
        raise VrechoError(f"scene file {path}: cannot read ({e.strerror})") from None
    try:
        d = json.loads(text)
    except json.JSONDecodeError as e:
        raise VrechoError(f"scene file {path}: not valid JSON (line {e.lineno}: {e.msg})") from None
    try:
        return Scene.from_dict(d)
    except VrechoError as e:
        raise VrechoError(f"scene file {path}: {e}") from None


def _rect(room: Room, wall: int, u0: float, u1: float, z0: float, z1: float) -> np.ndarray:
    origin, u, _ = room.wall_frame(wall)
    z = np.array([0.0, 0.0, 1.0])
    return np.array([origin + a * u + b * z for a, b in ((u0, z0), (u1, z0), (u1, z1), (u0, z1))])


def _wall_minus_holes(length: float, height: float, holes: list) -> list[tuple]:
    """Rectangles (u0, u1, z0, z1) covering a wall except the holes: a grid on every hole edge,
    its free cells merged along each row."""
    us = sorted({0.0, length, *[v for h in holes for v in h[:2]]})
    zs = sorted({0.0, height, *[v for h in holes for v in h[2:]]})
    rects = []
    for z0, z1 in zip(zs[:-1], zs[1:]):
        if z1 - z0 < 1e-9:
            continue
        start = None
        for u0, u1 in zip(us[:-1], us[1:]):
            um, zm = (u0 + u1) / 2, (z0 + z1) / 2
            free = not any(h[0] < um < h[1] and h[2] < zm < h[3] for h in holes)
            if free and start is None:
                start = u0
            if not free and start is not None:
                rects.append((start, u0, z0, z1))
                start = None
        if start is not None:
            rects.append((start, us[-1], z0, z1))
    return [r for r in rects if r[1] - r[0] > 1e-9]


def builtin_scene() -> Scene:
    """The demo's living room: a closed window, an open window, a wall mirror, a glass door, and
    three sound sources, with a walkthrough path."""
    with resources.files("vrecho.assets").joinpath("living_room.json").open() as f:
        return Scene.from_dict(json.load(f))
