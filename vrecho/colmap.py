"""Camera poses in COLMAP's text format (``cameras.txt``, ``images.txt``), read and written.

COLMAP's text model (https://colmap.github.io/format.html) is two small files, parsed here
rather than with pycolmap (a large binary wheel for two text files):

``cameras.txt``
    One line per camera: ``CAMERA_ID MODEL WIDTH HEIGHT PARAMS[]``. vrecho reads the pinhole
    part of SIMPLE_PINHOLE (f, cx, cy), PINHOLE (fx, fy, cx, cy), SIMPLE_RADIAL and RADIAL
    (f, cx, cy, k...) and OPENCV (fx, fy, cx, cy, k1, k2, p1, p2); lens distortion is ignored
    (a phone's is small; for exact pictures run ``colmap image_undistorter`` first and give its
    model and images). Fisheye models are refused.
``images.txt``
    Two lines per image: ``IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID NAME`` and its 2-D points
    (ignored; the line may be empty). The quaternion and translation map world to camera
    (x_cam = R x_world + t); the camera's axes are OpenCV's (x right, y down, z forward), as in
    :class:`vrecho.camera.View`.

vrecho's world is metric with z up (PROTOCOL.md): a model from a phone's tracking (ARKit,
ARCore, and the apps that export their poses as COLMAP text) is; a COLMAP reconstruction from
pictures alone must first be scaled and levelled (``colmap model_aligner``).
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from .errors import VrechoError

PINHOLE_PARAMS = {"SIMPLE_PINHOLE": 3, "PINHOLE": 4, "SIMPLE_RADIAL": 4, "RADIAL": 5, "OPENCV": 8}
"""The camera models vrecho reads, with their number of parameters."""


@dataclass
class Camera:
    """A COLMAP camera.

    Parameters
    ----------
    model : str
        COLMAP's camera model, one of :data:`PINHOLE_PARAMS`.
    width, height : int
        Image size in pixels.
    params : numpy.ndarray, shape (p,), float
        The model's parameters in COLMAP's order (focal lengths and principal point in pixels,
        then distortion), p as :data:`PINHOLE_PARAMS` says.
    """

    model: str
    width: int
    height: int
    params: np.ndarray

    @property
    def intrinsics(self) -> np.ndarray:
        """The pinhole matrix (3, 3), pixels (distortion left out). COLMAP puts pixel centres at
        half-integers (the image's corner is 0, 0); vrecho at integers, hence the half pixel."""
        p = self.params
        fx, fy, cx, cy = (p[0], p[0], p[1], p[2]) if self.model in ("SIMPLE_PINHOLE", "SIMPLE_RADIAL", "RADIAL") \
            else (p[0], p[1], p[2], p[3])
        return np.array([[fx, 0, cx - 0.5], [0, fy, cy - 0.5], [0, 0, 1.0]])


@dataclass
class Image:
    """A posed picture.

    Parameters
    ----------
    name : str
        Its file name, as ``images.txt`` gives it.
    camera_id : int
        Id of its :class:`Camera`.
    pose : numpy.ndarray, shape (4, 4), float64
        Camera-to-world matrix, OpenCV axes, in the model's units (metres in vrecho's world).
    """

    name: str
    camera_id: int
    pose: np.ndarray


def _lines(path: Path) -> list[str]:
    if not path.is_file():
        raise VrechoError(f"poses: {path.parent} has no {path.name} (expected COLMAP's text model: cameras.txt and "
                          "images.txt; convert a binary model with `colmap model_converter --output_type TXT`)")
    return [line.strip() for line in path.read_text().splitlines() if not line.startswith("#")]


def quaternion_matrix(q) -> np.ndarray:
    """Rotation matrix of a quaternion (w, x, y, z), normalised first.

    Parameters
    ----------
    q : array_like, shape (4,), float
        The quaternion, scalar first (COLMAP's order); not zero.

    Returns
    -------
    numpy.ndarray, shape (3, 3), float64
        The rotation matrix.

    Examples
    --------
    >>> quaternion_matrix([2.0, 0.0, 0.0, 0.0])
    array([[1., 0., 0.],
           [0., 1., 0.],
           [0., 0., 1.]])
    """
    w, x, y, z = np.asarray(q, float) / np.linalg.norm(q)
    return Rotation.from_quat([x, y, z, w]).as_matrix()


def read_model(folder: str | Path) -> tuple[dict[int, Camera], list[Image]]:
    """COLMAP's ``cameras.txt`` and ``images.txt`` in ``folder``: the cameras by id, and the
    images in the file's order.

    Lines starting with ``#`` are comments; in ``images.txt`` only lines of exactly ten fields
    are read as image headers (points lines are skipped).

    Parameters
    ----------
    folder : str or pathlib.Path
        The folder of COLMAP's text model.

    Returns
    -------
    cameras : dict of int to Camera
        The cameras by id.
    images : list of Image
        The images in the file's order, their poses camera-to-world.

    Raises
    ------
    VrechoError
        For a missing file, a malformed line, an unsupported camera model (or a wrong number of
        its parameters), an image of an unknown camera, an image without a valid pose, or an
        ``images.txt`` with no image.
    """
    folder = Path(folder)
    cameras = {}
    for line in _lines(folder / "cameras.txt"):
        if not line:
            continue
        t = line.split()
        try:
            cid, model, width, height, params = int(t[0]), t[1], int(t[2]), int(t[3]), np.array(t[4:], float)
        except (IndexError, ValueError):
            raise VrechoError(f"poses: cameras.txt: cannot read {line!r}; expected CAMERA_ID MODEL WIDTH HEIGHT PARAMS")
        if model not in PINHOLE_PARAMS:
            raise VrechoError(f"poses: camera {cid} is {model}; vrecho reads {', '.join(PINHOLE_PARAMS)} "
                              "(undistort fisheye pictures with `colmap image_undistorter` first)")
        if len(params) != PINHOLE_PARAMS[model]:
            raise VrechoError(f"poses: camera {cid} ({model}) has {len(params)} parameters, expected "
                              f"{PINHOLE_PARAMS[model]}")
        cameras[cid] = Camera(model, width, height, params)
    images = []
    # An image's header has exactly ten fields; its points line has a multiple of three (or none).
    for line in _lines(folder / "images.txt"):
        t = line.split()
        if len(t) != 10:
            continue
        try:
            q, tr, cid = np.array(t[1:5], float), np.array(t[5:8], float), int(t[8])
        except ValueError:
            raise VrechoError(f"poses: images.txt: cannot read {line!r}; expected IMAGE_ID QW QX QY QZ TX TY TZ "
                              "CAMERA_ID NAME")
        if cid not in cameras:
            raise VrechoError(f"poses: image {t[9]} names camera {cid}, which cameras.txt lacks")
        if not np.all(np.isfinite(np.r_[q, tr])) or np.linalg.norm(q) < 1e-9:
            raise VrechoError(f"poses: image {t[9]} has no valid pose ({' '.join(t[1:8])})")
        r = quaternion_matrix(q)
        pose = np.eye(4)
        pose[:3, :3], pose[:3, 3] = r.T, -r.T @ tr
        images.append(Image(t[9], cid, pose))
    if not images:
        raise VrechoError(f"poses: {folder / 'images.txt'} holds no image")
    return cameras, images


def write_model(folder: str | Path, camera: Camera, names: list[str], poses: np.ndarray) -> Path:
    """Write one camera and the images ``names`` at camera-to-world ``poses`` as COLMAP's text
    model (no 2-D points): how a phone app exports its tracked poses.

    The camera gets id 1 and the images ids 1 to N, in order. Existing ``cameras.txt`` and
    ``images.txt`` are overwritten.

    Parameters
    ----------
    folder : str or pathlib.Path
        The folder to write in; created with its parents if needed.
    camera : Camera
        The one camera of every image.
    names : list of str
        The images' file names.
    poses : numpy.ndarray, shape (N, 4, 4), float
        Camera-to-world matrices, OpenCV axes, metres.

    Returns
    -------
    pathlib.Path
        ``folder``, as a ``Path``.
    """
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "cameras.txt").write_text(
        "# Camera list with one line of data per camera:\n#   CAMERA_ID, MODEL, WIDTH, HEIGHT, PARAMS[]\n"
        f"1 {camera.model} {camera.width} {camera.height} {' '.join(f'{p:.10g}' for p in camera.params)}\n")
    lines = ["# Image list with two lines of data per image:",
             "#   IMAGE_ID, QW, QX, QY, QZ, TX, TY, TZ, CAMERA_ID, NAME", "#   POINTS2D[] as (X, Y, POINT3D_ID)"]
    for k, (name, pose) in enumerate(zip(names, poses), start=1):
        r = pose[:3, :3].T
        x, y, z, w = Rotation.from_matrix(r).as_quat()
        t = -r @ pose[:3, 3]
        lines += [f"{k} {w:.12g} {x:.12g} {y:.12g} {z:.12g} {t[0]:.12g} {t[1]:.12g} {t[2]:.12g} 1 {name}", ""]
    (folder / "images.txt").write_text("\n".join(lines) + "\n")
    return folder


