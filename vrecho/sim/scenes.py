"""Random scenes as PROTOCOL.md allows them, device poses facing a discontinuity, the
walkthrough a person scanning a room would follow, and furniture for a room.
"""

from __future__ import annotations

import numpy as np

from ..device import MIC_ABOVE_EMITTER_M, DevicePose
from ..errors import VrechoError, check_number
from ..furniture import Furniture
from ..geometry import distance_to_polygon, point_in_polygon
from ..materials import BANDS_HZ, HEAVY_GLASS, MIRROR, WINDOW_GLASS, Material
from ..camera import CameraPath
from ..scene import DEPTH_RANGE_M, KINDS, MAX_INCIDENCE_DEG, Discontinuity, Room, Scene, SoundSource
from ..signals import SOUNDS

WALL_MATERIALS = ("plasterboard", "brickwork", "brick_wall_rough", "ceramic_tiles", "rough_concrete",
                  "unpainted_concrete", "wooden_lining", "wood_1.6cm")


FLOOR_MATERIALS = ("carpet_cotton", "carpet_hairy", "carpet_6mm_closed_cell_foam", "concrete_floor",
                   "ceramic_tiles", "wood_16mm", "linoleum_on_concrete")


CEILING_MATERIALS = ("plasterboard", "ceiling_plasterboard", "rough_concrete", "wooden_lining")


def face(scene: Scene, index: int, depth_m: float, *, offset_u_m: float = 0.0, offset_z_m: float = 0.0,
         yaw_deg: float = 0.0, pitch_deg: float = 0.0) -> DevicePose:
    """A device pose facing discontinuity ``index`` from ``depth_m`` metres.

    The emitter stands on the discontinuity's normal through its centre, shifted by
    ``offset_u_m`` along the wall and ``offset_z_m`` in height, turned by yaw (about z) and pitch.

    Parameters
    ----------
    scene : Scene
        The scene.
    index : int
        The discontinuity to face.
    depth_m : float
        Distance from the wall's plane in metres (positive: in front of it).
    offset_u_m, offset_z_m : float
        Shift along the wall and in height from the discontinuity's centre, in metres.
    yaw_deg, pitch_deg : float
        Turn about the vertical axis and tilt up, in degrees (0: facing the wall squarely).

    Returns
    -------
    DevicePose
        The pose, its target ``index``, up along z.

    Raises
    ------
    VrechoError
        If ``depth_m`` is not a positive finite number, or the device would be outside the room.

    Examples
    --------
    >>> import numpy as np
    >>> scene = random_scene(np.random.default_rng(0))
    >>> pose = face(scene, 0, 1.0)
    >>> pose.target, round(scene.depth_m(pose), 3)
    (0, 1.0)
    """
    depth_m = check_number(depth_m, "depth_m")
    if depth_m <= 0:
        raise VrechoError(f"depth_m: the device must stand in front of the surface (positive depth), got {depth_m}")
    d = scene.discontinuities[index]
    origin, u, normal = scene.room.wall_frame(d.wall)
    foot = origin + (d.center_u_m + offset_u_m) * u + np.array([0, 0, d.center_z_m + offset_z_m])
    emitter = foot - depth_m * normal
    yaw, pitch = np.radians(yaw_deg), np.radians(pitch_deg)
    f = normal * np.cos(yaw) + np.cross([0, 0, 1.0], normal) * np.sin(yaw)
    f = f * np.cos(pitch) + np.array([0, 0, 1.0]) * np.sin(pitch)
    pose = DevicePose(emitter, f, [0.0, 0.0, 1.0], index)
    if not scene.room.contains(pose.microphones(scene.mic_array)).all() or not scene.room.contains(emitter[None])[0]:
        raise VrechoError(f"depth_m: a device {depth_m} m in front of discontinuity {index} would be outside the room")
    return pose


