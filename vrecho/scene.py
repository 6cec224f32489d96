"""Scenes: rooms, surfaces, discontinuities, device poses, sound sources and camera paths.

A :class:`Scene` is plain data that travels: JSON in (:func:`load_scene`, validated, one error
naming the bad field) and out (:meth:`Scene.save`). World frame: right-handed, Z up, metres.
A room is a counter-clockwise polygon footprint extruded to a height; wall ``i`` runs from corner
``i`` to corner ``i + 1``. A discontinuity is a rectangle on one wall, placed by the distance of
its centre along the wall (``center_u_m``) and its centre height (``center_z_m``).

Materials are :mod:`vrecho.materials`, the device :mod:`vrecho.device`. :func:`builtin_scene` is
the demo's living room; :mod:`vrecho.sim.scenes` draws random scenes as PROTOCOL.md allows.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path

import numpy as np

from .camera import CameraPath
from .device import MIC_ARRAYS, REACH_M, DevicePose, MicArray
from .errors import (VrechoError, check_field, check_keys, check_list, check_number, check_text, check_vector,
                     read_json)
from .furniture import Furniture
from .geometry import distance_to_polygon, point_in_polygon, rectangles_around, segments_cross, signed_area
from .io import atomic_write_text
from .materials import BANDS_HZ, MIRROR, WINDOW_GLASS, Material
from .signals import SOUNDS

KINDS = ("open", "glass", "mirror")
DEPTH_RANGE_M = (0.25, 3.0)
MAX_INCIDENCE_DEG = 15.0

ROOM_SIZE_M = (1.0, 50.0)
"""A room's height and each side of its footprint's bounding box, in metres: impulse responses grow
some 500 samples a metre (a 50 m room: 1 s and 150 MB to simulate; a room 1e9 m high: 2 TiB)."""
MAX_CORNERS = 32
MAX_ITEMS = {"discontinuities": 32, "poses": 1000, "sources": 32, "furniture": 32}
"""The most of each list (and :data:`MAX_CORNERS` of a footprint): walls add to a simulation's time
(a room of 180 patches: 6 s an impulse response), poses and sources to its impulse responses."""


@dataclass(frozen=True)
class Patch:
    """A planar rectangle or polygon of the room's boundary, wound so its normal points out.

    Attributes
    ----------
    corners : numpy.ndarray [shape=(K, 3)]
        World corners, in metres.
    kind : str
        ``wall``, ``floor``, ``ceiling``, ``open``, ``glass``, ``mirror`` or ``furniture``.
    material : Material
    surface : int
        Wall index; -1 for the floor, -2 for the ceiling, -3 - i for furniture ``i``.
    discontinuity : int or None
        Index of the discontinuity the patch is, None for bare boundary.
    """

    corners: np.ndarray  # (K, 3)
    kind: str  # wall | floor | ceiling | open | glass | mirror | furniture
    material: Material
    surface: int  # wall index; -1 floor, -2 ceiling, -3 - i furniture i
    discontinuity: int | None = None

    @property
    def normal(self) -> np.ndarray:
        """Unit normal (3,) of the patch, from its corners' winding: out of the room."""
        c = self.corners
        n = np.cross(c[1] - c[0], c[-1] - c[0])
        return n / np.linalg.norm(n)


