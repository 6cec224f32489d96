"""Echo-reconstruction: the camera's scan of a room, with its glass and mirror failures.

This first part is the stand-in for the phone's scan: a walkthrough along the scene's camera
path renders grayscale and depth frames with the sensor's failures (it sees through glass and
finds a phantom room behind a mirror), and open3d's TSDF fusion (``VoxelBlockGrid``; the legacy
``ScalableTSDFVolume`` returns empty meshes on open3d 0.20) turns them into a coloured mesh.

Then the discontinuities: :func:`wall_planes` finds the room's walls by RANSAC (the nearest plane
to the cameras in each direction, so a phantom room or the street beyond a window is not taken
for a wall), :func:`holes` the empty regions within each and :func:`beyond_walls` the geometry
behind them (seen through glass or an opening, or a mirror's phantom room). The repair (the paper's Algorithm 1)
comes next.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .errors import VrechoError
from .render import DEPTH_MAX_M, Camera, View, World, camera_pose, render_view
from .scene import Scene


def walkthrough(scene: Scene, n_frames: int = 60, camera: Camera = Camera(), progress: bool = False) -> list[View]:
    """Frames rendered along the scene's camera path, evenly spaced in time."""
    from tqdm import tqdm

    if scene.camera_path is None:
        raise VrechoError(f"scene {scene.name!r}: no camera_path to walk")
    if n_frames < 2:
        raise VrechoError(f"n_frames: expected at least 2, got {n_frames}")
    world = World(scene)
    positions, forwards = scene.camera_path.sample(n_frames)
    return [render_view(world, camera_pose(p, f), camera)
            for p, f in tqdm(list(zip(positions, forwards)), desc="render walkthrough", unit="frame",
                             disable=not progress)]


def fuse(views: list[View], voxel_m: float = 0.03, trunc_voxels: float = 4.0, weight_threshold: float = 1.0):
    """TSDF fusion of depth and grayscale frames into a coloured triangle mesh.

    Parameters
    ----------
    views : list of :class:`vrecho.render.View`
    voxel_m : float
        Voxel size in metres.
    trunc_voxels : float
        Truncation distance in voxels.
    weight_threshold : float
        Fewest observations for a surface to be kept.

    Returns
    -------
    open3d.geometry.TriangleMesh
        Legacy mesh, world frame (Z up), vertex colours from the grayscale frames.
    """
    import open3d as o3d
    import open3d.core as o3c

    if not views:
        raise VrechoError("fuse: no frames")
    device = o3c.Device("CPU:0")
    grid = o3d.t.geometry.VoxelBlockGrid(attr_names=("tsdf", "weight", "color"),
                                         attr_dtypes=(o3c.float32, o3c.float32, o3c.float32),
                                         attr_channels=((1), (1), (3)), voxel_size=voxel_m,
                                         block_resolution=16, block_count=50_000, device=device)
    for view in views:
        intrinsic = o3c.Tensor(view.intrinsics, o3c.float64)
        extrinsic = o3c.Tensor(np.linalg.inv(view.pose), o3c.float64)  # world-to-camera
        depth = o3d.t.geometry.Image(o3c.Tensor(np.ascontiguousarray(view.depth, np.float32)))
        color = o3d.t.geometry.Image(o3c.Tensor(np.ascontiguousarray(np.repeat(view.gray[..., None], 3, axis=2),
                                                                     np.float32)))
        blocks = grid.compute_unique_block_coordinates(depth, intrinsic, extrinsic, 1.0, DEPTH_MAX_M,
                                                       trunc_voxels)
        grid.integrate(blocks, depth, color, intrinsic, intrinsic, extrinsic, 1.0, DEPTH_MAX_M, trunc_voxels)
    return grid.extract_triangle_mesh(weight_threshold=weight_threshold).to_legacy()


@dataclass
class Plane:
    """A planar surface found in the scan: unit ``normal`` pointing into the room (toward the
    cameras), ``offset`` (points x with normal . x + offset = 0) and the inlier vertices."""

    normal: np.ndarray
    offset: float
    inliers: np.ndarray  # (M, 3)

    @property
    def vertical(self) -> bool:
        return abs(self.normal[2]) < 0.1

    def frame(self) -> tuple[np.ndarray, np.ndarray]:
        """In-plane unit axes (along the wall, up) of a vertical plane."""
        up = np.array([0.0, 0.0, 1.0])
        along = np.cross(up, self.normal)
        return along / np.linalg.norm(along), up