def pinhole(K: np.ndarray, width: int, height: int) -> Camera:
    """The PINHOLE camera of a vrecho intrinsics matrix (pixel centres at integers).

    Parameters
    ----------
    K : numpy.ndarray, shape (3, 3), float
        vrecho's pinhole matrix, in pixels.
    width, height : int
        Image size in pixels.

    Returns
    -------
    Camera
        A PINHOLE camera whose :attr:`Camera.intrinsics` give ``K`` back (skew is dropped).
    """
    return Camera("PINHOLE", width, height, np.array([K[0, 0], K[1, 1], K[0, 2] + 0.5, K[1, 2] + 0.5]))


def image_times(names: list[str], fps: float, *, first: int = 1) -> np.ndarray:
    """Each picture's time in the video (s), from the last number in its file name: pictures
    extracted at ``fps`` per second and numbered from ``first`` (``ffmpeg -i capture.mp4 -vf
    fps=2 images/%06d.png`` numbers from 1 at 2 per second: picture k shows time (k - 1) / 2).

    Parameters
    ----------
    names : list of str
        The pictures' file names.
    fps : float
        Pictures per second of video; positive.
    first : int
        Number of the first picture; 1 by default.

    Returns
    -------
    numpy.ndarray, shape (len(names),), float64
        Each picture's time in seconds.

    Raises
    ------
    VrechoError
        If ``fps`` is not positive, or a name holds no number.

    Examples
    --------
    >>> image_times(["images/000001.png", "images/000004.png"], 2.0)
    array([0. , 1.5])
    """
    if not fps > 0:
        raise VrechoError(f"image-fps: expected a positive rate, got {fps}")
    out = []
    for name in names:
        m = re.findall(r"\d+", Path(name).stem)
        if not m:
            raise VrechoError(f"poses: image {name!r} has no frame number in its name; expected pictures numbered "
                              "as ffmpeg writes them (images/%06d.png)")
        out.append((int(m[-1]) - first) / fps)
    return np.array(out)
