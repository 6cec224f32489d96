"""The camera: pinhole intrinsics, camera poses, projection and the paper's crops.

Conventions are OpenCV's (x right, y down, z forward); poses are camera-to-world 4 x 4 matrices in
vrecho's world frame (Z up, metres). A :class:`View` is one frame (grayscale, z-depth, intrinsics,
pose), real or simulated (:mod:`vrecho.sim.render` draws them from a scene's truth). The capture
device of a frame (:func:`device_pose`) has its microphone at the camera, 7 cm above the emitter.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.ndimage import map_coordinates

from .errors import VrechoError
from .scene import MIC_ABOVE_EMITTER_M, DevicePose


CROP_SHAPE = (64, 25)
"""Rows x columns of the grayscale crop around a discontinuity (the paper's 64 x 25 image)."""


DEPTH_MAX_M = 10.0


@dataclass(frozen=True)
class Camera:
    """A pinhole camera: image size in pixels and horizontal field of view in degrees."""

    width: int = 320
    height: int = 240
    fov_deg: float = 65.0

    @property
    def intrinsics(self) -> np.ndarray:
        f = 0.5 * self.width / np.tan(np.radians(self.fov_deg) / 2)
        return np.array([[f, 0, (self.width - 1) / 2], [0, f, (self.height - 1) / 2], [0, 0, 1.0]])


@dataclass
class View:
    """One rendered frame: ``gray`` (H, W) in [0, 1], ``depth`` (H, W) z-depth in metres with 0
    where the sensor returns nothing, ``intrinsics`` (3, 3), ``pose`` (4, 4) camera-to-world."""

    gray: np.ndarray
    depth: np.ndarray
    intrinsics: np.ndarray
    pose: np.ndarray


def camera_pose(position, forward, up=(0.0, 0.0, 1.0)) -> np.ndarray:
    """Camera-to-world 4 x 4 matrix (OpenCV axes) at ``position`` looking along ``forward``."""
    f = np.asarray(forward, float)
    f = f / np.linalg.norm(f)
    right = np.cross(f, up)
    if np.linalg.norm(right) < 1e-9:
        raise VrechoError("camera: forward must not be parallel to up")
    right /= np.linalg.norm(right)
    down = np.cross(f, right)
    T = np.eye(4)
    T[:3, :3] = np.stack([right, down, f], axis=1)
    T[:3, 3] = position
    return T


def project(view: View, points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Pixel column, row (floats) and z-depth (metres) of world points (N, 3) in a frame; points
    behind the camera get meaningless pixels (check ``z``)."""
    cam = (np.asarray(points, float) - view.pose[:3, 3]) @ view.pose[:3, :3]
    z = cam[:, 2]
    K = view.intrinsics
    with np.errstate(divide="ignore", invalid="ignore"):
        return K[0, 0] * cam[:, 0] / z + K[0, 2], K[1, 1] * cam[:, 1] / z + K[1, 2], z


def crop_grid(c: np.ndarray, shape: tuple[int, int], margin: float) -> np.ndarray:
    """World points (rows * cols, 3) of a crop of the rectangle ``c``: left to right from u1 to
    u0 (the wall seen from the room), top to bottom from z1 to z0, widened by ``margin``."""
    rows, cols = shape
    a = np.linspace(-margin, 1 + margin, cols)[None, :, None]
    b = np.linspace(1 + margin, -margin, rows)[:, None, None]
    return (c[1] + a * (c[0] - c[1]) + b * (c[3] - c[0])).reshape(-1, 3)


def crop_view(view: View, corners: np.ndarray, *, shape: tuple[int, int] = CROP_SHAPE,
              margin: float = 0.15) -> tuple[np.ndarray, float]:
    """The same crop as :func:`crop`, resampled (bilinearly) from a camera frame: what a real
    capture gives. ``corners`` (4, 3): a wall rectangle wound like the scene's walls, (u0, z0),
    (u1, z0), (u1, z1), (u0, z1). Points outside the frame or behind the camera are black.

    Returns
    -------
    crop : numpy.ndarray, shape (64, 25), uint8
    inside : float
        Share of the crop that lies within the frame (1 when the frame holds all of it).
    """
    col, row, z = project(view, crop_grid(np.asarray(corners, float), shape, margin))
    h, w = view.gray.shape
    ok = (z > 1e-3) & (col >= 0) & (col <= w - 1) & (row >= 0) & (row <= h - 1)
    gray = np.zeros(len(z))
    gray[ok] = map_coordinates(view.gray.astype(np.float64), [row[ok], col[ok]], order=1)
    return np.round(255 * np.clip(gray, 0, 1).reshape(shape)).astype(np.uint8), float(ok.mean())


def mesh_depth(mesh, poses: np.ndarray, intrinsics: np.ndarray, width: int, height: int) -> np.ndarray:
    """Depth frames (N, H, W) float32 of an open3d triangle mesh seen from camera-to-world
    ``poses`` (N, 4, 4) through a pinhole ``intrinsics``: z-depth in metres, 0 where a ray meets
    nothing within :data:`DEPTH_MAX_M`. What a depth sensor reads off a user's mesh: where the
    mesh has a hole the ray goes on to whatever lies beyond it, as the sensor's did."""
    import open3d as o3d  # heavy (1.2 s to import): only where meshes are made or ray-cast

    rc = o3d.t.geometry.RaycastingScene()
    rc.add_triangles(o3d.t.geometry.TriangleMesh.from_legacy(mesh))
    K = o3d.core.Tensor(np.asarray(intrinsics, float))
    out = np.zeros((len(poses), height, width), np.float32)
    for k, pose in enumerate(np.asarray(poses, float)):
        rays = rc.create_rays_pinhole(K, o3d.core.Tensor(np.linalg.inv(pose)), width, height)
        z = rc.cast_rays(rays)["t_hit"].numpy()  # the rays' directions have z = 1 in the camera: t is z-depth
        out[k] = np.where(np.isfinite(z) & (z <= DEPTH_MAX_M), z, 0.0)
    return out


def device_pose(view: View, *, target: int | None = None) -> DevicePose:
    """The capture device of a frame: the camera is its microphone, 7 cm above the emitter."""
    up = -view.pose[:3, 1]  # OpenCV's y axis points down
    return DevicePose(view.pose[:3, 3] - MIC_ABOVE_EMITTER_M * up, view.pose[:3, 2], up, target)