@dataclass
class Hole:
    """An empty region of a wall plane: its bounding rectangle in the wall's frame (``u`` along
    the wall, ``z`` up, metres), its area and the plane."""

    plane: Plane
    u: tuple[float, float]
    z: tuple[float, float]
    area_m2: float

    def corners(self) -> np.ndarray:
        along, up = self.plane.frame()
        origin = -self.plane.offset * self.plane.normal
        return np.array([origin + a * along + b * up for a, b in
                         ((self.u[0], self.z[0]), (self.u[1], self.z[0]), (self.u[1], self.z[1]), (self.u[0], self.z[1]))])


def wall_planes(vertices: np.ndarray, cameras: np.ndarray, distance_m: float = 0.03, min_share: float = 0.01,
                max_planes: int = 12, seed: int = 0) -> list[Plane]:
    """The room's walls: planes found by RANSAC (open3d ``segment_plane``), one after another, of
    which the vertical ones nearest the cameras in each direction are kept (a phantom room
    behind a mirror, or buildings through a window, lie farther along the same directions)."""
    import open3d as o3d

    o3d.utility.random.seed(seed)
    rest = np.asarray(vertices, float)
    centre = np.asarray(cameras, float).mean(axis=0)
    found = []
    for _ in range(max_planes):
        if len(rest) < max(3, min_share * len(vertices)):
            break
        pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(rest))
        (a, b, c, d), idx = pcd.segment_plane(distance_m, 3, 1000)
        if len(idx) < min_share * len(vertices):
            break
        n = np.array([a, b, c]) / np.linalg.norm([a, b, c])
        d = d / np.linalg.norm([a, b, c])
        if n @ centre + d < 0:  # point the normal at the cameras
            n, d = -n, -d
        found.append(Plane(n, float(d), rest[idx]))
        rest = np.delete(rest, idx, axis=0)
    walls = []
    for p in sorted((p for p in found if p.vertical), key=lambda p: p.normal @ centre + p.offset):
        if all(p.normal @ w.normal < np.cos(np.radians(10)) for w in walls):
            walls.append(p)
    return walls


def holes(plane: Plane, cell_m: float = 0.05, min_area_m2: float = 0.1) -> list[Hole]:
    """Empty regions within the extent of a wall plane's inliers (a raster of ``cell_m`` cells)."""
    from scipy import ndimage

    along, up = plane.frame()
    uz = np.stack([plane.inliers @ along, plane.inliers @ up], axis=1)
    lo = uz.min(axis=0)
    ij = np.floor((uz - lo) / cell_m).astype(int)
    occupied = np.zeros(ij.max(axis=0) + 1, bool)
    occupied[ij[:, 0], ij[:, 1]] = True
    # The wall is the largest connected piece: distant geometry that happens to lie in the same
    # plane (the ground outside, beyond a window) is cut away.
    pieces, _ = ndimage.label(ndimage.binary_dilation(occupied, iterations=2))
    sizes = np.bincount(pieces.ravel())
    sizes[0] = 0
    rows, cols = np.nonzero(pieces == sizes.argmax())
    box = (slice(rows.min(), rows.max() + 1), slice(cols.min(), cols.max() + 1))
    lo = lo + cell_m * np.array([box[0].start, box[1].start])
    occupied = occupied[box] & (pieces[box] == sizes.argmax())
    occupied = ndimage.binary_closing(occupied, iterations=1, border_value=1)
    labels, _ = ndimage.label(~occupied)
    out = []
    for k, sl in enumerate(ndimage.find_objects(labels), start=1):
        area = float((labels[sl] == k).sum()) * cell_m ** 2
        if area < min_area_m2:
            continue
        u0, u1 = lo[0] + sl[0].start * cell_m, lo[0] + sl[0].stop * cell_m
        z0, z1 = lo[1] + sl[1].start * cell_m, lo[1] + sl[1].stop * cell_m
        out.append(Hole(plane, (u0, u1), (z0, z1), area))
    return out


def beyond_walls(vertices: np.ndarray, walls: list[Plane], margin_m: float = 0.1) -> np.ndarray:
    """Which vertices lie more than ``margin_m`` behind a wall plane: what the camera saw through
    glass or an opening, or the phantom room a mirror makes (the repair tells them apart)."""
    v = np.asarray(vertices, float)
    out = np.zeros(len(v), bool)
    for w in walls:
        out |= v @ w.normal + w.offset < -margin_m
    return out