def _sample_depth(rng: np.random.Generator, max_depth: float) -> float:
    lo, hi = DEPTH_RANGE_M
    hi = min(hi, max_depth)
    if rng.random() < 0.35:  # enough frames near the real-scene bins: 1, 2 and 3 ft
        d = rng.choice([0.3048, 0.6096, 0.9144]) + rng.uniform(-0.12, 0.12)
    else:
        d = rng.uniform(lo, hi)
    return float(np.clip(d, lo, hi))


def closed_absorption(kind: str, rng: np.random.Generator) -> tuple[float, ...]:
    """Absorption coefficients of a random pane of glass or mirror.

    Glass lies between heavy and window glass (a random blend, jittered per band); anything
    else is a mirror, its coefficients scaled by 0.8 to 1.2 per band.

    Parameters
    ----------
    kind : str
        "glass", or "mirror".
    rng : numpy.random.Generator
        Source of the draw.

    Returns
    -------
    tuple of float
        One coefficient per octave band of :data:`vrecho.scene.BANDS_HZ` (7), rounded to 4
        decimals.
    """
    if kind == "glass":
        t = np.clip(rng.uniform() + rng.uniform(-0.1, 0.1, len(BANDS_HZ)), 0, 1)
        return tuple(np.round(np.array(HEAVY_GLASS) * (1 - t) + np.array(WINDOW_GLASS) * t, 4))
    return tuple(np.round(np.array(MIRROR) * rng.uniform(0.8, 1.2, len(BANDS_HZ)), 4))


def random_scene(rng: np.random.Generator, name: str = "scene", *, n_poses: int = 8, n_sources: int = 2,
                 n_discontinuities: tuple[int, int] = (1, 3)) -> Scene:
    """Draw a scene as PROTOCOL.md allows.

    Rooms 2.5 to 6 m on a side (a box, or a box with one corner cut), 2.4 to 3 m high, with walls,
    floor and ceiling of pyroomacoustics' database; 1 to 3 discontinuities (open, glass, mirror,
    0.4 to 2.5 m on a side, glass and mirror coefficients drawn per scene; at most one per wall);
    ``n_poses`` device poses each facing a discontinuity (in turn) from 0.25 to 3 m within
    15 degrees of its normal; ``n_sources`` ambient sources playing one of the 16 sounds (gain
    -6 to 6 dB); the device's loudspeaker directivity (``emitter_p``) from 0.5 (cardioid) to 0.9.
    The scene has no camera path (see :func:`walkthrough_path`).

    Parameters
    ----------
    rng : numpy.random.Generator
        Source of the draw: the same seed gives the same scene.
    name : str
        The scene's name (default "scene"); it also seeds the exterior the camera sees.
    n_poses : int
        Number of device poses (default 8).
    n_sources : int
        Number of ambient sound sources (default 2).
    n_discontinuities : tuple of (int, int)
        Fewest and most discontinuities, both included (default (1, 3)).

    Returns
    -------
    Scene
        The scene, validated.

    Raises
    ------
    RuntimeError
        If the device could not be placed in 200 tries.

    Examples
    --------
    >>> import numpy as np
    >>> scene = random_scene(np.random.default_rng(0))
    >>> len(scene.poses), len(scene.sources), len(scene.discontinuities)
    (8, 2, 1)
    """
    for _ in range(200):
        scene = _try_random_scene(rng, name, n_poses, n_sources, n_discontinuities)
        if scene is not None:
            return scene
    raise RuntimeError("random_scene: could not place the device in 200 tries")  # pragma: no cover


