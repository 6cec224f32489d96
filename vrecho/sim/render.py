"""What a camera sees of a scene: grayscale images and depth frames by ray casting (open3d).

What a camera sees follows PROTOCOL.md: an opening shows what lies beyond the room (an exterior
of ground, buildings and sky drawn per scene); glass shows what lies beyond, slightly dimmed,
with a faint reflection of the room; a mirror shows the room reflected. The depth sensor fails
the way real ones do: through glass it returns what lies beyond, or nothing (per pane,
``Discontinuity.depth_sensor_sees_through``), and in a mirror it returns the length of the
reflected path: a phantom room behind the wall.

Camera frame conventions are :mod:`vrecho.camera`'s (OpenCV's; poses camera-to-world).
"""

from __future__ import annotations

import zlib

import numpy as np

from ..camera import CROP_SHAPE, DEPTH_MAX_M, Camera, View, crop_grid
from ..device import DevicePose
from ..errors import VrechoError
from ..geometry import triangulate_polygon
from ..scene import Scene

GLASS_TRANSMIT = 0.85


GLASS_REFLECT = 0.08


MIRROR_REFLECT = 0.92


MAX_BOUNCES = 3


_DIFFUSE, _GLASS, _MIRROR = 0, 1, 2


class World:
    """The scene as open3d ray-casting geometry, with what each piece looks like.

    The room's patches (openings left out, so rays pass through them) and an exterior drawn
    from the scene's name: ground, and 8 to 13 boxes (buildings, trees) at least 1 m outside the
    room.

    Parameters
    ----------
    scene : Scene
        The scene to draw.

    Attributes
    ----------
    scene : Scene
        The scene drawn.
    """

    def __init__(self, scene: Scene):
        import open3d as o3d  # heavy (1.2 s to import): only where meshes are made or ray-cast

        self.scene = scene
        self._rc = o3d.t.geometry.RaycastingScene()
        self._kind: list[int] = []
        self._albedo: list[float] = []
        self._sees_through: list[bool] = []
        self._pattern: list[int] = []
        self._interior: list[bool] = []
        rng = np.random.default_rng(zlib.crc32(scene.name.encode()))
        for p in scene.patches():
            if p.kind == "open":
                continue
            kind = {"glass": _GLASS, "mirror": _MIRROR}.get(p.kind, _DIFFUSE)
            albedo = {"floor": 0.45, "ceiling": 0.9}.get(p.kind, 0.55 + 0.3 * _hash01(p.material.name))
            sees = p.discontinuity is None or scene.discontinuities[p.discontinuity].depth_sensor_sees_through
            self._add(p.corners, kind, albedo, sees, {"floor": 1, "ceiling": 0}.get(p.kind, 2))
        # The exterior, seen through openings and glass: ground, buildings, trees.
        fp = scene.room.footprint
        lo, hi = fp.min(axis=0), fp.max(axis=0)
        self._add(np.array([[lo[0] - 80, lo[1] - 80, -0.02], [hi[0] + 80, lo[1] - 80, -0.02],
                            [hi[0] + 80, hi[1] + 80, -0.02], [lo[0] - 80, hi[1] + 80, -0.02]]), _DIFFUSE, 0.3, True, 3)
        for _ in range(int(rng.integers(8, 14))):
            ang = rng.uniform(0, 2 * np.pi)
            dist = rng.uniform(2.0, 14.0)
            way = np.array([np.cos(ang), np.sin(ang)])
            c = (lo + hi) / 2 + (np.linalg.norm(hi - lo) / 2 + dist) * way
            size = np.r_[rng.uniform(1.0, 6.0, 2), rng.uniform(2.0, 12.0)]
            while np.all(np.abs(c - (lo + hi) / 2) < (hi - lo) / 2 + size[:2] / 2 + 1.0):
                c = c + 0.5 * way  # a building stands at least 1 m outside the room, never in it
            self._add_box(np.r_[c - size[:2] / 2, 0.0], np.r_[c + size[:2] / 2, size[2]], rng.uniform(0.3, 0.9),
                          int(rng.integers(4, 6)))

    def _add(self, corners: np.ndarray, kind: int, albedo: float, sees_through: bool, pattern: int) -> None:
        import open3d as o3d  # heavy (1.2 s to import): only where meshes are made or ray-cast

        tris = triangulate_polygon(corners)
        mesh = o3d.t.geometry.TriangleMesh()
        mesh.vertex.positions = o3d.core.Tensor(corners.astype(np.float32))
        mesh.triangle.indices = o3d.core.Tensor(tris.astype(np.int32))
        self._rc.add_triangles(mesh)
        self._kind.append(kind)
        self._albedo.append(albedo)
        self._sees_through.append(sees_through)
        self._pattern.append(pattern)
        self._interior.append(pattern < 3)  # room patches are lit by the room's light, the rest by the sun

    def _add_box(self, lo, hi, albedo, pattern) -> None:
        x0, y0, z0 = lo
        x1, y1, z1 = hi
        faces = [[(x0, y0, z0), (x1, y0, z0), (x1, y0, z1), (x0, y0, z1)], [(x1, y0, z0), (x1, y1, z0), (x1, y1, z1), (x1, y0, z1)],
                 [(x1, y1, z0), (x0, y1, z0), (x0, y1, z1), (x1, y1, z1)], [(x0, y1, z0), (x0, y0, z0), (x0, y0, z1), (x0, y1, z1)],
                 [(x0, y0, z1), (x1, y0, z1), (x1, y1, z1), (x0, y1, z1)]]
        for f in faces:
            self._add(np.array(f, float), _DIFFUSE, float(albedo), True, pattern)

    def cast(self, origins: np.ndarray, dirs: np.ndarray):
        """Distance, geometry id (-1 on a miss) and unit normal of the first hit of each ray.

        Parameters
        ----------
        origins : numpy.ndarray [shape=(N, 3)]
            Ray origins in metres.
        dirs : numpy.ndarray [shape=(N, 3)]
            Unit ray directions.

        Returns
        -------
        t : numpy.ndarray [shape=(N,)], float64
            Distance to the hit in metres, infinite on a miss.
        gid : numpy.ndarray [shape=(N,)], int64
            Geometry id of the hit piece, -1 on a miss.
        normals : numpy.ndarray [shape=(N, 3)], float64
            Unit normal of the hit triangle.
        """
        import open3d as o3d  # heavy (1.2 s to import): only where meshes are made or ray-cast

        rays = o3d.core.Tensor(np.hstack([origins, dirs]).astype(np.float32))
        ans = self._rc.cast_rays(rays)
        t = ans["t_hit"].numpy().astype(np.float64)
        gid = ans["geometry_ids"].numpy().astype(np.int64)
        gid[~np.isfinite(t)] = -1
        return t, gid, ans["primitive_normals"].numpy().astype(np.float64)

    def shade(self, points: np.ndarray, normals: np.ndarray, gid: np.ndarray) -> np.ndarray:
        """Radiance of diffuse hits: albedo times a procedural texture times Lambert lighting.

        The room's pieces are lit by a light 10 cm below the ceiling above the footprint's
        centre, the exterior by the sun.

        Parameters
        ----------
        points : numpy.ndarray [shape=(N, 3)]
            Hit points in metres.
        normals : numpy.ndarray [shape=(N, 3)]
            Unit normals there.
        gid : numpy.ndarray [shape=(N,)], int
            Geometry ids of the hit pieces (no misses).

        Returns
        -------
        numpy.ndarray [shape=(N,)], float64
            Grayscale radiance, 0 to 1.
        """
        albedo = np.asarray(self._albedo)[gid]
        pattern = np.asarray(self._pattern)[gid]
        x, y, z = points.T
        tex = np.ones(len(points))
        tex = np.where(pattern == 1, 0.8 + 0.2 * (np.floor(x / 0.2) % 2), tex)  # floor planks
        tex = np.where(pattern == 2, 0.9 + 0.1 * np.sin(2 * np.pi * (x + y) / 0.35) * np.sin(2 * np.pi * z / 0.5), tex)
        tex = np.where(pattern == 3, 0.85 + 0.15 * np.sin(x * 1.7) * np.sin(y * 1.3), tex)  # ground
        windows = (np.floor((x + y) / 1.2) % 2) * (np.floor(z / 1.5) % 2)
        tex = np.where(pattern == 4, 1.0 - 0.5 * windows, tex)  # buildings
        tex = np.where(pattern == 5, 0.6 + 0.4 * np.sin(3 * x) * np.sin(3 * y), tex)  # trees
        room = self.scene.room
        lo, hi = room.footprint.min(axis=0), room.footprint.max(axis=0)
        light = np.r_[(lo + hi) / 2, room.height_m - 0.1]
        to_light = light - points
        to_light /= np.linalg.norm(to_light, axis=1, keepdims=True)
        inside = np.asarray(self._interior)[gid]
        sun = np.array([0.4, 0.3, 0.87])
        lambert = np.abs(np.sum(normals * np.where(inside[:, None], to_light, sun), axis=1))
        return albedo * tex * (0.35 + 0.65 * lambert)

    def trace(self, origins: np.ndarray, dirs: np.ndarray) -> np.ndarray:
        """Grayscale radiance (N,) along rays, through glass and off mirrors up to 3 bounces.

        A ray that misses everything sees the sky; one still on glass or a mirror after the last
        bounce looks like a dim wall.

        Parameters
        ----------
        origins : numpy.ndarray [shape=(N, 3)]
            Ray origins in metres.
        dirs : numpy.ndarray [shape=(N, 3)]
            Unit ray directions.

        Returns
        -------
        numpy.ndarray [shape=(N,)], float64
            Radiance, clipped to 0 to 1.
        """
        out = np.zeros(len(origins))
        idx = np.arange(len(origins))
        weight = np.ones(len(origins))
        kinds = np.asarray(self._kind)
        for bounce in range(MAX_BOUNCES + 1):
            if len(idx) == 0:
                break
            t, gid, n = self.cast(origins, dirs)
            miss = gid < 0
            np.add.at(out, idx[miss], weight[miss] * (0.75 + 0.2 * np.clip(dirs[miss, 2], 0, 1)))  # sky
            hit = ~miss
            kind = np.full(len(idx), -1)
            kind[hit] = kinds[gid[hit]]
            pts = origins + np.where(np.isfinite(t), t, 0)[:, None] * dirs
            diffuse = kind == _DIFFUSE
            np.add.at(out, idx[diffuse], weight[diffuse] * self.shade(pts[diffuse], n[diffuse], gid[diffuse]))
            refl = _reflect(dirs, n)
            new_o, new_d, new_w, new_i = [], [], [], []
            last = bounce == MAX_BOUNCES
            for mask, d, w in ((kind == _GLASS, dirs, GLASS_TRANSMIT), (kind == _GLASS, refl, GLASS_REFLECT),
                               (kind == _MIRROR, refl, MIRROR_REFLECT)):
                if last:  # out of bounces: what is left looks like a dim wall
                    np.add.at(out, idx[mask], weight[mask] * w * 0.4)
                    continue
                new_o.append(pts[mask] + 1e-3 * d[mask])
                new_d.append(d[mask])
                new_w.append(weight[mask] * w)
                new_i.append(idx[mask])
            if last:
                break
            origins, dirs = np.concatenate(new_o), np.concatenate(new_d)
            weight, idx = np.concatenate(new_w), np.concatenate(new_i)
        return np.clip(out, 0.0, 1.0)

    def sensor_range(self, origins: np.ndarray, dirs: np.ndarray) -> np.ndarray:
        """Path length (N,) a depth sensor reports along each ray, 0 for no return.

        Through glass to what lies beyond (or nothing, for a pane the sensor does not see
        through), off a mirror to the phantom behind it; a ray that hits nothing returns nothing.

        Parameters
        ----------
        origins : numpy.ndarray [shape=(N, 3)]
            Ray origins in metres.
        dirs : numpy.ndarray [shape=(N, 3)]
            Unit ray directions.

        Returns
        -------
        numpy.ndarray [shape=(N,)], float64
            Path length in metres along the (possibly reflected) ray, 0 for no return.
        """
        total = np.zeros(len(origins))
        valid = np.ones(len(origins), bool)
        idx = np.arange(len(origins))
        kinds = np.asarray(self._kind)
        sees = np.asarray(self._sees_through)
        for _ in range(MAX_BOUNCES + 1):
            t, gid, n = self.cast(origins, dirs)
            miss = gid < 0
            valid[idx[miss]] = False
            total[idx[~miss]] += t[~miss]
            kind = np.where(miss, -1, kinds[np.maximum(gid, 0)])
            blind = (kind == _GLASS) & ~sees[np.maximum(gid, 0)]
            valid[idx[blind]] = False
            go_on = (kind == _MIRROR) | ((kind == _GLASS) & ~blind)
            if not go_on.any():
                break
            pts = origins + np.where(np.isfinite(t), t, 0)[:, None] * dirs
            d = np.where((kind == _MIRROR)[:, None], _reflect(dirs, n), dirs)
            origins, dirs, idx = pts[go_on] + 1e-3 * d[go_on], d[go_on], idx[go_on]
        total[~valid] = 0.0
        return total


