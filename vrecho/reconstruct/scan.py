"""A capture the reconstruction works on: the camera's frames, the mesh fused from them (or the
user's own) and, where the device listened, its recordings (:class:`Echoes`).

:func:`fuse` is open3d's TSDF fusion (``VoxelBlockGrid``; the legacy ``ScalableTSDFVolume``
returns empty meshes on open3d 0.20), its mesh in a repeatable order (:func:`canonical`); :func:`load_scan` reads a user's scan folder and
:meth:`Scan.save` writes one.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from tqdm import tqdm

from ..camera import DEPTH_MAX_M, View
from ..errors import VrechoError, check_number
from ..io import MAX_COORDINATE_M, ensure_writable_dir, read_arrays, read_mesh, write_mesh


@dataclass
class Echoes:
    """The device's recordings of its own probe, one per walkthrough frame that listened.

    Parameters
    ----------
    frame : numpy.ndarray [shape=(K,)], int
        The walkthrough frames (indices into the scan's views) the recordings were heard at;
        flattened to (K,) int.
    audio : numpy.ndarray [shape=(K, n)]
        1 s frames at ``fs`` Hz from the pulse onset; stored as float32 (one 1-D recording is
        taken as K = 1).
    fs : int
        Sample rate of ``audio`` and ``emitted``, in Hz.
    emitted : numpy.ndarray [shape=(k,)]
        The emitted probe, at ``fs``.

    Raises
    ------
    VrechoError
        When ``frame`` and ``audio`` hold different numbers of recordings.

    Examples
    --------
    >>> import numpy as np
    >>> from vrecho.reconstruct import Echoes
    >>> e = Echoes([3, 7], np.zeros((2, 44100)), 44100, np.ones(4410))
    >>> e.audio.dtype
    dtype('float32')
    >>> e.of(7).shape
    (44100,)
    >>> e.of(5) is None
    True
    """

    frame: np.ndarray
    audio: np.ndarray
    fs: int
    emitted: np.ndarray

    def __post_init__(self):
        self.frame = np.asarray(self.frame, int).reshape(-1)
        self.audio = np.atleast_2d(np.asarray(self.audio, np.float32))
        if len(self.frame) != len(self.audio):
            raise VrechoError(f"echoes: {len(self.frame)} frame indices for {len(self.audio)} recordings")

    def of(self, frame: int) -> np.ndarray | None:
        """The recording heard at a walkthrough frame.

        Parameters
        ----------
        frame : int
            Index of the frame in the scan's views.

        Returns
        -------
        numpy.ndarray [shape=(n,)], float32, or None
            The first recording heard at ``frame`` (at :attr:`fs` Hz), or None where the device
            did not listen there.
        """
        k = np.flatnonzero(self.frame == frame)
        return self.audio[k[0]] if len(k) else None


@dataclass
class Scan:
    """A capture: the camera's frames, the mesh fused from them (or the user's own) and, when the
    device listened, its recordings.

    Parameters
    ----------
    views : list of :class:`~vrecho.camera.View`
        The camera's frames (grayscale, z-depth in metres, intrinsics, camera-to-world pose), in
        walkthrough order.
    mesh : open3d.geometry.TriangleMesh
        The mesh fused from the frames (:func:`fuse`) or the user's own, in the same world frame
        (z up, metres).
    echoes : :class:`Echoes`, optional
        What the device heard at some of the frames; None (the default) when it did not listen.
    """

    views: list[View]
    mesh: object  # open3d.geometry.TriangleMesh
    echoes: Echoes | None = None

    @property
    def cameras(self) -> np.ndarray:
        """Camera positions (N, 3) of the frames, world coordinates in metres."""
        return np.array([v.pose[:3, 3] for v in self.views])

    def save(self, folder: str | Path) -> Path:
        """Write the scan in the documented folder format (see :func:`load_scan`).

        ``frames.npz`` holds every frame's depth, gray and pose and the first frame's intrinsics;
        ``mesh.ply`` the mesh; ``echoes.npz`` the recordings, when the scan has them.

        Parameters
        ----------
        folder : str or pathlib.Path
            The folder to write in; created if needed.

        Returns
        -------
        pathlib.Path
            The folder written.

        Raises
        ------
        VrechoError
            When the folder cannot be created or written in.
        """
        folder = ensure_writable_dir(Path(folder))
        np.savez_compressed(folder / "frames.npz", depth=np.stack([v.depth for v in self.views]),
                            gray=np.stack([v.gray for v in self.views]), pose=np.stack([v.pose for v in self.views]),
                            intrinsics=self.views[0].intrinsics)
        write_mesh(folder / "mesh.ply", self.mesh)
        if self.echoes is not None:
            e = self.echoes
            np.savez_compressed(folder / "echoes.npz", frame=e.frame, audio=e.audio, fs=e.fs, emitted=e.emitted)
        return folder


def fuse(views: list[View], *, voxel_m: float = 0.03, trunc_voxels: float = 4.0, weight_threshold: float = 1.0,
         progress: bool = False):
    """TSDF fusion of depth and grayscale frames into a coloured triangle mesh.

    open3d's ``VoxelBlockGrid`` on the CPU, depth in metres read up to
    :data:`~vrecho.camera.DEPTH_MAX_M` (10 m). Frames with no depth reading in range (clear
    glass up close, the sky), and frames whose few readings touch no voxel block, are skipped.
    open3d's parallel extraction orders the same vertices and triangles differently from run
    to run; they are put in a canonical order (:func:`canonical`), so that all that follows is
    repeatable.

    Parameters
    ----------
    views : list of :class:`vrecho.camera.View`
        The frames: ``depth`` (H, W) z-depth in metres (0 where the sensor returned nothing),
        ``gray`` (H, W) in [0, 1], intrinsics in pixels, camera-to-world poses.
    voxel_m : float
        Voxel size in metres (default 0.03).
    trunc_voxels : float
        Truncation distance in voxels (default 4).
    weight_threshold : float
        Fewest observations for a surface to be kept (default 1).
    progress : bool
        Show a progress bar over the frames.

    Returns
    -------
    open3d.geometry.TriangleMesh
        Legacy mesh, world frame (Z up), vertex colours from the grayscale frames.

    Raises
    ------
    VrechoError
        When ``views`` is empty, or no frame has a depth reading in range.
    """
    import open3d as o3d  # heavy (1.2 s to import): only where meshes are made or ray-cast
    import open3d.core as o3c  # heavy (1.2 s to import): only where meshes are made or ray-cast

    if not views:
        raise VrechoError("fuse: no frames")
    device = o3c.Device("CPU:0")
    grid = o3d.t.geometry.VoxelBlockGrid(attr_names=("tsdf", "weight", "color"),
                                         attr_dtypes=(o3c.float32, o3c.float32, o3c.float32),
                                         attr_channels=((1), (1), (3)), voxel_size=voxel_m,
                                         block_resolution=16, block_count=50_000, device=device)

    used = 0
    for view in tqdm(views, desc="fuse (TSDF)", unit="frame", disable=not progress):
        if not np.any((view.depth > 0) & (view.depth <= DEPTH_MAX_M)):
            continue  # nothing in range (clear glass up close, the sky): open3d would abort
        intrinsic = o3c.Tensor(view.intrinsics, o3c.float64)
        extrinsic = o3c.Tensor(np.linalg.inv(view.pose), o3c.float64)  # world-to-camera
        depth = o3d.t.geometry.Image(o3c.Tensor(np.ascontiguousarray(view.depth, np.float32)))
        color = o3d.t.geometry.Image(o3c.Tensor(np.ascontiguousarray(np.repeat(view.gray[..., None], 3, axis=2),
                                                                     np.float32)))
        try:
            blocks = grid.compute_unique_block_coordinates(depth, intrinsic, extrinsic, 1.0, DEPTH_MAX_M,
                                                           trunc_voxels)
        except RuntimeError as e:  # a few stray readings that touch no voxel block
            if "No block is touched" in str(e):
                continue
            raise
        used += 1
        grid.integrate(blocks, depth, color, intrinsic, intrinsic, extrinsic, 1.0, DEPTH_MAX_M, trunc_voxels)
    if not used:
        raise VrechoError("fuse: no frame has a depth reading in range")
    return canonical(grid.extract_triangle_mesh(weight_threshold=weight_threshold).to_legacy())


def canonical(mesh):
    """The same triangle mesh in a canonical order: its vertices sorted by x, then y, then z,
    its triangles by their vertices' new indices (each triangle's own corners as they were: the
    winding kept). Vertex colours and normals follow their vertices.

    Parameters
    ----------
    mesh : open3d.geometry.TriangleMesh

    Returns
    -------
    open3d.geometry.TriangleMesh
        A new mesh.
    """
    import open3d as o3d  # heavy (1.2 s to import): only where meshes are made or ray-cast

    v, t = np.asarray(mesh.vertices), np.asarray(mesh.triangles)
    order = np.lexsort(v.T[::-1])
    rank = np.empty(len(v), np.int64)
    rank[order] = np.arange(len(v))
    t = rank[t]
    t = t[np.lexsort(np.vstack([t.T[::-1], np.sort(t, axis=1).T[::-1]]))]  # (ties: the same corners, wound otherwise)
    out = o3d.geometry.TriangleMesh(o3d.utility.Vector3dVector(v[order]), o3d.utility.Vector3iVector(t.astype(np.int32)))
    if mesh.has_vertex_colors():
        out.vertex_colors = o3d.utility.Vector3dVector(np.asarray(mesh.vertex_colors)[order])
    if mesh.has_vertex_normals():
        out.vertex_normals = o3d.utility.Vector3dVector(np.asarray(mesh.vertex_normals)[order])
    return out


def load_scan(folder: str | Path, *, voxel_m: float = 0.03, progress: bool = False) -> Scan:
    """A user's capture, read from a scan folder.

    The folder holds:

    ``frames.npz`` (required)
        ``depth`` (N, H, W) float, metres along the camera's axis, 0 where the sensor returned
        nothing; ``gray`` (N, H, W) in [0, 1] (float) or 0..255 (uint8); ``pose`` (N, 4, 4)
        camera-to-world, OpenCV axes (x right, y down, z forward), world z up, metres;
        ``intrinsics`` (3, 3) pinhole matrix in pixels.
    ``mesh.ply`` (optional)
        The user's own mesh, in the same world frame; fused from the frames when absent.
    ``echoes.npz`` (optional)
        ``frame`` (K,) frame indices, ``audio`` (K, n) 1 s recordings from the probe's onset
        (microphone 7 cm above the loudspeaker, both at the camera), ``fs`` (Hz), ``emitted``
        (the probe, 1-D at ``fs``). Without it only oracle labels can repair the scan.

    Parameters
    ----------
    folder : str or pathlib.Path
        The scan folder.
    voxel_m : float
        Voxel size in metres of the fusion (:func:`fuse`) when the folder has no ``mesh.ply``
        (default 0.03).
    progress : bool
        Show a progress bar while fusing.

    Returns
    -------
    Scan
        The frames (gray as float32 in [0, 1], depth float32), the mesh and, where the folder
        has ``echoes.npz``, the :class:`Echoes`.

    Raises
    ------
    VrechoError
        Naming the file: when ``frames.npz`` is missing, or it or ``echoes.npz`` cannot be read
        (:func:`vrecho.io.read_arrays`: not an ``.npz``, truncated, an array missing, pickled
        or over 4 GiB) or holds arrays that are not numbers or of the wrong shapes; when depth
        is not finite and non-negative, float gray outside 0 to 1, the intrinsics not a pinhole
        matrix, a pose not a rigid motion within :data:`vrecho.io.MAX_COORDINATE_M`; when
        ``echoes.npz``'s frames are not whole numbers naming the scan's frames, its ``fs`` not a
        whole number of 1 Hz to 1 MHz, or its sounds not finite; when ``mesh.ply`` is not a mesh
        :func:`vrecho.io.read_mesh` takes; and when fusion finds no depth reading in range.
    """
    folder = Path(folder)
    path = folder / "frames.npz"
    if not path.is_file():
        raise VrechoError(f"scan: {folder} has no frames.npz (see vrecho.reconstruct.load_scan for the format)")
    names = ("depth", "gray", "pose", "intrinsics")
    f = read_arrays(path, names)
    depth, gray, pose, K = (_numbers(path, k, f[k]) for k in names)
    if depth.ndim != 3 or 0 in depth.shape or gray.shape != depth.shape or pose.shape != (len(depth), 4, 4) \
            or K.shape != (3, 3):
        raise VrechoError(f"scan: {path}: expected depth and gray (N, H, W), pose (N, 4, 4), intrinsics (3, 3); got "
                          f"{depth.shape}, {gray.shape}, {pose.shape}, {K.shape}")
    if not (np.all(np.isfinite(depth)) and np.all(np.isfinite(pose)) and depth.min() >= 0):
        raise VrechoError(f"scan: {path}: depth must be finite and non-negative, poses finite")
    if gray.dtype != np.uint8 and not (np.all(np.isfinite(gray)) and gray.min() >= 0 and gray.max() <= 1):
        raise VrechoError(f"scan: {path}: gray must be uint8, or floats in 0 to 1")
    if not (np.all(np.isfinite(K)) and K[0, 0] > 0 and K[1, 1] > 0 and np.allclose(K[2], [0, 0, 1])):
        raise VrechoError(f"scan: {path}: intrinsics must be a pinhole matrix (fx, fy > 0, last row 0 0 1), got "
                          f"{K.tolist()}")
    r = pose[:, :3, :3]
    rigid = np.all(np.abs(r.transpose(0, 2, 1) @ r - np.eye(3)) < 1e-3, axis=(1, 2)) & (np.linalg.det(r) > 0) \
        & np.all(np.abs(pose[:, 3] - [0, 0, 0, 1]) < 1e-6, axis=1) & (np.abs(pose[:, :3, 3]).max(axis=1) <= MAX_COORDINATE_M)
    if not rigid.all():
        k = int(np.flatnonzero(~rigid)[0])
        raise VrechoError(f"scan: {path}: pose {k} is not a camera-to-world rigid motion (a rotation, a position "
                          f"within {MAX_COORDINATE_M:g} m, last row 0 0 0 1): {np.round(pose[k], 4).tolist()}")
    gray = gray.astype(np.float32) / 255 if gray.dtype == np.uint8 else gray.astype(np.float32)
    views = [View(g, d.astype(np.float32), K.astype(float), p.astype(float)) for g, d, p in zip(gray, depth, pose)]
    echoes = None
    path = folder / "echoes.npz"
    if path.is_file():  # read (and checked) before the mesh, which may take fusion
        f = {k: _numbers(path, k, a) for k, a in read_arrays(path, ("frame", "audio", "fs", "emitted")).items()}
        if f["frame"].ndim != 1 or f["frame"].dtype.kind not in "iu" or f["audio"].shape[:1] != f["frame"].shape \
                or f["audio"].ndim != 2 or not f["audio"].shape[1] or f["emitted"].ndim != 1 or not f["emitted"].size \
                or f["fs"].shape != () or f["fs"].dtype.kind not in "iu":
            raise VrechoError(f"scan: {path}: expected frame (K,) whole numbers, audio (K, n), fs a whole number and "
                              f"emitted (k,); got {f['frame'].shape} {f['frame'].dtype}, {f['audio'].shape}, "
                              f"{f['fs'].shape} {f['fs'].dtype}, {f['emitted'].shape}")
        fs = int(check_number(f["fs"][()], f"scan: {path}: fs (Hz)", lo=1, hi=1_000_000))
        if not (np.all(np.isfinite(f["audio"])) and np.all(np.isfinite(f["emitted"]))):
            raise VrechoError(f"scan: {path}: audio and emitted must be finite")
        if f["frame"].min(initial=0) < 0 or f["frame"].max(initial=0) >= len(views):
            raise VrechoError(f"scan: echoes.npz names frames outside 0..{len(views) - 1}")
        echoes = Echoes(f["frame"], f["audio"], fs, f["emitted"].astype(float))
    mesh_path = folder / "mesh.ply"
    if mesh_path.is_file():
        mesh = read_mesh(mesh_path)
    else:
        mesh = fuse(views, voxel_m=voxel_m, progress=progress)
    return Scan(views, mesh, echoes)


def _numbers(path: Path, key: str, a: np.ndarray) -> np.ndarray:
    """``a`` if it holds real numbers (bool, int, uint or float), else one error naming it."""
    if a.dtype.kind not in "biuf":
        raise VrechoError(f"scan: {path}: {key} holds {a.dtype} values; expected numbers")
    return a