def _try_random_scene(rng, name, n_poses, n_sources, n_discontinuities) -> Scene | None:
    lx, ly = rng.uniform(2.5, 6.0, 2)
    height = float(rng.uniform(2.4, 3.0))
    fp = [(0.0, 0.0), (lx, 0.0), (lx, ly), (0.0, ly)]
    if rng.random() < 0.25:  # cut one corner: a pentagon
        cx, cy = rng.uniform(0.5, 0.35 * lx), rng.uniform(0.5, 0.35 * ly)
        fp = [(0.0, 0.0), (lx, 0.0), (lx, ly - cy), (lx - cx, ly), (0.0, ly)]
    fp = np.round(np.array(fp), 3)
    scat = float(np.round(rng.uniform(0.05, 0.3), 3))
    if rng.random() < 0.5:
        walls = [Material.from_database(str(rng.choice(WALL_MATERIALS)), scattering=scat)] * len(fp)
    else:
        walls = [Material.from_database(str(rng.choice(WALL_MATERIALS)), scattering=scat) for _ in fp]
    room = Room(fp, round(height, 3), walls, Material.from_database(str(rng.choice(FLOOR_MATERIALS)), scattering=scat),
                Material.from_database(str(rng.choice(CEILING_MATERIALS)), scattering=scat))
    # Devices differ: from a cardioid to nearly omnidirectional loudspeakers.
    scene = Scene(name, room, emitter_p=float(np.round(rng.uniform(0.5, 0.9), 3)))

    n_disc = int(rng.integers(n_discontinuities[0], n_discontinuities[1] + 1))
    walls_free = list(rng.permutation(len(fp)))
    for _ in range(n_disc):
        if not walls_free:
            break
        w = int(walls_free.pop())
        length = room.wall_lengths[w]
        kind = str(rng.choice(KINDS))
        width = float(rng.uniform(0.4, min(2.5, length - 0.2)))
        if kind == "open" and rng.random() < 0.4:  # a door: from the floor up
            h = float(rng.uniform(1.9, min(2.3, height - 0.1)))
            z0 = 0.0
        else:
            h = float(rng.uniform(0.4, min(2.5, height - 0.2)))
            z0 = float(rng.uniform(0.0 if kind == "mirror" else 0.2, height - 0.05 - h)) if height - 0.05 - h > 0.2 else 0.05
        u_c = float(rng.uniform(width / 2 + 0.05, length - width / 2 - 0.05))
        absorption = (1.0,) * 7 if kind == "open" else closed_absorption(kind, rng)
        width, h, z0, u_c = (round(v, 3) for v in (width, h, z0, u_c))  # centres stay exact edges
        scene.discontinuities.append(Discontinuity(
            w, u_c, z0 + h / 2, width, h, kind, absorption,
            float(np.round(rng.uniform(0.01, 0.05), 3)), bool(rng.random() < 0.5)))

    for k in range(n_poses):
        target = k % len(scene.discontinuities)
        pose = _random_pose(scene, target, rng)
        if pose is None:
            return None
        scene.poses.append(pose)
    for _ in range(n_sources):
        for _ in range(100):
            p = np.array([rng.uniform(0, lx), rng.uniform(0, ly), rng.uniform(0.3, height - 0.3)])
            if room.contains(p[None], margin_m=0.3)[0]:
                break
        else:
            return None
        scene.sources.append(SoundSource(np.round(p, 3), str(rng.choice(SOUNDS)), float(np.round(rng.uniform(-6, 6), 2))))
    scene.validate()
    return scene


