"""The camera: pinhole intrinsics, camera poses, projection, the paper's crops and walkthrough paths.

Conventions are OpenCV's (x right, y down, z forward); poses are camera-to-world 4 x 4 matrices in
vrecho's world frame (Z up, metres). A :class:`View` is one frame (grayscale, z-depth, intrinsics,
pose), real or simulated (:mod:`vrecho.sim.render` draws them from a scene's truth). The capture
device of a frame (:func:`device_pose`) has its microphone at the camera, 7 cm above the emitter.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.interpolate import CubicSpline
from scipy.ndimage import map_coordinates

from .device import MIC_ABOVE_EMITTER_M, REACH_M, DevicePose
from .errors import VrechoError, check_field, check_keys, check_list, check_number, check_vector

CROP_SHAPE = (64, 25)
"""Rows x columns of the grayscale crop around a discontinuity (the paper's 64 x 25 image)."""


DEPTH_MAX_M = 10.0

MAX_KEYFRAMES = 1000
"""The most keyframes of a :class:`CameraPath`."""
DURATION_S = (0.1, 3600.0)
"""A walk's length range, in seconds."""


@dataclass(frozen=True)
class Camera:
    """A pinhole camera: image size in pixels and horizontal field of view in degrees.

    Parameters
    ----------
    width : int
        Image width in pixels; 320 by default.
    height : int
        Image height in pixels; 240 by default.
    fov_deg : float
        Horizontal field of view in degrees; 65 by default.

    Examples
    --------
    >>> Camera().intrinsics[:, 2]
    array([159.5, 119.5,   1. ])
    """

    width: int = 320
    height: int = 240
    fov_deg: float = 65.0

    @property
    def intrinsics(self) -> np.ndarray:
        """The pinhole matrix (3, 3) in pixels, principal point at the image centre."""
        f = 0.5 * self.width / np.tan(np.radians(self.fov_deg) / 2)
        return np.array([[f, 0, (self.width - 1) / 2], [0, f, (self.height - 1) / 2], [0, 0, 1.0]])


@dataclass
class View:
    """One rendered frame: grayscale image, z-depth, intrinsics and camera pose.

    Parameters
    ----------
    gray : numpy.ndarray, shape (H, W), float
        Grayscale image in [0, 1].
    depth : numpy.ndarray, shape (H, W), float
        z-depth in metres, with 0 where the sensor returns nothing.
    intrinsics : numpy.ndarray, shape (3, 3), float
        Pinhole matrix in pixels (pixel centres at integers).
    pose : numpy.ndarray, shape (4, 4), float
        Camera-to-world matrix, OpenCV axes, metres.
    """

    gray: np.ndarray
    depth: np.ndarray
    intrinsics: np.ndarray
    pose: np.ndarray


def camera_pose(position, forward, up=(0.0, 0.0, 1.0)) -> np.ndarray:
    """Camera-to-world 4 x 4 matrix (OpenCV axes) at ``position`` looking along ``forward``.

    The camera's x axis (right) is ``forward`` x ``up``, its y axis (down) ``forward`` x right:
    the image is upright with respect to ``up``.

    Parameters
    ----------
    position : array_like, shape (3,), float
        Camera centre in the world frame, in metres.
    forward : array_like, shape (3,), float
        Viewing direction (the camera's z axis); any length.
    up : array_like, shape (3,), float
        The world direction that shows as up in the image; +Z by default.

    Returns
    -------
    numpy.ndarray, shape (4, 4), float64
        Columns right, down, forward (unit) and the position, over (0, 0, 0, 1).

    Raises
    ------
    VrechoError
        If ``forward`` is parallel to ``up``.

    Examples
    --------
    >>> T = camera_pose((1.0, 2.0, 1.5), (0.0, 1.0, 0.0))
    >>> T[:3, 2]
    array([0., 1., 0.])
    >>> T[:3, 3]
    array([1. , 2. , 1.5])
    """
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
    """Pixel column, row (floats) and z-depth (metres) of world points in a frame.

    Points behind the camera get meaningless pixels (check ``z``).

    Parameters
    ----------
    view : View
        The frame; its ``pose`` and ``intrinsics`` are used.
    points : array_like, shape (N, 3), float
        World points, in metres.

    Returns
    -------
    col, row : numpy.ndarray, shape (N,), float64
        Pixel coordinates (pixel centres at integers); not finite where ``z`` is 0.
    z : numpy.ndarray, shape (N,), float64
        z-depth in metres in the camera frame; negative behind the camera.
    """
    cam = (np.asarray(points, float) - view.pose[:3, 3]) @ view.pose[:3, :3]
    z = cam[:, 2]
    K = view.intrinsics
    with np.errstate(divide="ignore", invalid="ignore"):
        return K[0, 0] * cam[:, 0] / z + K[0, 2], K[1, 1] * cam[:, 1] / z + K[1, 2], z


def crop_grid(c: np.ndarray, shape: tuple[int, int], margin: float) -> np.ndarray:
    """World points of a crop of the rectangle ``c``, in image order (row by row).

    Left to right from u1 to u0 (the wall seen from the room), top to bottom from z1 to z0,
    widened by ``margin``.

    Parameters
    ----------
    c : numpy.ndarray, shape (4, 3), float
        The rectangle's world corners in metres, (u0, z0), (u1, z0), (u1, z1), (u0, z1), as
        :meth:`vrecho.scene.Scene.discontinuity_corners` gives them.
    shape : tuple of int
        Rows and columns of the crop.
    margin : float
        Widening on each side, as a fraction of the rectangle's width and height.

    Returns
    -------
    numpy.ndarray, shape (rows * cols, 3), float64
        World points in metres.
    """
    rows, cols = shape
    a = np.linspace(-margin, 1 + margin, cols)[None, :, None]
    b = np.linspace(1 + margin, -margin, rows)[:, None, None]
    return (c[1] + a * (c[0] - c[1]) + b * (c[3] - c[0])).reshape(-1, 3)


def crop_view(view: View, corners: np.ndarray, *, shape: tuple[int, int] = CROP_SHAPE,
              margin: float = 0.15) -> tuple[np.ndarray, float]:
    """The same crop as :func:`vrecho.sim.render.crop`, resampled (bilinearly) from a camera
    frame: what a real capture gives.

    Points outside the frame or behind the camera are black.

    Parameters
    ----------
    view : View
        The camera frame.
    corners : array_like, shape (4, 3), float
        A wall rectangle in metres, wound like the scene's walls, (u0, z0), (u1, z0), (u1, z1),
        (u0, z1).
    shape : tuple of int
        Rows and columns of the crop; :data:`CROP_SHAPE` (64, 25) by default.
    margin : float
        Widening on each side, as a fraction of the rectangle's width and height; 0.15 by
        default.

    Returns
    -------
    crop : numpy.ndarray, shape (64, 25), uint8
        The grayscale crop (``shape`` when given).
    inside : float
        Share of the crop that lies within the frame, in front of the camera (1 when the frame
        holds all of it).
    """
    col, row, z = project(view, crop_grid(np.asarray(corners, float), shape, margin))
    h, w = view.gray.shape
    ok = (z > 1e-3) & (col >= 0) & (col <= w - 1) & (row >= 0) & (row <= h - 1)
    gray = np.zeros(len(z))
    gray[ok] = map_coordinates(view.gray.astype(np.float64), [row[ok], col[ok]], order=1)
    return np.round(255 * np.clip(gray, 0, 1).reshape(shape)).astype(np.uint8), float(ok.mean())


def mesh_depth(mesh, poses: np.ndarray, intrinsics: np.ndarray, width: int, height: int) -> np.ndarray:
    """Depth frames of an open3d triangle mesh seen from camera-to-world poses.

    What a depth sensor reads off a user's mesh: where the mesh has a hole the ray goes on to
    whatever lies beyond it, as the sensor's did.

    Parameters
    ----------
    mesh : open3d.geometry.TriangleMesh
        The mesh, in metres (as :func:`vrecho.io.read_mesh` gives it).
    poses : numpy.ndarray, shape (N, 4, 4), float
        Camera-to-world matrices, OpenCV axes, metres.
    intrinsics : numpy.ndarray, shape (3, 3), float
        Pinhole matrix in pixels.
    width, height : int
        Image size in pixels.

    Returns
    -------
    numpy.ndarray, shape (N, H, W), float32
        z-depth in metres, 0 where a ray meets nothing within :data:`DEPTH_MAX_M` (10 m).
    """
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
    """The capture device of a frame: the camera is its microphone, 7 cm above the emitter.

    Parameters
    ----------
    view : View
        The frame; only its ``pose`` is used.
    target : int, optional
        Index of the discontinuity the device faces; None by default.

    Returns
    -------
    vrecho.scene.DevicePose
        Emitter 7 cm below the camera along the image's up axis, forward along the camera's
        optical axis.
    """
    up = -view.pose[:3, 1]  # OpenCV's y axis points down
    return DevicePose(view.pose[:3, 3] - MIC_ABOVE_EMITTER_M * up, view.pose[:3, 2], up, target)


@dataclass
class CameraPath:
    """A smooth walkthrough (cubic splines) through keyframes.

    Parameters
    ----------
    positions, look_at : array_like [shape=(K, 3)]
        Keyframe camera positions and the points they look at, K >= 2, in metres.
    duration_s : float
        Length of the walk in seconds; 30 by default.

    Raises
    ------
    VrechoError
        For other shapes, more than :data:`MAX_KEYFRAMES`, a coordinate beyond :data:`REACH_M`,
        a walk whose camera looks at a point within 1 cm of itself (no direction: checked at the
        keyframes and 15 points between each two), or a duration outside :data:`DURATION_S`.
    """

    positions: np.ndarray
    look_at: np.ndarray
    duration_s: float = 30.0

    def __post_init__(self):
        try:
            self.positions = np.asarray(self.positions, dtype=float)
            self.look_at = np.asarray(self.look_at, dtype=float)
        except (TypeError, ValueError):
            raise VrechoError("camera_path: expected lists of [x, y, z] keyframes") from None
        if self.positions.ndim != 2 or self.positions.shape[1] != 3 or not 2 <= len(self.positions) <= MAX_KEYFRAMES:
            raise VrechoError(f"camera_path.positions: expected 2 to {MAX_KEYFRAMES} [x, y, z] keyframes, "
                              f"got shape {self.positions.shape}")
        if self.look_at.shape != self.positions.shape:
            raise VrechoError("camera_path.look_at: expected one look-at point per keyframe")
        for name, v in (("positions", self.positions), ("look_at", self.look_at)):
            if not (np.all(np.isfinite(v)) and np.abs(v).max() <= REACH_M):
                raise VrechoError(f"camera_path.{name}: coordinates must be finite, from {-REACH_M:g} to {REACH_M:g} m")
        t = np.linspace(0.0, 1.0, 16 * (len(self.positions) - 1) + 1)  # the keyframes and 15 points between each two
        pos, tgt = self._track(t)
        near = np.linalg.norm(tgt - pos, axis=1) < 0.01
        if near.any():
            raise VrechoError(f"camera_path.look_at: the camera looks at a point within 1 cm of itself at "
                              f"{100 * t[np.argmax(near)]:.1f}% of the walk; no direction to look")
        self.duration_s = check_number(self.duration_s, "camera_path.duration_s", lo=DURATION_S[0], hi=DURATION_S[1])

    def sample(self, n: int) -> tuple[np.ndarray, np.ndarray]:
        """Evenly spaced points of the walk.

        Parameters
        ----------
        n : int
            How many.

        Returns
        -------
        positions, forward : numpy.ndarray [shape=(n, 3)]
            Camera positions (metres) and unit forward axes, from start to end.
        """
        return self.at(np.linspace(0.0, 1.0, n))

    def at(self, t) -> tuple[np.ndarray, np.ndarray]:
        """Points of the walk at given fractions of it.

        Parameters
        ----------
        t : array_like [shape=(n,)]
            Fractions of the walk, 0 (start) to 1 (end); clipped to that range.

        Returns
        -------
        positions, forward : numpy.ndarray [shape=(n, 3)]
            Camera positions (metres) and unit forward axes.
        """
        pos, tgt = self._track(np.clip(np.asarray(t, float), 0.0, 1.0))
        fwd = tgt - pos
        return pos, fwd / np.linalg.norm(fwd, axis=1, keepdims=True)

    def _track(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Camera positions and the points they look at (n, 3) at fractions ``t`` of the walk."""
        k = np.linspace(0.0, 1.0, len(self.positions))
        bc = "natural" if len(k) > 2 else "not-a-knot"
        return CubicSpline(k, self.positions, bc_type=bc)(t), CubicSpline(k, self.look_at, bc_type=bc)(t)

    def to_dict(self) -> dict:
        """The path's JSON form.

        Returns
        -------
        dict
            ``positions``, ``look_at``, ``duration_s``.
        """
        return {"positions": self.positions.tolist(), "look_at": self.look_at.tolist(), "duration_s": self.duration_s}

    @classmethod
    def from_dict(cls, d, where: str = "camera_path") -> "CameraPath":
        """A path from its JSON form.

        Parameters
        ----------
        d : dict
            As :meth:`to_dict` writes it; ``duration_s`` 30 if absent.
        where : str
            Where ``d`` sits in its file, named by errors; ``"camera_path"`` by default.

        Returns
        -------
        CameraPath
        """
        check_keys(d, ("positions", "look_at", "duration_s"), where)
        points = {}
        for key in ("positions", "look_at"):
            found = check_list(check_field(d, key, where), f"{where}.{key}", lo=2, hi=MAX_KEYFRAMES)
            points[key] = np.array([check_vector(p, f"{where}.{key}[{i}]", lo=-REACH_M, hi=REACH_M)
                                    for i, p in enumerate(found)])
        return cls(points["positions"], points["look_at"],
                   check_number(check_field(d, "duration_s", where, 30.0), f"{where}.duration_s",
                                lo=DURATION_S[0], hi=DURATION_S[1]))
