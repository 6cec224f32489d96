"""Where the device was at each pulse: COLMAP's text model of a capture's pictures (read by
:mod:`vrecho.colmap`) on the recording's clock, poses interpolated at the pulses, and the
:class:`~vrecho.reconstruct.Scan` of the user's mesh seen from them.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation, Slerp

from .. import colmap
from ..camera import View, mesh_depth
from ..errors import VrechoError
from ..reconstruct.scan import Echoes, Scan
from ..signals import FS

VIEW_WIDTH = 320
"""Pictures and depth frames of a posed capture are worked at this width (pixels), as the
simulator's camera: hole carving and EchoCNN's 64 x 25 crop need no more."""


MAX_POSE_GAP_S = 1.0
"""A pulse takes the pose of the pictures around it (interpolated) when one lies this close."""


def interpolate_poses(times, key_times, key_poses, *, max_gap_s: float = MAX_POSE_GAP_S) -> tuple[np.ndarray, np.ndarray]:
    """Camera-to-world poses at ``times`` from posed pictures at ``key_times``: positions linear
    and rotations spherical between the two pictures around each time, or the nearest picture's
    beyond either end.

    Parameters
    ----------
    times : numpy.ndarray [shape=(K,)], float
        The times to pose, in seconds.
    key_times : numpy.ndarray [shape=(P,)], float
        The posed pictures' times in seconds, in any order (one pose is kept per time).
    key_poses : numpy.ndarray [shape=(P, 4, 4)], float
        Their camera-to-world poses (metres).
    max_gap_s : float
        How close, in seconds, a picture must lie for a time to be posed (default
        :data:`MAX_POSE_GAP_S`, 1 s).

    Returns
    -------
    poses : numpy.ndarray [shape=(K, 4, 4)], float
        Camera-to-world poses at ``times``.
    ok : numpy.ndarray [shape=(K,)], bool
        Which times have a picture within ``max_gap_s``; the others get the nearest pose, not
        to be used.

    Examples
    --------
    >>> import numpy as np
    >>> from vrecho.capture import interpolate_poses
    >>> moved = np.eye(4)
    >>> moved[0, 3] = 2.0
    >>> poses, ok = interpolate_poses([0.5, 5.0], [0.0, 1.0], np.stack([np.eye(4), moved]))
    >>> poses[0, :3, 3]
    array([1., 0., 0.])
    >>> ok
    array([ True, False])
    """
    times = np.asarray(times, float)
    order = np.argsort(key_times)
    kt, kp = np.asarray(key_times, float)[order], np.asarray(key_poses, float)[order]
    kt, first = np.unique(kt, return_index=True)  # one pose per time
    kp = kp[first]
    ok = np.min(np.abs(times[:, None] - kt[None]), axis=1) <= max_gap_s if len(times) else np.zeros(0, bool)
    tc = np.clip(times, kt[0], kt[-1])
    out = np.tile(np.eye(4), (len(times), 1, 1))
    if len(kt) == 1:
        out[:] = kp[0]
        return out, ok
    out[:, :3, :3] = Slerp(kt, Rotation.from_matrix(kp[:, :3, :3]))(tc).as_matrix()
    for axis in range(3):
        out[:, axis, 3] = np.interp(tc, kt, kp[:, axis, 3])
    return out, ok


def view_intrinsics(camera, *, width: int = VIEW_WIDTH) -> tuple[np.ndarray, int, int]:
    """A COLMAP camera's pinhole matrix scaled to ``width`` pixels across (pixel centres at
    integers), and the scaled size.

    Parameters
    ----------
    camera : :class:`vrecho.colmap.Camera`
        The camera (distortion left out).
    width : int
        The working width in pixels (default :data:`VIEW_WIDTH`, 320).

    Returns
    -------
    intrinsics : numpy.ndarray [shape=(3, 3)], float
        The pinhole matrix, in pixels at the working size.
    width, height : int
        The working size in pixels (aspect kept, height rounded).
    """
    s = width / camera.width
    K = camera.intrinsics.copy()
    K[:2, :2] *= s
    K[:2, 2] = s * (K[:2, 2] + 0.5) - 0.5
    return K, width, int(round(camera.height * s))


@dataclass
class Poses:
    """A capture's posed pictures (from COLMAP's text model, :mod:`vrecho.colmap`; see
    :func:`read_poses`), in time order.

    Parameters
    ----------
    intrinsics : numpy.ndarray [shape=(3, 3)], float
        The camera's pinhole matrix at the working size, in pixels.
    width, height : int
        The working size in pixels.
    names : list of str
        Each picture's file name.
    time_s : numpy.ndarray [shape=(P,)], float
        Each picture's time on the recording's clock, in seconds.
    pose : numpy.ndarray [shape=(P, 4, 4)], float
        Each picture's camera-to-world pose in a z-up world (metres).
    to_z_up : numpy.ndarray [shape=(4, 4)], float
        Turns the model's world into that one (identity, or a y-up world turned).
    """

    intrinsics: np.ndarray
    width: int
    height: int
    names: list[str]
    time_s: np.ndarray
    pose: np.ndarray
    to_z_up: np.ndarray


def read_poses(folder, image_fps: float, duration_s: float, *, video_start_s: float = 0.0) -> Poses:
    """COLMAP's text model in ``folder`` for a capture of ``duration_s`` seconds, its pictures
    numbered from 1 at ``image_fps`` (:func:`vrecho.colmap.image_times`) from the video's first
    picture, ``video_start_s`` after the sound's start. Checked: one camera, pictures within the
    recording (to 1 s), the cameras upright in a z-up world (a y-up world is turned z up).

    Parameters
    ----------
    folder : str or pathlib.Path
        The folder of COLMAP's ``cameras.txt`` and ``images.txt``.
    image_fps : float
        The rate the pictures were extracted at, in pictures per second.
    duration_s : float
        The recording's length in seconds.
    video_start_s : float
        When the video's first picture shows, in seconds from the sound's start (default 0).

    Returns
    -------
    Poses
        The pictures in time order, their intrinsics at :data:`VIEW_WIDTH`.

    Raises
    ------
    VrechoError
        For a model :func:`vrecho.colmap.read_model` cannot read, an ``image_fps`` that is not
        above 0 and at most 1000, or a picture name without a number; for a camera more than 10
        times as wide as high (or the reverse); when the pictures use more than one camera, lie
        outside the recording, or the cameras' up axes point neither along the world's z nor
        its y.
    """
    cameras, images = colmap.read_model(folder)
    used = {im.camera_id for im in images}
    if len({(cameras[c].model, cameras[c].width, cameras[c].height, tuple(cameras[c].params)) for c in used}) > 1:
        raise VrechoError(f"poses: the images use {len(used)} different cameras; expected the one camera of a video "
                          "(COLMAP: --ImageReader.single_camera 1)")
    K, w, h = view_intrinsics(cameras[images[0].camera_id])
    if not w / 10 <= h <= 10 * w:
        raise VrechoError(f"poses: the camera's pictures are {cameras[images[0].camera_id].width} x "
                          f"{cameras[images[0].camera_id].height} pixels; expected a video's (at most 10 times as "
                          "high as wide, and 10 times as wide as high)")
    names = [im.name for im in images]
    times = colmap.image_times(names, image_fps) + video_start_s
    if times.max() > duration_s + 1.0 or times.min() < -1.0:
        raise VrechoError(f"poses do not match the recording: images.txt's pictures lie at {times.min():.1f} to "
                          f"{times.max():.1f} s (numbered at --image-fps {image_fps:g}), the recording lasts "
                          f"{duration_s:.1f} s; expected the poses of this video's pictures and their extraction rate")
    pose = np.stack([im.pose for im in images])
    up = np.median(-pose[:, :3, 1], axis=0)  # OpenCV's y points down
    to_z_up = np.eye(4)
    if up[1] >= np.cos(np.radians(45)):  # a y-up world (ARKit's, OpenGL's): turned z up
        to_z_up[:3, :3] = [[1, 0, 0], [0, 0, -1], [0, 1, 0]]
        pose = to_z_up @ pose
    elif up[2] < np.cos(np.radians(45)):
        raise VrechoError(f"poses: the cameras' up axes point {np.round(up, 2).tolist()}, up neither the world's z nor "
                          "its y; expected a metric model with gravity along -z or -y (a phone's tracked poses, or "
                          "a COLMAP model scaled and levelled with `colmap model_aligner`)")
    order = np.argsort(times, kind="stable")
    return Poses(K, w, h, [names[k] for k in order], times[order], pose[order], to_z_up)


def posed_scan(mesh, poses: Poses, pictures: np.ndarray, frames: np.ndarray, frame_times: np.ndarray,
               frame_pictures: np.ndarray, emitted: np.ndarray, *, min_hit: float = 0.3):
    """A :class:`~vrecho.reconstruct.Scan` of a user's mesh and capture: one view per posed
    picture and one per pulse frame (the pose interpolated at its emission), each with the depth
    the mesh gives along its rays (:func:`~vrecho.camera.mesh_depth`) and its picture (uint8 at
    the working size), and the pulses' frames as its echoes. Pulses with no posed picture within
    :data:`MAX_POSE_GAP_S` are left out.

    Parameters
    ----------
    mesh : open3d.geometry.TriangleMesh
        The user's mesh, in the poses' z-up world (metres).
    poses : Poses
        The posed pictures (:func:`read_poses`).
    pictures : numpy.ndarray [shape=(P, H, W)], uint8
        The posed pictures at the working size, in the order of ``poses``.
    frames : numpy.ndarray [shape=(K, 44100)], float32
        The pulses' 1 s frames at 44.1 kHz (:func:`~.onsets.cut_frames`).
    frame_times : numpy.ndarray [shape=(K,)], float
        Each frame's time on the recording's clock, in seconds.
    frame_pictures : numpy.ndarray [shape=(K, H, W)], uint8
        The picture at each frame, at the working size.
    emitted : numpy.ndarray [shape=(k,)], float
        The probe played, at 44.1 kHz.
    min_hit : float
        Smallest share of the pulse views' pixels whose ray must meet the mesh (default 0.3).

    Returns
    -------
    scan : :class:`~vrecho.reconstruct.Scan`
        The P posed pictures' views, then one view per pulse kept; its :class:`Echoes` name
        the pulse views (indices P onward) at 44.1 kHz.
    ok : numpy.ndarray [shape=(K,)], bool
        Which frames the scan holds.

    Raises
    ------
    VrechoError
        When no pulse lies within :data:`MAX_POSE_GAP_S` of a posed picture; when less than
        ``min_hit`` of what the camera sees at the pulses meets the mesh; and when the
        pictures' size is not the camera's at the working width.
    """
    pulse_pose, ok = interpolate_poses(frame_times, poses.time_s, poses.pose)
    if not ok.any():
        raise VrechoError(f"poses do not match the recording: no pulse ({len(frame_times)} from "
                          f"{frame_times.min():.1f} to {frame_times.max():.1f} s) lies within {MAX_POSE_GAP_S:g} s of "
                          f"a posed picture ({poses.time_s.min():.1f} to {poses.time_s.max():.1f} s)")
    all_pose = np.concatenate([poses.pose, pulse_pose[ok]])
    depth = mesh_depth(mesh, all_pose, poses.intrinsics, poses.width, poses.height)
    hit = float(np.mean(depth[len(poses.pose):] > 0))
    if hit < min_hit:
        raise VrechoError(f"mesh: only {hit:.0%} of what the camera sees at the pulses meets the mesh; expected the "
                          "surfaces in view (the mesh and images.txt in one world frame, metric, z up)")
    gray = np.concatenate([pictures, frame_pictures[ok]]).astype(np.float32) / 255
    if gray.shape[1:] != depth.shape[1:]:
        raise VrechoError(f"images: pictures of {gray.shape[2]} x {gray.shape[1]} pixels at the working width, the "
                          f"camera's are {poses.width} x {poses.height}: cameras.txt is not this video's camera")
    views = [View(g, d, poses.intrinsics, p) for g, d, p in zip(gray, depth, all_pose)]
    n = len(poses.pose)
    echoes = Echoes(np.arange(n, n + int(ok.sum())), frames[ok], FS, np.asarray(emitted, float))
    return Scan(views, mesh, echoes), ok