def _random_pose(scene: Scene, index: int, rng: np.random.Generator) -> DevicePose | None:
    d = scene.discontinuities[index]
    room = scene.room
    origin, u, normal = room.wall_frame(d.wall)
    u0, u1, z0, z1 = d.bounds()
    for _ in range(50):
        # The foot of the emitter's perpendicular stays on the rectangle, so the specular echo
        # comes from the discontinuity; a handheld device between 0.6 and 2.0 m high.
        mu = min(0.1, 0.25 * (u1 - u0))
        zl, zh = max(z0 + mu, 0.6), min(z1 - mu, 2.0)
        if zl > zh:
            zl = zh = float(np.clip((z0 + z1) / 2, 0.3, room.height_m - 0.3))
        foot = origin + rng.uniform(u0 + mu, u1 - mu) * u + np.array([0, 0, rng.uniform(zl, zh)])
        # How far into the room the normal runs before it leaves: bounds the depth.
        ts = np.arange(0.15, 6.5, 0.025)
        inside = room.contains(foot[None] - ts[:, None] * normal, margin_m=0.1)
        if not inside[0]:
            continue
        max_depth = ts[np.argmin(inside)] - 0.1 if not inside.all() else ts[-1]
        if max_depth < DEPTH_RANGE_M[0]:
            continue
        depth = _sample_depth(rng, max_depth)
        theta = np.radians(rng.uniform(0, MAX_INCIDENCE_DEG))
        phi = rng.uniform(0, 2 * np.pi)
        side = np.cross([0, 0, 1.0], normal)
        f = np.cos(theta) * normal + np.sin(theta) * (np.cos(phi) * side + np.sin(phi) * np.array([0, 0, 1.0]))
        pose = DevicePose(np.round(foot - depth * normal, 4), f, [0.0, 0.0, 1.0], index)
        if room.contains(pose.microphones(scene.mic_array), margin_m=0.02).all() and room.contains(pose.emitter[None], margin_m=0.02)[0]:
            return pose
    return None


def walkthrough_path(scene: Scene, *, distance_m: float = 1.6, height_m: float = 1.5, duration_s: float = 40.0,
                     reach_m: tuple[float, float] = (0.8, 1.9), clear_m: float = 0.35) -> CameraPath:
    """A camera path around a room that looks at every wall, and squarely at each discontinuity.

    Keyframes in the footprint's order: in front of each discontinuity (or of the middle of a
    wall without one), looking at its centre, then tilting down to its foot and up to its top
    where they lie beyond what the camera holds from there. Where to stand (:func:`_stand`):
    near ``distance_m`` and ``height_m``, so that the device's loudspeaker faces the
    discontinuity itself (its echo comes back from the foot of the loudspeaker's perpendicular:
    only there does the echo speak of it; see :func:`vrecho.reconstruct.decide.infer`), with no other
    surface (floor, ceiling, another wall) at the same distance within ``clear_m`` (their echoes
    would drown an opening's silence), and with the whole discontinuity in the camera's view.
    What a person scanning the room would do; the scenes of :func:`random_scene` have no path of
    their own.

    Parameters
    ----------
    scene : Scene
        The scene.
    distance_m : float
        Preferred distance from the wall in metres (default 1.6).
    height_m : float
        Preferred camera height in metres (default 1.5).
    duration_s : float
        Length of the walk in seconds (default 40).
    reach_m : tuple of (float, float)
        Lowest and highest camera heights the arm reaches, in metres (default 0.8 to 1.9).
    clear_m : float
        How far, in metres, every other surface's distance must stay from the discontinuity's
        (default 0.35).

    Returns
    -------
    vrecho.camera.CameraPath
        Keyframe positions and look-at points, ending where it starts.

    Examples
    --------
    >>> import numpy as np
    >>> path = walkthrough_path(random_scene(np.random.default_rng(0)))
    >>> path.positions.shape, path.duration_s
    ((12, 3), 40.0)
    """
    room = scene.room
    positions, targets = [], []
    for w, length in enumerate(room.wall_lengths):
        origin, u, normal = room.wall_frame(w)
        ds = sorted((d for d in scene.discontinuities if d.wall == w), key=lambda d: d.center_u_m)
        looks = [(d.center_u_m, d.width_m, d.bounds()[2:]) for d in ds] or [(length / 2, 0.0, (1.0, 1.6))]
        for u_m, width, (z0, z1) in looks:
            centre = origin + u_m * u
            pos, dist = _stand(room, w, centre, width, z0, z1, distance_m, height_m, reach_m, clear_m)
            band = min(0.6, 0.35 * dist)  # what the camera holds above and below its axis, with a margin
            tilts = [z for z, beyond in ((z0 + 0.3, z0 < pos[2] - band), (z1 - 0.3, z1 > pos[2] + band)) if beyond]
            # Looking at the centre, but not so steeply that the camera no longer faces it.
            level = np.clip((z0 + z1) / 2, pos[2] - min(0.7, 0.35 * dist), pos[2] + min(0.3, 0.35 * dist))
            for z_m in [level] + tilts:
                positions.append(pos)
                targets.append(centre + np.array([0.0, 0.0, z_m]))
    positions.append(positions[0])
    targets.append(targets[0])
    return CameraPath(np.round(positions, 3), np.round(targets, 3), duration_s)