def _hash01(name: str) -> float:
    return (zlib.crc32(name.encode()) % 1000) / 1000.0


def _reflect(d: np.ndarray, n: np.ndarray) -> np.ndarray:
    return d - 2 * np.sum(d * n, axis=1, keepdims=True) * n


def render_view(world: World | Scene, pose: np.ndarray, *, camera: Camera = Camera()) -> View:
    """Render a grayscale image and a depth frame from a camera-to-world ``pose`` (4, 4).

    Parameters
    ----------
    world : World or Scene
        What to render (a scene is made into a :class:`World` first, at some cost: pass a World
        to render many frames).
    pose : numpy.ndarray [shape=(4, 4)]
        Camera-to-world pose (OpenCV axes; :func:`vrecho.camera.camera_pose`), metres.
    camera : vrecho.camera.Camera
        Image size and field of view (default ``Camera()``: 320 x 240 pixels, 65 degrees).

    Returns
    -------
    vrecho.camera.View
        ``gray`` (H, W) float32 in [0, 1]; ``depth`` (H, W) float32 z-depth in metres, 0 where
        the sensor returns nothing or beyond 10 m; the intrinsics (3, 3) and ``pose``.
    """
    world = World(world) if isinstance(world, Scene) else world
    K = camera.intrinsics
    v, u = np.mgrid[0:camera.height, 0:camera.width]
    rays_cam = np.stack([(u - K[0, 2]) / K[0, 0], (v - K[1, 2]) / K[1, 1], np.ones_like(u, float)], -1).reshape(-1, 3)
    dirs = rays_cam @ pose[:3, :3].T
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    origins = np.broadcast_to(pose[:3, 3], dirs.shape).copy()
    gray = world.trace(origins, dirs)
    rng = world.sensor_range(origins, dirs)
    depth = rng * (dirs @ pose[:3, 2])
    depth[(depth > DEPTH_MAX_M) | (depth <= 0)] = 0.0
    shape = (camera.height, camera.width)
    return View(gray.reshape(shape).astype(np.float32), depth.reshape(shape).astype(np.float32), K, pose)


