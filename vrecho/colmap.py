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
from .io import MAX_COORDINATE_M

PINHOLE_PARAMS = {"SIMPLE_PINHOLE": 3, "PINHOLE": 4, "SIMPLE_RADIAL": 4, "RADIAL": 5, "OPENCV": 8}
"""The camera models vrecho reads, with their number of parameters."""
MAX_IMAGE_SIDE = 100_000
"""Largest width or height of a camera's pictures, in pixels."""


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


MAX_MODEL_BYTES = 1 << 28
"""Largest ``cameras.txt`` or ``images.txt`` read (256 MiB: some 500 000 images' points)."""


def _lines(path: Path) -> list[tuple[int, str]]:
    """The lines of a model's text file, numbered from 1, stripped, comments left out."""
    if not path.is_file():
        raise VrechoError(f"poses: {path.parent} has no {path.name} (expected COLMAP's text model: cameras.txt and "
                          "images.txt; convert a binary model with `colmap model_converter --output_type TXT`)")
    try:
        if path.stat().st_size > MAX_MODEL_BYTES:
            raise VrechoError(f"poses: {path} is larger than {MAX_MODEL_BYTES >> 20} MiB; expected COLMAP's text model")
        data = path.read_bytes()
        text = data.decode("utf-8")
    except OSError as e:
        raise VrechoError(f"poses: {path}: cannot read it ({e.strerror or e})") from None
    except UnicodeDecodeError as e:
        line = data[:e.start].count(b"\n") + 1
        raise VrechoError(f"poses: {path}: line {line} is not text (UTF-8); expected COLMAP's text model (convert a "
                          "binary one with `colmap model_converter --output_type TXT`)") from None
    return [(n, line.strip()) for n, line in enumerate(text.split("\n"), start=1)
            if not line.lstrip().startswith("#")]


def _whole(token: str, where: str) -> int:
    """A COLMAP id or size: a whole number written in at most 10 ASCII digits."""
    if not (token.isascii() and token.isdigit() and len(token) <= 10):
        raise VrechoError(f"{where}: expected a whole number, got {token[:40]!r}")
    return int(token)


def _numbers(tokens: list[str], where: str) -> np.ndarray:
    """Finite numbers written as text (Python's float syntax less its infinities and NaN)."""
    try:
        x = np.array([float(t) for t in tokens])
    except ValueError:
        raise VrechoError(f"{where}: expected numbers, got {' '.join(tokens)[:80]!r}") from None
    if not np.all(np.isfinite(x)):
        raise VrechoError(f"{where}: expected finite numbers, got {' '.join(tokens)[:80]!r}")
    return x


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
    q = np.asarray(q, float)
    q = q / np.abs(q).max()  # first to the largest: a norm of huge numbers overflows
    w, x, y, z = q / np.linalg.norm(q)
    return Rotation.from_quat([x, y, z, w]).as_matrix()