def _stand(room: Room, w: int, centre: np.ndarray, width: float, z0: float, z1: float, distance_m: float,
           height_m: float, reach_m: tuple[float, float], clear_m: float,
           fov_deg: float = 65.0) -> tuple[np.ndarray, float]:
    """Where a person scanning stands to face the point ``centre`` (at floor level) of wall
    ``w``, for a discontinuity ``width`` wide from ``z0`` to ``z1`` high: the camera's position
    and its distance from the wall. Of the places 0.4 m inside the room, heights within reach
    and distances from 0.6 m to 0.6 m beyond ``distance_m``, the first by: the whole width in
    view (a ``fov_deg`` camera, 15 cm to spare each side), the distance clear of every other
    surface's (see :func:`walkthrough_path`), then nearest ``distance_m`` and ``height_m``.
    The loudspeaker (:data:`MIC_ABOVE_EMITTER_M` below the camera) stays 15 cm inside the
    discontinuity's height where it can."""
    _, _, normal = room.wall_frame(w)
    lo, hi = max(z0 + 0.15, reach_m[0] - MIC_ABOVE_EMITTER_M), min(z1 - 0.15, reach_m[1] - MIC_ABOVE_EMITTER_M)
    if lo > hi:  # too small or out of reach: as near its middle as the arm goes
        lo = hi = float(np.clip((z0 + z1) / 2, reach_m[0] - MIC_ABOVE_EMITTER_M, reach_m[1] - MIC_ABOVE_EMITTER_M))
    emitters = np.unique(np.r_[np.clip(height_m - MIC_ABOVE_EMITTER_M, lo, hi), np.arange(lo, hi + 1e-9, 0.05)])
    others = [(room.wall_frame(v)[0], room.wall_frame(v)[2]) for v in range(len(room.wall_lengths)) if v != w]
    half_view = np.tan(np.radians(fov_deg / 2))
    best = None
    for dist in np.arange(0.6, distance_m + 0.65, 0.1):
        xy = (centre - dist * normal)[:2]
        if not room.contains(np.r_[xy, 1.0][None], margin_m=0.4)[0]:
            continue
        walls = [abs(float(n[:2] @ (xy - o[:2]))) for o, n in others]
        for e in emitters:
            echoes = np.array(walls + [e, room.height_m - e])
            key = (dist * half_view < width / 2 + 0.15, np.min(np.abs(echoes - dist)) < clear_m,
                   abs(dist - distance_m) + abs(e + MIC_ABOVE_EMITTER_M - height_m))
            if best is None or key < best[0]:
                best = (key, np.r_[xy, e + MIC_ABOVE_EMITTER_M], float(dist))
    if best is None:  # no room to stand 0.4 m inside: as far out as the room allows
        return np.r_[(centre - 0.6 * normal)[:2], np.clip(height_m, *reach_m)], 0.6
    return best[1], best[2]


FURNITURE_KINDS = ("table", "sofa", "shelf", "door leaf")
"""What :func:`random_furniture` draws."""

_WOOD = Material("wood", (0.15, 0.11, 0.1, 0.07, 0.06, 0.07, 0.07))
_FABRIC = Material("fabric", (0.1, 0.2, 0.45, 0.6, 0.65, 0.6, 0.6), 0.3)


