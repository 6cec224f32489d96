"""Echo-reconstruction: the camera's scan of a room, with its glass and mirror failures.

This first part is the stand-in for the phone's scan: a walkthrough along the scene's camera
path renders grayscale and depth frames with the sensor's failures (it sees through glass and
finds a phantom room behind a mirror), and open3d's TSDF fusion (``VoxelBlockGrid``; the legacy
``ScalableTSDFVolume`` returns empty meshes on open3d 0.20) turns them into a coloured mesh.
"""

from __future__ import annotations

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