@dataclass
class Room:
    """A polygon footprint (counter-clockwise, metres) extruded from z = 0 to ``height_m``.

    Parameters
    ----------
    footprint : array_like [shape=(K, 2)]
        Corners [x, y] in metres; kept as float64.
    height_m : float
        Floor to ceiling, in metres.
    walls : list of Material
        One per wall (wall ``i`` from corner ``i`` to ``i + 1``).
    floor, ceiling : Material

    Raises
    ------
    VrechoError
        For other than 3 to :data:`MAX_CORNERS` finite corners, a corner beyond
        :data:`~vrecho.device.REACH_M`, a height or a side of the footprint's bounding box
        outside :data:`ROOM_SIZE_M`, a clockwise or self-crossing footprint, a wall shorter than
        5 cm, or a wrong number of wall materials.
    """

    footprint: np.ndarray
    height_m: float
    walls: list[Material]
    floor: Material
    ceiling: Material

    def __post_init__(self):
        self.footprint = np.asarray(self.footprint, dtype=float)
        fp = self.footprint
        if fp.ndim != 2 or fp.shape[1] != 2 or not 3 <= fp.shape[0] <= MAX_CORNERS or not np.all(np.isfinite(fp)):
            raise VrechoError(f"room.footprint: expected 3 to {MAX_CORNERS} finite [x, y] corners, got shape {fp.shape}")
        if np.abs(fp).max() > REACH_M:
            raise VrechoError(f"room.footprint: corners must lie within {REACH_M:g} m of the origin in x and y")
        lo, hi = ROOM_SIZE_M
        extent = fp.max(axis=0) - fp.min(axis=0)
        if extent.min() < lo or extent.max() > hi:
            raise VrechoError(f"room.footprint: spans {extent[0]:g} x {extent[1]:g} m; each side of its bounding box "
                              f"must be from {lo:g} to {hi:g} m")
        self.height_m = check_number(self.height_m, "room.height_m", lo=lo, hi=hi)
        check_list(self.walls, "room.walls (one material per wall)", lo=len(fp), hi=len(fp))
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
        """Length of each wall (K,), in metres."""
        return np.linalg.norm(np.roll(self.footprint, -1, axis=0) - self.footprint, axis=1)

    @property
    def box(self) -> tuple[np.ndarray, np.ndarray]:
        """The room's bounding box: its low and high corners (3,), floor to ceiling."""
        return (np.r_[self.footprint.min(axis=0), 0.0], np.r_[self.footprint.max(axis=0), self.height_m])

    def wall_frame(self, i: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Wall ``i``'s frame.

        Parameters
        ----------
        i : int
            Wall index.

        Returns
        -------
        origin, along, normal : numpy.ndarray [shape=(3,)]
            Corner ``i`` at floor level (metres), the unit direction along the wall and the unit
            outward normal.
        """
        p0, p1 = self.footprint[i], self.footprint[(i + 1) % len(self.footprint)]
        u = (p1 - p0) / np.linalg.norm(p1 - p0)
        return np.array([p0[0], p0[1], 0.0]), np.array([u[0], u[1], 0.0]), np.array([u[1], -u[0], 0.0])

    def contains(self, points: np.ndarray, *, margin_m: float = 0.0) -> np.ndarray:
        """Whether points lie inside the room.

        Parameters
        ----------
        points : array_like [shape=(N, 3) or (3,)]
            World positions, in metres.
        margin_m : float
            Least distance from every surface, in metres; 0 by default.

        Returns
        -------
        numpy.ndarray [shape=(N,), dtype=bool]
        """
        p = np.atleast_2d(points)
        inside = point_in_polygon(p[:, :2], self.footprint) & (p[:, 2] > margin_m) & (p[:, 2] < self.height_m - margin_m)
        if margin_m > 0:
            inside &= distance_to_polygon(p[:, :2], self.footprint) >= margin_m
        return inside

    def to_dict(self) -> dict:
        """The room's JSON form.

        Returns
        -------
        dict
            ``footprint``, ``height_m``, ``walls``, ``floor``, ``ceiling`` (materials as objects).
        """
        return {"footprint": self.footprint.tolist(), "height_m": self.height_m,
                "walls": [m.to_dict() for m in self.walls], "floor": self.floor.to_dict(),
                "ceiling": self.ceiling.to_dict()}

    @classmethod
    def from_dict(cls, d, where: str = "room") -> "Room":
        """A room from its JSON form.

        Parameters
        ----------
        d : dict
            As :meth:`to_dict` writes it; ``walls`` may be one material for every wall.
        where : str
            Where ``d`` sits in its file, named by errors; ``"room"`` by default.

        Returns
        -------
        Room
        """
        check_keys(d, ("footprint", "height_m", "walls", "floor", "ceiling"), where)
        corners = check_list(check_field(d, "footprint", where), f"{where}.footprint", lo=3, hi=MAX_CORNERS)
        fp = np.array([check_vector(c, f"{where}.footprint[{i}]", 2, lo=-REACH_M, hi=REACH_M)
                       for i, c in enumerate(corners)])
        height = check_field(d, "height_m", where)  # checked, with the footprint's extent, by the room itself
        walls = check_field(d, "walls", where)
        if isinstance(walls, (str, dict)):
            walls = [walls] * len(fp)
        check_list(walls, f"{where}.walls", lo=len(fp), hi=len(fp))
        return cls(fp, height, [Material.from_dict(w, f"{where}.walls[{i}]") for i, w in enumerate(walls)],
                   Material.from_dict(check_field(d, "floor", where), f"{where}.floor"),
                   Material.from_dict(check_field(d, "ceiling", where), f"{where}.ceiling"))


@dataclass
class Discontinuity:
    """A rectangle on a wall that a camera leaves as a hole or fills wrongly.

    Checked by :meth:`Scene.validate` and :meth:`from_dict`, not on construction.

    Parameters
    ----------
    wall : int
        Index of its wall.
    center_u_m, center_z_m, width_m, height_m : float
        Centre along the wall from its corner, centre height, width and height, in metres.
    kind : str
        ``open`` (an opening: absorbs everything), ``glass`` or ``mirror``.
    absorption : tuple of float
        Per band of :data:`vrecho.materials.BANDS_HZ`, in [0, 1]; 1.0 in every band by default.
    scattering : float
        In [0, 1]; 0.02 by default.
    depth_sensor_sees_through : bool
        For glass, whether a depth camera returns what lies beyond (True) or nothing (False).
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
        """Whether it is an opening."""
        return self.kind == "open"

    @property
    def material(self) -> str | None:
        """``glass`` or ``mirror`` for a closed surface, None for an opening."""
        return None if self.is_open else self.kind

    @property
    def acoustic_material(self) -> Material:
        """Its :class:`Material`, named after its kind."""
        return Material(self.kind, self.absorption, self.scattering)

    def bounds(self) -> tuple[float, float, float, float]:
        """The rectangle's extent in its wall's coordinates.

        Returns
        -------
        u0, u1, z0, z1 : float
            Along the wall and in height, in metres.
        """
        return (self.center_u_m - self.width_m / 2, self.center_u_m + self.width_m / 2,
                self.center_z_m - self.height_m / 2, self.center_z_m + self.height_m / 2)

    def to_dict(self) -> dict:
        """The discontinuity's JSON form.

        Returns
        -------
        dict
            Its fields by name.
        """
        return {"wall": self.wall, "center_u_m": self.center_u_m, "center_z_m": self.center_z_m,
                "width_m": self.width_m, "height_m": self.height_m, "kind": self.kind,
                "absorption": list(self.absorption), "scattering": self.scattering,
                "depth_sensor_sees_through": self.depth_sensor_sees_through}

    @classmethod
    def from_dict(cls, d, where: str) -> "Discontinuity":
        """A discontinuity from its JSON form.

        Parameters
        ----------
        d : dict
            As :meth:`to_dict` writes it; ``absorption`` defaults by kind (an opening's 1.0).
        where : str
            Where ``d`` sits in its file, named by errors.

        Returns
        -------
        Discontinuity
        """
        check_keys(d, ("wall", "center_u_m", "center_z_m", "width_m", "height_m", "kind", "absorption", "scattering",
                       "depth_sensor_sees_through"), where)
        kind = check_text(check_field(d, "kind", where), f"{where}.kind", choices=KINDS)
        wall = check_field(d, "wall", where)
        check_number(wall, f"{where}.wall", lo=0, hi=MAX_CORNERS - 1)
        if not isinstance(wall, int):
            raise VrechoError(f"{where}.wall: expected a wall index (a whole number), got {wall!r}")
        default_abs = {"open": (1.0,) * 7, "glass": WINDOW_GLASS, "mirror": MIRROR}[kind]
        absorption = check_vector(check_field(d, "absorption", where, default_abs), f"{where}.absorption",
                                  len(BANDS_HZ), lo=0.0, hi=1.0)
        sees = check_field(d, "depth_sensor_sees_through", where, True)
        if not isinstance(sees, bool):
            raise VrechoError(f"{where}.depth_sensor_sees_through: expected true or false, got {type(sees).__name__}")
        along, up = 2 * ROOM_SIZE_M[1], ROOM_SIZE_M[1]  # Scene.validate then checks it against its wall
        return cls(wall,
                   check_number(check_field(d, "center_u_m", where), f"{where}.center_u_m", lo=0.0, hi=along),
                   check_number(check_field(d, "center_z_m", where), f"{where}.center_z_m", lo=0.0, hi=up),
                   check_number(check_field(d, "width_m", where), f"{where}.width_m", lo=0.01, hi=along),
                   check_number(check_field(d, "height_m", where), f"{where}.height_m", lo=0.01, hi=up),
                   kind, tuple(absorption.tolist()),
                   check_number(check_field(d, "scattering", where, 0.02), f"{where}.scattering", lo=0.0, hi=1.0),
                   sees)


@dataclass
class SoundSource:
    """An ambient sound source in the room playing one of the emitted sounds.

    Parameters
    ----------
    position : array_like [shape=(3,)]
        World position, in metres; kept as given (:meth:`from_dict` gives a float array).
    sound : str
        One of :data:`vrecho.signals.SOUNDS`.
    gain_db : float
        Level relative to the sound's own, in dB; 0 by default.
    """

    position: np.ndarray
    sound: str
    gain_db: float = 0.0

    def to_dict(self) -> dict:
        """The source's JSON form.

        Returns
        -------
        dict
            ``position``, ``sound``, ``gain_db``.
        """
        return {"position": np.asarray(self.position).tolist(), "sound": self.sound, "gain_db": self.gain_db}

    @classmethod
    def from_dict(cls, d, where: str) -> "SoundSource":
        """A source from its JSON form.

        Parameters
        ----------
        d : dict
            As :meth:`to_dict` writes it; ``gain_db`` in -60 to 40 dB, 0 if absent.
        where : str
            Where ``d`` sits in its file, named by errors.

        Returns
        -------
        SoundSource
        """
        check_keys(d, ("position", "sound", "gain_db"), where)
        sound = check_text(check_field(d, "sound", where), f"{where}.sound", choices=SOUNDS)
        return cls(check_vector(check_field(d, "position", where), f"{where}.position", lo=-REACH_M, hi=REACH_M), sound,
                   check_number(check_field(d, "gain_db", where, 0.0), f"{where}.gain_db", lo=-60.0, hi=40.0))


@dataclass
class Scene:
    """A room with its discontinuities, device poses, sound sources and camera path.

    Parameters
    ----------
    name : str
    room : Room
    discontinuities, poses, sources : list
        Of :class:`Discontinuity`, :class:`DevicePose` and :class:`SoundSource`; none by default.
    camera_path : CameraPath, optional
    mic_array : MicArray
        The device's microphones; ``MIC_ARRAYS["phone"]`` by default.
    emitter_p : float
        The device's loudspeaker directivity, pyroomacoustics' cardioid family: gain
        p + (1 - p) cos(angle off the forward axis); 1 is omnidirectional, 0.5 a cardioid. A
        phone's speaker in its body radiates forward: 0.7 (the default) is about 3 dB down at 90
        degrees, 8 dB behind.
    furniture : list of Furniture
        Boxes in the room (tables, sofas, shelves, door leaves); none by default.

    Raises
    ------
    VrechoError
        Naming the first field that is impossible (:meth:`validate`).
    """

    name: str
    room: Room
    discontinuities: list[Discontinuity] = field(default_factory=list)
    poses: list[DevicePose] = field(default_factory=list)
    sources: list[SoundSource] = field(default_factory=list)
    camera_path: CameraPath | None = None
    mic_array: MicArray = MIC_ARRAYS["phone"]
    emitter_p: float = 0.7
    furniture: list[Furniture] = field(default_factory=list)

    def __post_init__(self):
        self.validate()

    # -- checks ---------------------------------------------------------------------------------
    def validate(self) -> None:
        """Raise :class:`VrechoError` naming the first impossible field (too many, off its wall, out of the room)."""
        check_number(self.emitter_p, "scene.emitter_p", lo=0.0, hi=1.0)
        for key, most in MAX_ITEMS.items():
            check_list(getattr(self, key), key, hi=most)
        room = self.room
        lo, hi = room.box
        inside = f"the room spans x {lo[0]:g} to {hi[0]:g}, y {lo[1]:g} to {hi[1]:g}, z 0 to {hi[2]:g} m"
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
                raise VrechoError(f"{where}.emitter: {np.round(p.emitter, 3).tolist()} is outside the room "
                                  f"({inside})")
            mics = p.microphones(self.mic_array)
            outside = ~room.contains(mics)
            if outside.any():
                k = int(np.argmax(outside))
                raise VrechoError(f"{where}: microphone {k} at {np.round(mics[k], 3).tolist()} is outside the room "
                                  f"({inside})")
            if p.target is not None and not 0 <= p.target < len(self.discontinuities):
                raise VrechoError(f"{where}.target: no discontinuity {p.target}; there are {len(self.discontinuities)}")
        for i, s in enumerate(self.sources):
            if not room.contains(np.asarray(s.position)[None])[0]:
                raise VrechoError(f"sources[{i}].position: {np.round(s.position, 3).tolist()} is outside the room "
                                  f"({inside})")
        for i, f in enumerate(self.furniture):
            if not point_in_polygon(f.footprint(), room.footprint).all() or f.top_m > room.height_m:
                raise VrechoError(f"furniture[{i}] ({f.name}): not wholly inside the room ({inside})")
        if self.camera_path is not None:
            outside = ~room.contains(self.camera_path.positions)
            if outside.any():
                raise VrechoError(f"camera_path.positions[{int(np.argmax(outside))}]: outside the room ({inside})")

    # -- geometry -------------------------------------------------------------------------------
    def discontinuity_corners(self, index: int) -> np.ndarray:
        """A discontinuity's corners.

        Parameters
        ----------
        index : int
            The discontinuity's index in :attr:`discontinuities`.

        Returns
        -------
        numpy.ndarray [shape=(4, 3)]
            World corners in metres, wound like its wall (normal out of the room).
        """
        d = self.discontinuities[index]
        return _rect(self.room, d.wall, *d.bounds())

    def discontinuity_center(self, index: int) -> np.ndarray:
        """A discontinuity's centre.

        Parameters
        ----------
        index : int
            The discontinuity's index in :attr:`discontinuities`.

        Returns
        -------
        numpy.ndarray [shape=(3,)]
            World position in metres.
        """
        return self.discontinuity_corners(index).mean(axis=0)

    def depth_m(self, pose: DevicePose, index: int | None = None) -> float:
        """The depth d of PROTOCOL.md: from the emitter to a discontinuity's plane, along its normal.

        Parameters
        ----------
        pose : DevicePose
        index : int or None
            The discontinuity; the pose's target by default.

        Returns
        -------
        float
            Metres; negative when the emitter is behind the plane.

        Raises
        ------
        VrechoError
            If no index is given and the pose has no target.
        """
        index = pose.target if index is None else index
        if index is None:
            raise VrechoError("pose.target: the pose faces no discontinuity")
        origin, _, normal = self.room.wall_frame(self.discontinuities[index].wall)
        return float(np.dot(origin - pose.emitter, normal))

    def incidence_deg(self, pose: DevicePose, index: int | None = None) -> float:
        """Angle between the device's forward axis and a discontinuity's wall normal.

        Parameters
        ----------
        pose : DevicePose
        index : int or None
            The discontinuity; the pose's target by default.

        Returns
        -------
        float
            Degrees; 0 when the device faces the surface squarely.
        """
        index = pose.target if index is None else index
        _, _, normal = self.room.wall_frame(self.discontinuities[index].wall)
        return float(np.degrees(np.arccos(np.clip(np.dot(pose.forward, normal), -1, 1))))

    def patches(self) -> list[Patch]:
        """The room's boundary as planar patches.

        Returns
        -------
        list of Patch
            Per wall, its pieces cut around each discontinuity, then the discontinuities
            themselves; then floor and ceiling; then each piece of furniture's faces (kind
            "furniture", ``surface`` -3 - its index). Every patch's normal points out of the
            room's air.
        """
        room = self.room
        out: list[Patch] = []
        for w, (length, material) in enumerate(zip(room.wall_lengths, room.walls)):
            holes = [(i, d.bounds()) for i, d in enumerate(self.discontinuities) if d.wall == w]
            for u0, u1, z0, z1 in rectangles_around(length, room.height_m, [b for _, b in holes]):
                out.append(Patch(_rect(room, w, u0, u1, z0, z1), "wall", material, w))
            for i, b in holes:
                d = self.discontinuities[i]
                out.append(Patch(_rect(room, w, *b), d.kind, d.acoustic_material, w, i))
        fp = room.footprint
        out.append(Patch(np.c_[fp[::-1], np.zeros(len(fp))], "floor", room.floor, -1))
        out.append(Patch(np.c_[fp, np.full(len(fp), room.height_m)], "ceiling", room.ceiling, -2))
        for i, f in enumerate(self.furniture):
            out.extend(Patch(face, "furniture", f.material, -3 - i) for face in f.faces())
        return out

    # -- JSON -----------------------------------------------------------------------------------
    def to_dict(self) -> dict:
        """The scene's JSON form.

        Returns
        -------
        dict
            With ``format`` "vrecho-scene" and ``version`` 1.
        """
        return {"format": "vrecho-scene", "version": 1, "name": self.name, "room": self.room.to_dict(),
                "discontinuities": [d.to_dict() for d in self.discontinuities],
                "poses": [p.to_dict() for p in self.poses], "sources": [s.to_dict() for s in self.sources],
                "camera_path": None if self.camera_path is None else self.camera_path.to_dict(),
                "mic_array": self.mic_array.name, "emitter_p": self.emitter_p,
                "furniture": [f.to_dict() for f in self.furniture]}

    def to_json(self) -> str:
        """The scene as JSON text, as :meth:`save` writes it.

        Returns
        -------
        str
        """
        return json.dumps(self.to_dict(), indent=1)

    def save(self, path: str | Path) -> Path:
        """Write the scene as JSON, atomically (a temporary file renamed into place).

        Parameters
        ----------
        path : str or pathlib.Path

        Returns
        -------
        pathlib.Path
            The file written.
        """
        return atomic_write_text(Path(path), self.to_json())

    @classmethod
    def from_dict(cls, d) -> "Scene":
        """A scene from its JSON form, validated.

        Parameters
        ----------
        d : dict
            The JSON object, as :meth:`to_dict` writes it.

        Returns
        -------
        Scene

        Raises
        ------
        VrechoError
            Naming the bad field and its allowed range or choices: a missing or unknown field, a
            value of the wrong type or out of range, or a scene :meth:`validate` refuses.
        """
        check_keys(d, ("format", "version", "name", "room", *MAX_ITEMS, "camera_path", "mic_array", "emitter_p"),
                   "scene")
        check_text(check_field(d, "format", "scene", "vrecho-scene"), "scene.format", choices=("vrecho-scene",))
        check_number(check_field(d, "version", "scene", 1), "scene.version", lo=1, hi=1)  # the only version
        mic = check_text(check_field(d, "mic_array", "scene", "phone"), "scene.mic_array", choices=tuple(MIC_ARRAYS))

        def items(key, read):
            found = check_list(check_field(d, key, "scene", []), key, hi=MAX_ITEMS[key])
            return [read(x, f"{key}[{i}]") for i, x in enumerate(found)]

        cp = check_field(d, "camera_path", "scene", None)
        return cls(check_text(check_field(d, "name", "scene", "scene"), "scene.name"),
                   Room.from_dict(check_field(d, "room", "scene")),
                   items("discontinuities", Discontinuity.from_dict), items("poses", DevicePose.from_dict),
                   items("sources", SoundSource.from_dict),
                   None if cp is None else CameraPath.from_dict(cp), MIC_ARRAYS[mic],
                   check_number(check_field(d, "emitter_p", "scene", 0.7), "scene.emitter_p", lo=0.0, hi=1.0),
                   items("furniture", Furniture.from_dict))


def load_scene(path: str | Path) -> Scene:
    """Read and validate a scene JSON file; one :class:`VrechoError` names what is wrong.

    Parameters
    ----------
    path : str or pathlib.Path
        A scene file as :meth:`Scene.save` writes it.

    Returns
    -------
    Scene

    Raises
    ------
    VrechoError
        If the file is not strict JSON (:func:`vrecho.errors.read_json`) or describes an
        impossible scene (:meth:`Scene.from_dict`).
    """
    path = Path(path)
    d = read_json(path, "scene file", expect=dict)
    try:
        return Scene.from_dict(d)
    except VrechoError as e:
        raise VrechoError(f"scene file {path}: {e}") from None


def _rect(room: Room, wall: int, u0: float, u1: float, z0: float, z1: float) -> np.ndarray:
    origin, u, _ = room.wall_frame(wall)
    z = np.array([0.0, 0.0, 1.0])
    return np.array([origin + a * u + b * z for a, b in ((u0, z0), (u1, z0), (u1, z1), (u0, z1))])


def builtin_scene() -> Scene:
    """The demo's living room: a closed window, an open window, a wall mirror, a glass door, and
    three sound sources, with a walkthrough path.

    Returns
    -------
    Scene

    Examples
    --------
    >>> scene = builtin_scene()
    >>> len(scene.discontinuities), len(scene.sources)
    (4, 3)
    """
    with resources.files("vrecho.assets").joinpath("living_room.json").open() as f:
        return Scene.from_dict(json.load(f))