def random_furniture(room: Room, rng: np.random.Generator, n: int, *, kinds=FURNITURE_KINDS,
                     keep_clear: list | None = None) -> list[Furniture]:
    """Up to ``n`` pieces of furniture placed in a room without overlapping.

    Tables (a top 0.7 to 0.76 m up, its legs left out), sofas (0.8 to 0.9 m high, fabric), shelves
    (1.6 to 2 m high, 3 to 8 cm off a wall) and open door leaves (4 cm thick, hinged at a wall,
    open 30 to 90 degrees).

    Parameters
    ----------
    room : Room
        The room.
    rng : numpy.random.Generator
        The draw.
    n : int
        How many to try for.
    kinds : tuple of str
        Which of :data:`FURNITURE_KINDS` to draw from.
    keep_clear : list of (numpy.ndarray, float), optional
        Discs ([x, y], radius in metres) to leave empty (where people walk).

    Returns
    -------
    list of vrecho.furniture.Furniture
        Those that found a place (50 tries each).
    """
    placed: list[Furniture] = []
    discs = list(keep_clear or [])
    fp, lengths = room.footprint, room.wall_lengths
    for _ in range(n):
        kind = str(rng.choice(kinds))
        for _ in range(50):
            w = int(rng.integers(len(fp)))
            origin, u, normal = room.wall_frame(w)
            yaw = float(np.degrees(np.arctan2(u[1], u[0])))
            if kind == "table":
                size, z0, material = (rng.uniform(0.8, 1.8), rng.uniform(0.6, 1.0), 0.04), rng.uniform(0.66, 0.72), _WOOD
                centre = np.array([rng.uniform(fp[:, 0].min(), fp[:, 0].max()), rng.uniform(fp[:, 1].min(), fp[:, 1].max())])
                yaw = float(rng.uniform(0, 180))
            else:
                if kind == "sofa":
                    size, z0, material, gap = (rng.uniform(1.6, 2.2), rng.uniform(0.8, 0.95), rng.uniform(0.8, 0.9)), 0.0, _FABRIC, 0.05
                elif kind == "shelf":
                    size, z0, material, gap = (rng.uniform(0.6, 1.2), rng.uniform(0.3, 0.4), rng.uniform(1.6, 2.0)), 0.0, _WOOD, \
                        rng.uniform(0.03, 0.08)
                else:  # a door leaf, hinged near the wall and swung open into the room
                    size, z0, material = (rng.uniform(0.8, 0.9), 0.04, rng.uniform(1.95, 2.0)), 0.01, _WOOD
                if lengths[w] < size[0] + 0.3:
                    continue
                along = rng.uniform(size[0] / 2 + 0.1, lengths[w] - size[0] / 2 - 0.1)
                if kind == "door leaf":
                    swing = np.radians(rng.uniform(30, 90))
                    hinge = origin[:2] + (along - size[0] / 2) * u[:2] - 0.03 * normal[:2]
                    direction = np.cos(swing) * u[:2] - np.sin(swing) * normal[:2]
                    centre = hinge + direction * size[0] / 2
                    yaw = float(np.degrees(np.arctan2(direction[1], direction[0])))
                else:
                    centre = origin[:2] + along * u[:2] - (gap + size[1] / 2) * normal[:2]
            piece = Furniture(kind, tuple(np.round(centre, 3)), tuple(np.round(size, 3)), z0=round(float(z0), 3),
                              yaw_deg=round(yaw, 2), material=material)
            corners = piece.footprint()
            radius = 0.5 * float(np.hypot(*piece.size[:2]))
            if not point_in_polygon(corners, fp).all() or (distance_to_polygon(corners, fp).min() < 0.02 and kind == "table"):
                continue
            if piece.top_m > room.height_m - 0.1:
                continue
            if any(np.linalg.norm(piece.center - np.asarray(c)) < radius + r + 0.05 for c, r in discs):
                continue
            placed.append(piece)
            discs.append((np.asarray(piece.center), radius))
            break
    return placed