def crop(world: World | Scene, pose: DevicePose, index: int | None = None, *, shape: tuple[int, int] = CROP_SHAPE,
         margin: float = 0.15) -> np.ndarray:
    """The camera's grayscale crop around a discontinuity (the pose's target by default).

    Rays from the camera through a grid over the discontinuity's rectangle, widened by
    ``margin`` on each side: the perspective view of that region, resampled to ``shape``.

    Parameters
    ----------
    world : World or Scene
        What to look at (a scene is made into a :class:`World` first).
    pose : DevicePose
        The device; the camera is at its microphone.
    index : int, optional
        The discontinuity (the pose's target by default).
    shape : tuple of (int, int)
        Rows and columns of the crop (default (64, 25)).
    margin : float
        Widening on each side, as a fraction of the rectangle's width and height (default 0.15).

    Returns
    -------
    numpy.ndarray [shape=shape, (64, 25) by default], uint8
        The grayscale crop, 0 to 255.

    Raises
    ------
    VrechoError
        If there is no such discontinuity (or the pose has no target and no ``index`` is given).
    """
    world = World(world) if isinstance(world, Scene) else world
    scene = world.scene
    index = pose.target if index is None else index
    if index is None or not 0 <= index < len(scene.discontinuities):
        raise VrechoError(f"crop: no discontinuity {index!r} to look at")
    targets = crop_grid(scene.discontinuity_corners(index), shape, margin)
    origin = pose.camera
    dirs = targets - origin
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    gray = world.trace(np.broadcast_to(origin, dirs.shape).copy(), dirs)
    return np.round(255 * gray.reshape(shape)).astype(np.uint8)