def read_model(folder: str | Path) -> tuple[dict[int, Camera], list[Image]]:
    """COLMAP's ``cameras.txt`` and ``images.txt`` in ``folder``: the cameras by id, and the
    images in the file's order.

    Lines starting with ``#`` are comments; in ``images.txt`` only lines of exactly ten fields
    are read as image headers, and lines of a multiple of three right after a header (an image's
    2-D points, or none) are skipped unread; such a line anywhere else is refused.

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
        Naming the file and line: for a missing or unreadable file (not UTF-8 text, or over
        :data:`MAX_MODEL_BYTES`), a malformed line (a field that is not a whole number where an
        id or size is due, or not a finite number), an unsupported camera model (or a wrong
        number of its parameters), a camera's size outside 1 to :data:`MAX_IMAGE_SIDE` pixels or
        a focal length not positive, a camera id or an image id or name given twice, an image of
        an unknown camera, an image name with control characters, an image without a valid pose
        (a zero quaternion, a translation beyond :data:`vrecho.io.MAX_COORDINATE_M`), or an
        ``images.txt`` with no image.
    """
    folder = Path(folder)
    cameras = {}
    for n, line in _lines(folder / "cameras.txt"):
        if not line:
            continue
        where, t = f"poses: {folder / 'cameras.txt'}, line {n}", line.split()
        if len(t) < 5:
            raise VrechoError(f"{where}: cannot read {line[:80]!r}; expected CAMERA_ID MODEL WIDTH HEIGHT PARAMS")
        cid, model = _whole(t[0], f"{where}, CAMERA_ID"), t[1]
        width, height = _whole(t[2], f"{where}, WIDTH"), _whole(t[3], f"{where}, HEIGHT")
        if model not in PINHOLE_PARAMS:
            raise VrechoError(f"{where}: camera {cid} is {model[:40]}; vrecho reads {', '.join(PINHOLE_PARAMS)} "
                              "(undistort fisheye pictures with `colmap image_undistorter` first)")
        params = _numbers(t[4:], f"{where}, PARAMS")
        if len(params) != PINHOLE_PARAMS[model]:
            raise VrechoError(f"{where}: camera {cid} ({model}) has {len(params)} parameters, expected "
                              f"{PINHOLE_PARAMS[model]}")
        if cid in cameras:
            raise VrechoError(f"{where}: camera {cid} again (each CAMERA_ID once)")
        if not (1 <= width <= MAX_IMAGE_SIDE and 1 <= height <= MAX_IMAGE_SIDE):
            raise VrechoError(f"{where}: camera {cid} is {width} x {height} pixels; expected 1 to {MAX_IMAGE_SIDE}")
        cam = Camera(model, width, height, params)
        if not np.all(np.diag(cam.intrinsics)[:2] > 0):
            raise VrechoError(f"{where}: camera {cid}'s focal length must be positive (pixels), got "
                              f"{np.diag(cam.intrinsics)[:2].tolist()}")
        cameras[cid] = cam
    images, ids, names = [], set(), set()
    # An image's header has exactly ten fields; its points line, right after it, a multiple of three
    # (or none): a line of points anywhere else is a header that lost fields, not to be skipped.
    after_header = False
    for n, line in _lines(folder / "images.txt"):
        where, t = f"poses: {folder / 'images.txt'}, line {n}", line.split()
        if len(t) != 10:
            if len(t) % 3 or (t and not after_header):
                raise VrechoError(f"{where}: cannot read {line[:80]!r}; expected IMAGE_ID QW QX QY QZ TX TY TZ "
                                  "CAMERA_ID NAME, or on the line after it the image's 2-D points (X Y POINT3D_ID ..)")
            after_header = False
            continue
        after_header = True
        iid, cid, name = _whole(t[0], f"{where}, IMAGE_ID"), _whole(t[8], f"{where}, CAMERA_ID"), t[9]
        q, tr = _numbers(t[1:5], f"{where}, QW QX QY QZ"), _numbers(t[5:8], f"{where}, TX TY TZ")
        if cid not in cameras:
            raise VrechoError(f"{where}: image {name[:80]} names camera {cid}, which cameras.txt lacks")
        if iid in ids or name in names:
            raise VrechoError(f"{where}: image {iid} ({name[:80]}) again (each IMAGE_ID and NAME once)")
        if not name.isprintable():
            raise VrechoError(f"{where}: image {iid}'s name {name[:80]!r} holds control characters")
        if not np.any(q) or np.abs(tr).max() > MAX_COORDINATE_M:
            raise VrechoError(f"poses: image {name} has no valid pose ({' '.join(t[1:8])}); expected a non-zero "
                              f"quaternion and a translation within {MAX_COORDINATE_M:g} m ({where})")
        r = quaternion_matrix(q)
        pose = np.eye(4)
        pose[:3, :3], pose[:3, 3] = r.T, -r.T @ tr
        images.append(Image(name, cid, pose))
        ids.add(iid)
        names.add(name)
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
        Pictures per second of video; above 0, at most 1000.
    first : int
        Number of the first picture; 1 by default.

    Returns
    -------
    numpy.ndarray, shape (len(names),), float64
        Each picture's time in seconds.

    Raises
    ------
    VrechoError
        If ``fps`` is not a number above 0 and at most 1000, or a name holds no number (of at
        most 12 digits).

    Examples
    --------
    >>> image_times(["images/000001.png", "images/000004.png"], 2.0)
    array([0. , 1.5])
    """
    if isinstance(fps, bool) or not isinstance(fps, (int, float, np.integer, np.floating)) or not 0 < fps <= 1000:
        raise VrechoError(f"image-fps: expected a rate above 0 and at most 1000 pictures per second, got {fps!r}")
    out = []
    for name in names:
        m = re.findall(r"[0-9]+", Path(name).stem)
        if not m or len(m[-1]) > 12:
            raise VrechoError(f"poses: image {name!r} has no frame number in its name; expected pictures numbered "
                              "as ffmpeg writes them (images/%06d.png)")
        out.append((int(m[-1]) - first) / fps)
    return np.array(out)
