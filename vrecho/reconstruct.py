"""Echo-reconstruction: the camera's scan of a room, its glass and mirror failures, and their repair.

1. **Scan** (:func:`scan_scene`, or :func:`load_scan` for a user's capture): a walkthrough
   along the scene's camera path renders grayscale and depth frames with the sensor's failures
   (it sees through glass, or gets nothing back, and finds a phantom room behind a mirror), and
   open3d's TSDF fusion (``VoxelBlockGrid``; the legacy ``ScalableTSDFVolume`` returns empty
   meshes on open3d 0.20) turns them into a coloured mesh.
2. **Discontinuities**: :func:`wall_planes` (RANSAC; the nearest plane to the cameras in each
   direction that is not seen only through another), :func:`holes` (free space carved by the
   depth frames) and :func:`beyond_walls` (geometry behind the walls).
3. **What each hole is**: :func:`infer` asks EchoCNN about the frames that look at it
   (:func:`facing`) and adds what the scan knows (the echo's expected delay, the mirror test by
   reflection); :func:`oracle` reads the truth.
4. **Repair**, the paper's Algorithm 1 (:func:`repair`, both its variants); :func:`reconstruct`
   runs 2 to 4 and :func:`run` is ``vrecho reconstruct``. Metrics against the truth:
   :mod:`vrecho.scan_metrics`.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .errors import VrechoError
from .render import DEPTH_MAX_M, Camera, View, World, camera_pose, project, render_view
from .scene import MIC_ABOVE_EMITTER_M, DevicePose, Scene, distance_to_polygon, point_in_polygon, signed_area
from .signals import FS, probe


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


def fuse(views: list[View], voxel_m: float = 0.03, trunc_voxels: float = 4.0, weight_threshold: float = 1.0,
         progress: bool = False):
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
    from tqdm import tqdm

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
        """In-plane unit axes of a vertical plane: along the wall (the direction of the scene's own
        wall axis, so crops are not mirrored), and up."""
        up = np.array([0.0, 0.0, 1.0])
        along = np.cross(self.normal, up)
        return along / np.linalg.norm(along), up

    def to_wall(self, points: np.ndarray) -> np.ndarray:
        """Wall coordinates (N, 2) (along, up; see :meth:`frame`) of world points (N, 3)."""
        return np.atleast_2d(points) @ np.stack(self.frame(), axis=1)

    def to_world(self, uz: np.ndarray, offset: float | None = None) -> np.ndarray:
        """World points (N, 3) of wall coordinates (N, 2), on the plane (or at another ``offset``)."""
        along, up = self.frame()
        offset = self.offset if offset is None else offset
        uz = np.atleast_2d(uz)
        return -offset * self.normal + uz[:, :1] * along + uz[:, 1:] * up


@dataclass
class Hole:
    """An empty region of a wall plane, seen through by the depth camera: its ``outline`` (K, 2),
    a convex polygon in the wall's frame (``u`` along the wall, ``z`` up, metres; see
    :meth:`Plane.frame`), its area and the plane."""

    plane: Plane
    outline: np.ndarray
    area_m2: float

    @property
    def u(self) -> tuple[float, float]:
        return float(self.outline[:, 0].min()), float(self.outline[:, 0].max())

    @property
    def z(self) -> tuple[float, float]:
        return float(self.outline[:, 1].min()), float(self.outline[:, 1].max())

    def corners(self) -> np.ndarray:
        """Bounding rectangle (4, 3), wound like the scene's walls: (u0, z0), (u1, z0), (u1, z1), (u0, z1)."""
        (u0, u1), (z0, z1) = self.u, self.z
        return self.plane.to_world(np.array([[u0, z0], [u1, z0], [u1, z1], [u0, z1]]))

    def polygon(self, offset: float | None = None) -> np.ndarray:
        """The outline in world coordinates (K, 3)."""
        return self.plane.to_world(self.outline, offset)

    def contains(self, points: np.ndarray, margin_m: float = 0.0) -> np.ndarray:
        """Whether world points project into the outline (convex; widened by about ``margin_m``)."""
        uz = self.plane.to_wall(points)
        a = self.outline
        e = np.roll(a, -1, axis=0) - a
        e = e / np.linalg.norm(e, axis=1, keepdims=True)
        cross = e[:, 0] * (uz[:, None, 1] - a[:, 1]) - e[:, 1] * (uz[:, None, 0] - a[:, 0])
        sign = 1.0 if signed_area(a) > 0 else -1.0
        return np.all(sign * cross >= -margin_m, axis=1)


def wall_planes(vertices: np.ndarray, cameras: np.ndarray, distance_m: float = 0.03, min_share: float = 0.003,
                max_planes: int = 20, seed: int = 0) -> list[Plane]:
    """The room's walls: planes found by RANSAC (open3d ``segment_plane``), one after another, of
    which the vertical ones nearest the cameras in each direction are kept (a phantom room
    behind a mirror, or buildings through a window, lie farther along the same directions)."""
    import open3d as o3d

    o3d.utility.random.seed(seed)
    rest = np.asarray(vertices, float)
    # open3d's parallel TSDF extraction orders the same vertices differently run to run; RANSAC
    # draws by index, so a canonical order makes the walls (and all that follows) repeatable.
    rest = rest[np.lexsort(rest.T[::-1])]
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
    # RANSAC also strings scattered points (the outdoors, seen in pieces) into planes: a wall is
    # a dense surface, at least a tenth as dense as the densest plane found.
    vertical = [_dense_part(p) for p in found if p.vertical]
    density = [_density(p) for p in vertical]
    vertical = [p for p, rho in zip(vertical, density) if rho >= 0.1 * max(density, default=0.0)]
    # What is seen only through another plane (the outside's facades through a window, a mirror's
    # phantom room, whose walls may be coplanar with the room's own) lies behind a wall, where the
    # line from the cameras to it crosses that wall's scanned extent: such points are dropped,
    # and a plane left with few points is no wall. Walls are vertical: the rest is refitted so.
    direct = []
    for p in vertical:
        keep = np.ones(len(p.inliers), bool)
        for q in vertical:
            if q is not p:
                keep &= ~_occluded(p.inliers, q, centre)
        if keep.sum() >= max(3, min_share * len(vertices)):
            direct.append(_vertical_fit(p.inliers[keep], centre))
    # The nearest plane in each direction is the wall, unless it is a remnant much smaller than
    # another plane facing the same way (a facade outside, seen above a wall's scanned extent),
    # or has a camera behind it (a facade seen through a window may stand nearer the cameras'
    # centre than the wall it is seen through, but the walkthrough passes it).
    cams = np.asarray(cameras, float)
    walls = []
    for p in sorted(direct, key=lambda p: p.normal @ centre + p.offset):
        same = [q for q in direct if p.normal @ q.normal >= np.cos(np.radians(10))]
        if len(p.inliers) < 0.25 * max(len(q.inliers) for q in same) or np.min(cams @ p.normal + p.offset) < -0.1:
            continue
        if all(p.normal @ w.normal < np.cos(np.radians(10)) for w in walls):
            walls.append(p)
    # RANSAC may take a wall in pieces (a door splits it): coplanar pieces are one wall.
    merged = []
    for w in walls:
        pieces = [q.inliers for q in direct if q.normal @ w.normal >= np.cos(np.radians(10))
                  and abs(np.median(q.inliers @ w.normal) + w.offset) < 0.06]
        merged.append(_vertical_fit(np.vstack(pieces), centre) if len(pieces) > 1 else w)
    return merged


def _dense_part(p: Plane, cell_m: float = 0.1, share: float = 0.25, min_side_m: float = 0.3) -> Plane:
    """The plane's inliers in its connected pieces (10 cm cells) that are surfaces, not strips:
    at least a quarter of the largest piece's area, or at least ``min_side_m`` wide and tall.
    RANSAC's plane also takes thin strips of other surfaces that cross it, which would stretch
    the wall's extent across the room; a wall's own pieces, parted where no frame looked, stay."""
    from scipy import ndimage

    cells = np.floor(p.to_wall(p.inliers) / cell_m).astype(int)
    cells -= cells.min(axis=0)
    grid = np.zeros(cells.max(axis=0) + 1, bool)
    grid[cells[:, 0], cells[:, 1]] = True
    labels, n = ndimage.label(grid, structure=np.ones((3, 3)))
    if n <= 1:
        return p
    area = np.bincount(labels.ravel())[1:]
    sides = np.array([[s.stop - s.start for s in sl] for sl in ndimage.find_objects(labels)]) * cell_m
    keep = np.r_[False, (area >= share * area.max()) | np.all(sides >= min_side_m, axis=1)]
    return Plane(p.normal, p.offset, p.inliers[keep[labels[cells[:, 0], cells[:, 1]]]])


def _density(p: Plane) -> float:
    """Inliers per square metre of the plane's extent (5th to 95th percentile)."""
    uz = p.to_wall(p.inliers)
    lo, hi = np.percentile(uz, [5, 95], axis=0)
    return 0.9 * len(p.inliers) / max(float(np.prod(hi - lo)), 1e-3)


def _occluded(points: np.ndarray, q: Plane, centre: np.ndarray) -> np.ndarray:
    """Which points (bool (N,)) lie behind ``q`` where their line of sight from ``centre`` crosses
    ``q`` within the extent (5th to 95th percentile) of ``q``'s inliers."""
    dc, dp = float(q.normal @ centre + q.offset), points @ q.normal + q.offset
    out = np.zeros(len(points), bool)
    crosses = np.flatnonzero((dp < -0.05) & (dc > 0))
    if not len(crosses):
        return out
    t = dc / (dc - dp[crosses])
    x = centre + t[:, None] * (points[crosses] - centre)
    lo, hi = np.percentile(q.to_wall(q.inliers), [5, 95], axis=0)
    uz = q.to_wall(x)
    out[crosses] = np.all((uz >= lo) & (uz <= hi), axis=1)
    return out


def _vertical_fit(points: np.ndarray, centre: np.ndarray) -> Plane:
    """The vertical plane through ``points`` by least squares (a line fit to their footprint),
    its normal toward ``centre``."""
    xy = points[:, :2] - points[:, :2].mean(axis=0)
    _, _, vt = np.linalg.svd(xy, full_matrices=False)
    n = np.r_[vt[-1], 0.0]
    d = -float(np.mean(points @ n))
    if n @ centre + d < 0:
        n, d = -n, -d
    return Plane(n, d, points)


def holes(plane: Plane, views: list[View], walls: list[Plane] = (), cell_m: float = 0.03, min_area_m2: float = 0.1,
          margin_m: float = 0.1) -> list[Hole]:
    """Regions of a wall plane that the depth camera saw through.

    A raster of ``cell_m`` cells over the plane's extent (its inliers, widened by 0.3 m up and
    down: the path may not look at a wall's bottom or top; not sideways, where it ends) is
    judged frame by frame: where a frame's depth reading at a cell lies beyond the cell (or is
    missing: clear glass, or nothing in range), the frame saw through it; where it agrees with
    the cell, it saw the wall; where it lies in front, something hid the cell. A cell is empty
    when more frames saw through it than saw the wall. Free space carved this way tells a hole
    from a part of the wall no frame looked at, and needs no dense mesh around the hole. Cells
    behind another of the room's ``walls`` are not the room's: a mirror's phantom room has walls
    in this plane too.
    """
    from scipy import ndimage
    from scipy.spatial import ConvexHull

    uz = plane.to_wall(plane.inliers)
    lo, hi = uz.min(axis=0) - [0.0, 0.3], uz.max(axis=0) + [0.0, 0.3]
    shape = tuple(np.ceil((hi - lo) / cell_m).astype(int))
    iu, iz = np.meshgrid(np.arange(shape[0]), np.arange(shape[1]), indexing="ij")
    centres = plane.to_world(lo + cell_m * (np.stack([iu.ravel(), iz.ravel()], axis=1) + 0.5))
    in_room = np.ones(len(centres), bool)
    for other in walls:
        if other is not plane:
            in_room &= centres @ other.normal + other.offset > -margin_m
    through = np.zeros(len(centres), np.int32)
    wall = np.zeros(len(centres), np.int32)
    for view in views:
        col, row, z = project(view, centres)
        col, row = np.round(col), np.round(row)
        h, w = view.depth.shape
        ok = (z > 0.1) & (col >= 0) & (col < w) & (row >= 0) & (row < h)
        d = np.full(len(z), -1.0)
        d[ok] = view.depth[row[ok].astype(int), col[ok].astype(int)]
        through += ok & ((d == 0) | (d > z + margin_m))
        wall += ok & (np.abs(d - z) <= margin_m)
    empty = ((through > wall) & in_room).reshape(shape)
    empty = ndimage.binary_opening(empty, iterations=1)  # single cells at depth edges
    labels, _ = ndimage.label(empty)
    out = []
    for k, sl in enumerate(ndimage.find_objects(labels), start=1):
        cells = np.argwhere(labels[sl] == k) + [sl[0].start, sl[1].start]
        area = len(cells) * cell_m ** 2
        if area < min_area_m2:
            continue
        corners = (lo + cell_m * (cells[:, None, :] + np.array([[0, 0], [1, 0], [0, 1], [1, 1]]))).reshape(-1, 2)
        hull = corners[ConvexHull(corners).vertices]
        out.append(Hole(plane, hull, float(area)))
    return out


def beyond_walls(vertices: np.ndarray, walls: list[Plane], margin_m: float = 0.1) -> np.ndarray:
    """Which vertices lie more than ``margin_m`` behind a wall plane: what the camera saw through
    glass or an opening, or the phantom room a mirror makes (the repair tells them apart)."""
    v = np.asarray(vertices, float)
    out = np.zeros(len(v), bool)
    for w in walls:
        out |= v @ w.normal + w.offset < -margin_m
    return out


# -- Which frames look at a hole, and what they hear -------------------------------------------

def device_pose(view: View, target: int | None = None) -> DevicePose:
    """The capture device of a frame: the camera is its microphone, 7 cm above the emitter."""
    up = -view.pose[:3, 1]  # OpenCV's y axis points down
    return DevicePose(view.pose[:3, 3] - MIC_ABOVE_EMITTER_M * up, view.pose[:3, 2], up, target)


def facing(views: list[View], hole: Hole, max_incidence_deg: float = 25.0,
           depth_range_m: tuple[float, float] = (0.25, 3.5), margin_m: float = 0.05) -> list[int]:
    """Frames that look at a hole: the camera's axis meets its outline (widened by ``margin_m``)
    within ``max_incidence_deg`` of the wall's normal, from ``depth_range_m`` (EchoCNN's range)."""
    n, offset = hole.plane.normal, hole.plane.offset
    out = []
    for i, view in enumerate(views):
        c, f = view.pose[:3, 3], view.pose[:3, 2]
        cos = -float(n @ f)
        depth = float(n @ c + offset)
        if cos < np.cos(np.radians(max_incidence_deg)) or not depth_range_m[0] <= depth <= depth_range_m[1]:
            continue
        if hole.contains((c + depth / cos * f)[None], margin_m)[0]:
            out.append(i)
    return out


@dataclass
class Echoes:
    """The device's recordings of its own probe: ``audio`` (K, n) 1 s frames at ``fs`` Hz from the
    pulse onset, heard at the walkthrough frames ``frame`` (K,), and the ``emitted`` probe."""

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
        k = np.flatnonzero(self.frame == frame)
        return self.audio[k[0]] if len(k) else None


def simulate_echoes(scene: Scene, views: list[View], frames, seed: int = 0, progress: bool = False) -> Echoes:
    """What the device hears at the given walkthrough frames while it plays vrecho's probe
    (pyroomacoustics, the recording conditions of PROTOCOL.md drawn per frame)."""
    from tqdm import tqdm

    from .acoustics import device_direct_amplitude, device_impulse_response, record_pulse
    from .data import recording_conditions

    frames = sorted(set(int(i) for i in frames))
    sound = probe()
    audio = np.zeros((len(frames), FS), np.float32)
    for k, i in enumerate(tqdm(frames, desc="simulate echoes", unit="frame", disable=not progress)):
        rng = np.random.default_rng([seed, i])
        pose = device_pose(views[i])
        ir = device_impulse_response(scene, pose)[0]
        audio[k] = record_pulse(ir, sound, device_direct_amplitude(scene, pose), rng, *recording_conditions(rng))
    return Echoes(np.array(frames, int), audio, FS, sound)


# -- What each hole is --------------------------------------------------------------------------

@dataclass
class Decision:
    """What a hole is judged to be: ``state`` closed, open or unknown (no frame looked at it),
    ``material`` (glass or mirror, for closed holes), ``offset_m`` (the plane of the surface:
    points x with normal . x + offset = 0, normal into the room), ``p_closed``, ``p_mirror``,
    ``confidence`` (probability of the answer given), ``source`` (echocnn or oracle) and the
    per-frame inferences it was combined from, and the scan's ``evidence`` (see :func:`infer`)."""

    state: str
    material: str | None
    offset_m: float | None
    p_closed: float
    p_mirror: float
    confidence: float
    source: str
    frames: list[dict] = field(default_factory=list)
    evidence: dict = field(default_factory=dict)


ECHO_CLOSED_DB = -2.5
"""Level (dB, :func:`~vrecho.features.echo_at`) at the scanned plane's delay above which the
echo says closed. Set on the living room and rooms of seeds 1000 and 3000 (not the benchmark's):
the frames' :data:`ECHO_QUANTILE` level reads -0.4 to 4.5 dB on 25 closed surfaces, -5.4 to -30
dB on 14 openings."""
ECHO_QUANTILE = 0.2
"""Which of the frames' levels speaks for a hole: a low one. Another surface's echo arriving
with the hole's (the floor's, the wall behind the device) only adds sound, so an opening's
silence shows in the frames it does not mask, while a closed surface echoes in every frame."""
ECHO_SLOPE_DB = 1.0
"""Width of the logistic around :data:`ECHO_CLOSED_DB`: 2.5 dB off it is 92 % one way."""
MIRROR_SHARE = 0.15
"""Share of seen-through geometry that, reflected, lands on the room: above it, a mirror (the
living room: mirror 0.27, window 0.006, opening 0.04)."""


def _logit(p: float) -> float:
    p = float(np.clip(p, 1e-4, 1 - 1e-4))
    return float(np.log(p / (1 - p)))


def infer(holes_: list[Hole], views: list[View], echoes: Echoes, classifier=None, mesh=None, walls=(),
          use_scan: bool = True, min_crop_inside: float = 0.98, max_frames: int = 6) -> list[Decision]:
    """vrecho's answer for each hole, from the frames that look at it (:func:`facing`).

    Each frame's recording goes to EchoCNN with the known probe (EchoCNN-E), and with the
    camera's crop around the hole when the frame holds all of it (EchoCNN-EV). Up to
    ``max_frames`` frames per hole, the most frontal first, are combined.

    With ``use_scan`` (vrecho's choice) the scan adds what it knows, by physics: the wall around
    the hole is scanned, so the delay of a closed surface's echo is known; the level there
    (:func:`~vrecho.features.echo_at`, a low quantile, :data:`ECHO_QUANTILE`, over the frames
    whose specular point, the foot of the emitter's perpendicular, falls in the hole; a logistic
    around :data:`ECHO_CLOSED_DB`)
    joins EchoCNN's open/closed log-odds, and the depth comes from the
    EchoCNN echo when it agrees with the scan within 10 cm, else from the echo nearest the
    scan's delay. The geometry seen through the hole, reflected in its plane
    (:func:`mirror_evidence`), says mirror or not where it is clear; EchoCNN's material answers
    otherwise. Without ``use_scan``: EchoCNN alone (probabilities averaged, depth the median
    of the frames' EchoCNN depths weighted by their closed probability).
    """
    from .classifier import load_classifier
    from .features import echo_at
    from .render import crop_view

    classifier = load_classifier() if classifier is None else classifier
    cameras = np.array([v.pose[:3, 3] for v in views])
    out = []
    for hole in holes_:
        n = hole.plane.normal
        frames = [i for i in facing(views, hole) if echoes.of(i) is not None]
        frames = sorted(frames, key=lambda i: float(n @ views[i].pose[:3, 2]))[:max_frames]
        if not frames:
            out.append(Decision("unknown", None, None, 0.5, 0.5, 0.0, "echocnn"))
            continue
        rows = []
        for i in frames:
            image, inside = crop_view(views[i], hole.corners())
            audio = echoes.of(i)
            pred = classifier.predict(audio, echoes.fs, image if inside >= min_crop_inside else None, echoes.emitted)
            pose = device_pose(views[i])
            scan_depth = float(n @ pose.emitter + hole.plane.offset)
            row = {"frame": i, "model": pred.model, "p_closed": pred.probabilities["closed"],
                   "p_mirror": pred.probabilities["mirror"], "echo_depth_m": pred.depth_m, "scan_depth_m": scan_depth}
            if use_scan:
                row["echo_level_db"], row["echo_at_scan_m"] = echo_at(audio, echoes.emitted, scan_depth, echoes.fs)
                row["depth_m"] = pred.depth_m if abs(pred.depth_m - scan_depth) < 0.1 else row["echo_at_scan_m"]
                # The specular echo comes from the foot of the perpendicular: only where it falls in
                # the hole does the echo speak of the hole (else of the wall beside it).
                foot = pose.emitter - scan_depth * n
                row["foot_in_hole"] = bool(hole.contains(foot[None], -0.05)[0])
            else:
                row["depth_m"] = pred.depth_m
            row["offset_m"] = row["depth_m"] - float(n @ pose.emitter)
            rows.append(row)
        p_closed = float(np.mean([r["p_closed"] for r in rows]))
        p_mirror = float(np.mean([r["p_mirror"] for r in rows]))
        evidence = {}
        if use_scan:
            levels = [r["echo_level_db"] for r in rows if r["foot_in_hole"]]
            if levels:
                level = float(np.quantile(levels, ECHO_QUANTILE))
                p_echo = 1 / (1 + np.exp(-(level - ECHO_CLOSED_DB) / ECHO_SLOPE_DB))
                p_closed = float(1 / (1 + np.exp(-(_logit(p_closed) + _logit(p_echo)))))
                evidence.update(echo_level_db=level, echo_frames=len(levels), echo_levels_db=levels)
            if mesh is not None:
                share, count = mirror_evidence(mesh, hole, walls, cameras)
                evidence.update(mirrored_share=share, seen_through_vertices=count)
                if count >= 200:  # enough seen through to judge
                    p_mirror = 0.97 if share >= MIRROR_SHARE else 0.03
                elif count < 50:  # nothing behind it: a mirror always shows its phantom; clear glass shows nothing
                    p_mirror = 0.1
        offsets = np.array([r["offset_m"] for r in rows])
        weights = np.array([r["p_closed"] for r in rows]) + 1e-6
        order = np.argsort(offsets)
        cum = np.cumsum(weights[order])
        offset = float(offsets[order][np.searchsorted(cum, cum[-1] / 2)])
        closed = p_closed >= 0.5
        out.append(Decision("closed" if closed else "open", ("mirror" if p_mirror >= 0.5 else "glass") if closed else None,
                            offset if closed else None, p_closed, p_mirror, max(p_closed, 1 - p_closed),
                            "echocnn+scan" if use_scan else "echocnn", rows, evidence))
    return out


def match_truth(scene: Scene, hole: Hole, max_offset_m: float = 0.15) -> int | None:
    """The scene's discontinuity a hole belongs to (largest overlap on the same wall), or None."""
    best, best_area = None, 0.0
    polygon = hole.polygon()
    for k, d in enumerate(scene.discontinuities):
        origin, u, normal = scene.room.wall_frame(d.wall)
        if hole.plane.normal @ normal > -np.cos(np.radians(10)):
            continue
        if abs(np.mean((polygon - origin) @ normal)) > max_offset_m:
            continue
        uz = np.stack([(polygon - origin) @ u, polygon[:, 2]], axis=1)
        u0, u1, z0, z1 = d.bounds()
        du = max(0.0, min(u1, uz[:, 0].max()) - max(u0, uz[:, 0].min()))
        dz = max(0.0, min(z1, uz[:, 1].max()) - max(z0, uz[:, 1].min()))
        if du * dz > best_area:
            best, best_area = k, du * dz
    return best


def oracle(scene: Scene, holes_: list[Hole]) -> list[Decision]:
    """The true answer for each hole: what a perfect EchoCNN would say. A hole that is none of
    the scene's discontinuities is plain wall the camera failed to see: closed, no material."""
    out = []
    for hole in holes_:
        k = match_truth(scene, hole)
        if k is not None and scene.discontinuities[k].is_open:
            out.append(Decision("open", None, None, 0.0, 0.0, 1.0, "oracle"))
            continue
        wall = scene.discontinuities[k].wall if k is not None else None
        if wall is None:  # the nearest of the room's walls
            wall = int(np.argmax([hole.plane.normal @ -scene.room.wall_frame(w)[2]
                                  for w in range(len(scene.room.footprint))]))
        origin, _, normal = scene.room.wall_frame(wall)
        c = hole.polygon().mean(axis=0)
        on_wall = c - ((c - origin) @ normal) * normal  # the true wall at the hole's centre
        material = scene.discontinuities[k].kind if k is not None else "wall"
        out.append(Decision("closed", material, float(-(hole.plane.normal @ on_wall)), 1.0,
                            float(material == "mirror"), 1.0, "oracle"))
    return out


# -- The repair: the paper's Algorithm 1 --------------------------------------------------------

SURFACE_COLOURS = {"glass": (0.55, 0.75, 0.95), "mirror": (0.85, 0.85, 0.9), "wall": (0.6, 0.6, 0.6)}
VARIANTS = ("simplified", "per_vertex")


@dataclass
class Surface:
    """A surface the repair added: its ``polygon`` (K, 3, world), ``material``, the hole it fills,
    the decision's confidence and its ``triangles`` (F, 3) in the repaired mesh."""

    hole: int
    material: str
    polygon: np.ndarray
    normal: np.ndarray
    confidence: float
    triangles: np.ndarray

    @property
    def area_m2(self) -> float:
        p = self.polygon - self.polygon[0]
        return float(0.5 * np.linalg.norm(np.cross(p[1:-1], p[2:]).sum(axis=0)))


def seen_through(points: np.ndarray, hole: Hole, cameras: np.ndarray, margin_m: float = 0.1,
                 max_cameras: int = 12) -> np.ndarray:
    """Which points (bool (N,)) lie behind a hole's plane where a camera saw them through the
    hole: the line from some camera (at most ``max_cameras`` of those in front, evenly spread)
    to the point crosses the hole's outline (widened by 5 cm)."""
    n, offset = hole.plane.normal, hole.plane.offset
    cams = np.asarray(cameras, float)
    cams = cams[cams @ n + offset > 0.1]
    cams = cams[np.unique(np.linspace(0, len(cams) - 1, min(max_cameras, len(cams))).astype(int))] if len(cams) else cams
    behind = np.flatnonzero(points @ n + offset < -margin_m)
    out = np.zeros(len(points), bool)
    for c in cams:
        idx = behind[~out[behind]]
        if not len(idx):
            break
        p = points[idx]
        dc, dp = float(c @ n + offset), p @ n + offset
        t = dc / (dc - dp)  # where the segment from the camera meets the plane
        out[idx[hole.contains(c + t[:, None] * (p - c), 0.05)]] = True
    return out


def mirror_evidence(mesh, hole: Hole, walls: list[Plane], cameras: np.ndarray, tolerance_m: float = 0.06,
                    shifts_m: np.ndarray = np.arange(-0.06, 0.061, 0.02)) -> tuple[float, int]:
    """How much of what the camera saw through a hole is the room itself, mirrored.

    A mirror's phantom is the room reflected in the mirror's plane: reflected back, it lands on
    the scanned room. What lies beyond glass or an opening does not. Returns the share of the
    seen-through vertices that, reflected, fall within ``tolerance_m`` of the scan's own
    surfaces (in front of every wall), and how many vertices were seen through. A mirror hangs a
    few centimetres off its wall, and a scanned surface lies within a voxel of the truth (the
    reflection is off by twice the plane's error): the mirror's plane is tried at the wall's
    plane moved by each of ``shifts_m`` (positive: toward the room), and the best share counts (on the
    tuning rooms of seeds 1000 and 3000: openings 0.09 at most, glass 0.06, mirrors 0.19 and
    above).
    """
    from scipy.spatial import cKDTree

    v = np.asarray(mesh.vertices)
    through = v[seen_through(v, hole, cameras)]
    if len(through) < 50:
        return 0.0, int(len(through))
    room = np.ones(len(v), bool)
    for w in walls:
        room &= v @ w.normal + w.offset > -0.05
    n = hole.plane.normal
    tree = cKDTree(v[room])
    shares = []
    for offset in hole.plane.offset + np.asarray(shifts_m):
        dist, _ = tree.query(through - 2 * (through @ n + offset)[:, None] * n, distance_upper_bound=tolerance_m)
        shares.append(float(np.mean(np.isfinite(dist))))
    return max(shares), int(len(through))


def repair(mesh, holes_: list[Hole], decisions: list[Decision], cameras: np.ndarray, variant: str = "simplified",
           min_component_triangles: int = 200, rim_m: float = 0.06):
    """The paper's Algorithm 1: fill what is closed, empty what a mirror made, leave openings open.

    Parameters
    ----------
    mesh : open3d.geometry.TriangleMesh
        The initial reconstruction (not modified).
    holes_, decisions : lists of the same length
        The holes found (:func:`holes`) and what each is (:func:`infer` or :func:`oracle`).
    cameras : array, shape (N, 3)
        Camera positions of the walkthrough (which phantom geometry was seen through a mirror).
    variant : {"simplified", "per_vertex"}
        ``simplified``: a new face, the convex hull of the hole's outline, at the decided plane.
        ``per_vertex``: the mesh's own vertices around the hole (within ``rim_m`` of its
        outline) on the convex hull are moved to the decided plane and the hull is filled from
        them, so the patch is stitched to the scan.
    min_component_triangles : int
        Connected pieces with fewer triangles are removed (loose fragments).

    Returns
    -------
    repaired : open3d.geometry.TriangleMesh
    surfaces : list of :class:`Surface`
    actions : list of dict, one per hole: what was done (filled, phantom triangles removed,
        fragments removed).
    """
    import copy

    import open3d as o3d
    from scipy.spatial import ConvexHull

    if variant not in VARIANTS:
        raise VrechoError(f"variant: expected one of {VARIANTS}, got {variant!r}")
    if len(holes_) != len(decisions):
        raise VrechoError(f"repair: {len(holes_)} holes but {len(decisions)} decisions")
    out = copy.deepcopy(mesh)
    if not out.has_vertex_colors():
        out.vertex_colors = o3d.utility.Vector3dVector(np.full((len(out.vertices), 3), 0.5))
    actions = [{"filled": False, "phantom_triangles_removed": 0, "fragment_triangles_removed": 0}
               for _ in holes_]
    # Removals first, then fills (so a fill is never taken for a fragment).
    remove = np.zeros(len(out.triangles), bool)
    centroids = np.asarray(out.vertices)[np.asarray(out.triangles)].mean(axis=1)
    for k, (hole, d) in enumerate(zip(holes_, decisions)):
        if d.state == "closed" and d.material == "mirror":  # the phantom room seen through it
            ph = seen_through(centroids, hole, cameras) & ~remove
            actions[k]["phantom_triangles_removed"] = int(ph.sum())
            remove |= ph
        elif d.state == "open":  # loose pieces floating in the opening
            near = np.abs(centroids @ hole.plane.normal + hole.plane.offset) < 0.1
            frag = near & hole.contains(centroids) & ~remove
            actions[k]["fragment_triangles_removed"] = int(frag.sum())
            remove |= frag
    out.remove_triangles_by_mask(remove)
    clusters, counts, _ = out.cluster_connected_triangles()
    small = np.asarray(counts)[np.asarray(clusters)] < min_component_triangles
    out.remove_triangles_by_mask(small)
    out.remove_unreferenced_vertices()

    surfaces = []
    verts = np.asarray(out.vertices).copy()
    cols = np.asarray(out.vertex_colors).copy()
    tris = [np.asarray(out.triangles)]
    for k, (hole, d) in enumerate(zip(holes_, decisions)):
        if d.state != "closed":
            continue
        n, offset = hole.plane.normal, d.offset_m
        colour = SURFACE_COLOURS.get(d.material, SURFACE_COLOURS["wall"])
        rim = None
        if variant == "per_vertex":
            near = np.abs(verts @ n + hole.plane.offset) < 0.05
            uz = hole.plane.to_wall(verts[near])
            close = distance_to_polygon(uz, hole.outline) <= rim_m
            idx = np.flatnonzero(near)[close & ~point_in_polygon(uz, hole.outline)]
            if len(idx) >= 3:
                rim = idx[ConvexHull(hole.plane.to_wall(verts[idx])).vertices]
        if rim is None:  # simplified (or too few rim vertices: recorded)
            ring = np.arange(len(verts), len(verts) + len(hole.outline))
            verts = np.vstack([verts, hole.polygon(offset)])
            cols = np.vstack([cols, np.tile(colour, (len(ring), 1))])
        else:
            ring = rim
            verts[ring] -= (verts[ring] @ n + offset)[:, None] * n  # depth(vertex) = EchoCNN's depth
            cols[ring] = colour
        fan = np.array([[ring[0], ring[i], ring[i + 1]] for i in range(1, len(ring) - 1)])
        # Face the room: counter-clockwise seen from the cameras' side.
        if np.cross(verts[fan[0, 1]] - verts[fan[0, 0]], verts[fan[0, 2]] - verts[fan[0, 0]]) @ n < 0:
            fan = fan[:, ::-1]
        tris.append(fan)
        actions[k].update(filled=True, fill="per_vertex" if rim is not None else "simplified",
                          fill_vertices=int(len(ring)))
        surfaces.append(Surface(k, d.material or "wall", verts[ring].copy(), n.copy(), d.confidence, fan))
    out.vertices = o3d.utility.Vector3dVector(verts)
    out.vertex_colors = o3d.utility.Vector3dVector(cols)
    out.triangles = o3d.utility.Vector3iVector(np.vstack(tris).astype(np.int32))
    out.compute_vertex_normals()
    return out, surfaces, actions


# -- The whole run: a scan (simulated or the user's) in, a repaired mesh and a report out -----------

@dataclass
class Scan:
    """A capture: the camera's frames (:class:`~vrecho.render.View`), the mesh fused from them
    (or the user's own) and, when the device listened, its :class:`Echoes`."""

    views: list[View]
    mesh: object  # open3d.geometry.TriangleMesh
    echoes: Echoes | None = None

    @property
    def cameras(self) -> np.ndarray:
        return np.array([v.pose[:3, 3] for v in self.views])

    def save(self, folder: str | Path) -> Path:
        """Write the scan in the documented folder format (see :func:`load_scan`)."""
        import open3d as o3d

        from .io import ensure_writable_dir

        folder = ensure_writable_dir(Path(folder))
        np.savez_compressed(folder / "frames.npz", depth=np.stack([v.depth for v in self.views]),
                            gray=np.stack([v.gray for v in self.views]), pose=np.stack([v.pose for v in self.views]),
                            intrinsics=self.views[0].intrinsics)
        o3d.io.write_triangle_mesh(str(folder / "mesh.ply"), self.mesh)
        if self.echoes is not None:
            e = self.echoes
            np.savez_compressed(folder / "echoes.npz", frame=e.frame, audio=e.audio, fs=e.fs, emitted=e.emitted)
        return folder


def load_scan(folder: str | Path, voxel_m: float = 0.03, progress: bool = False) -> Scan:
    """A user's capture, from a folder:

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
    """
    from .io import read_mesh

    folder = Path(folder)
    path = folder / "frames.npz"
    if not path.is_file():
        raise VrechoError(f"scan: {folder} has no frames.npz (see vrecho.reconstruct.load_scan for the format)")
    with np.load(path) as f:
        missing = {"depth", "gray", "pose", "intrinsics"} - set(f.files)
        if missing:
            raise VrechoError(f"scan: {path} lacks {sorted(missing)}")
        depth, gray, pose, K = (np.asarray(f[k]) for k in ("depth", "gray", "pose", "intrinsics"))
    if depth.ndim != 3 or gray.shape != depth.shape or pose.shape != (len(depth), 4, 4) or K.shape != (3, 3):
        raise VrechoError(f"scan: {path}: expected depth and gray (N, H, W), pose (N, 4, 4), intrinsics (3, 3); got "
                          f"{depth.shape}, {gray.shape}, {pose.shape}, {K.shape}")
    if not (np.all(np.isfinite(depth)) and np.all(np.isfinite(pose)) and depth.min() >= 0):
        raise VrechoError(f"scan: {path}: depth must be finite and non-negative, poses finite")
    gray = gray.astype(np.float32) / 255 if gray.dtype == np.uint8 else gray.astype(np.float32)
    views = [View(g, d.astype(np.float32), K.astype(float), p.astype(float)) for g, d, p in zip(gray, depth, pose)]
    mesh_path = folder / "mesh.ply"
    if mesh_path.is_file():
        mesh = read_mesh(mesh_path)
    else:
        mesh = fuse(views, voxel_m, progress=progress)
    echoes = None
    if (folder / "echoes.npz").is_file():
        with np.load(folder / "echoes.npz") as f:
            try:
                echoes = Echoes(f["frame"], f["audio"], int(f["fs"]), np.asarray(f["emitted"], float))
            except KeyError as e:
                raise VrechoError(f"scan: {folder / 'echoes.npz'} lacks {e}") from None
        if echoes.frame.min(initial=0) < 0 or echoes.frame.max(initial=0) >= len(views):
            raise VrechoError(f"scan: echoes.npz names frames outside 0..{len(views) - 1}")
    return Scan(views, mesh, echoes)


def scan_scene(scene: Scene, n_frames: int = 60, camera: Camera = Camera(), voxel_m: float = 0.03,
               progress: bool = False) -> Scan:
    """The simulated phone scan of a scene: its walkthrough (the scene's camera path, or
    :func:`~vrecho.scene.walkthrough_path`) fused into a mesh. No echoes yet: :func:`reconstruct`
    simulates them where frames look at a hole."""
    from .scene import walkthrough_path

    if scene.camera_path is None:
        scene = dataclasses.replace(scene, camera_path=walkthrough_path(scene))
    views = walkthrough(scene, n_frames, camera, progress)
    return Scan(views, fuse(views, voxel_m, progress=progress))


@dataclass
class Reconstruction:
    """Everything a run found and did; :meth:`report` is its JSON."""

    scan: Scan
    walls: list[Plane]
    holes: list[Hole]
    decisions: list[Decision]
    repaired: object  # open3d.geometry.TriangleMesh
    surfaces: list[Surface]
    actions: list[dict]
    variant: str
    seconds: dict

    def report(self) -> dict:
        return {
            "format": "vrecho-reconstruction", "version": 1, "variant": self.variant,
            "labels": self.decisions[0].source if self.decisions else None,
            "initial": {"vertices": len(self.scan.mesh.vertices), "triangles": len(self.scan.mesh.triangles)},
            "repaired": {"vertices": len(self.repaired.vertices), "triangles": len(self.repaired.triangles)},
            "walls": [{"normal": w.normal.round(4).tolist(), "offset_m": round(w.offset, 4), "inliers": len(w.inliers)}
                      for w in self.walls],
            "holes": [{"id": k, "wall": next(i for i, w in enumerate(self.walls) if w is h.plane),
                       "area_m2": round(h.area_m2, 3), "outline": h.polygon().round(4).tolist(),
                       "decision": {"state": d.state, "material": d.material,
                                    "offset_m": None if d.offset_m is None else round(d.offset_m, 4),
                                    "p_closed": round(d.p_closed, 4), "p_mirror": round(d.p_mirror, 4),
                                    "confidence": round(d.confidence, 4), "source": d.source,
                                    "frames": [_rounded(r) for r in d.frames], "evidence": _rounded(d.evidence)},
                       "action": a}
                      for k, (h, d, a) in enumerate(zip(self.holes, self.decisions, self.actions))],
            "surfaces": [{"hole": s.hole, "material": s.material, "area_m2": round(s.area_m2, 3),
                          "normal": s.normal.round(4).tolist(), "polygon": s.polygon.round(4).tolist(),
                          "confidence": round(s.confidence, 4)} for s in self.surfaces],
            "seconds": {k: round(v, 3) for k, v in self.seconds.items()},
        }


def _rounded(d: dict) -> dict:
    return {k: round(v, 4) if isinstance(v, float) else v for k, v in d.items()}


LABELS = ("echocnn", "echocnn-only", "oracle")
"""echocnn: EchoCNN with what the scan adds (vrecho's choice, see :func:`infer`); echocnn-only:
EchoCNN alone; oracle: the truth."""


def reconstruct(scan: Scan, scene: Scene | None = None, labels: str = "echocnn", variant: str = "simplified",
                classifier=None, seed: int = 0, progress: bool = False) -> Reconstruction:
    """Find the scan's discontinuities, decide what each is, and repair it (Algorithm 1).

    Parameters
    ----------
    scan : :class:`Scan`
        From :func:`scan_scene` or :func:`load_scan`.
    scene : Scene, optional
        The truth, for a simulated scan: echoes are simulated where frames look at a hole (when
        the scan has none), and ``labels="oracle"`` reads the answers from it.
    labels : {"echocnn", "echocnn-only", "oracle"}
        See :data:`LABELS`.
    variant : {"simplified", "per_vertex"}
        See :func:`repair`.
    """
    import time

    if labels not in LABELS:
        raise VrechoError(f"labels: expected one of {LABELS}, got {labels!r}")
    if variant not in VARIANTS:
        raise VrechoError(f"variant: expected one of {VARIANTS}, got {variant!r}")
    if labels == "oracle" and scene is None:
        raise VrechoError("labels='oracle' needs the scene's truth")
    seconds = {}
    t0 = time.perf_counter()
    vertices = np.asarray(scan.mesh.vertices)
    if len(vertices) < 100:
        raise VrechoError(f"scan: the mesh has {len(vertices)} vertices; nothing to reconstruct")
    walls = wall_planes(vertices, scan.cameras)
    found = [h for w in walls for h in holes(w, scan.views, walls)]
    seconds["discontinuities"] = time.perf_counter() - t0
    if labels == "oracle":
        decisions = oracle(scene, found)
    else:
        if scan.echoes is None:
            if scene is None:
                raise VrechoError("scan: no echoes.npz, so EchoCNN has nothing to hear; give echoes or use oracle labels")
            t = time.perf_counter()
            scan.echoes = simulate_echoes(scene, scan.views, {i for h in found for i in facing(scan.views, h)}, seed,
                                          progress)
            seconds["simulate_echoes"] = time.perf_counter() - t
        t = time.perf_counter()
        decisions = infer(found, scan.views, scan.echoes, classifier, scan.mesh, walls, use_scan=labels == "echocnn")
        seconds["infer"] = time.perf_counter() - t
    t = time.perf_counter()
    repaired, surfaces, actions = repair(scan.mesh, found, decisions, scan.cameras, variant)
    seconds["repair"] = time.perf_counter() - t
    seconds["total_without_simulation"] = sum(v for k, v in seconds.items() if k != "simulate_echoes")
    return Reconstruction(scan, walls, found, decisions, repaired, surfaces, actions, variant, seconds)


def before_after(result: Reconstruction, path: str | Path) -> Path:
    """A figure of the initial and the repaired mesh from two viewpoints (over the shoulder of
    the walkthrough, and from above), side by side."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from .render import render_mesh

    cams = result.scan.cameras
    centre = cams.mean(axis=0)
    v = np.asarray(result.scan.mesh.vertices)
    lo, hi = np.percentile(v, 2, axis=0), np.percentile(v, 98, axis=0)
    corner = np.array([hi[0], hi[1], 0.0])
    views = [camera_pose(np.r_[(corner + 0.25 * (centre - corner))[:2], hi[2] - 0.1],
                         np.r_[(centre - corner)[:2], -0.35 * np.linalg.norm((centre - corner)[:2])]),
             camera_pose(np.r_[centre[:2], hi[2] + 9.0], [0, 0, -1.0], up=(0, 1.0, 0))]
    fig, axes = plt.subplots(2, 2, figsize=(12, 9))
    for row, pose in enumerate(views):
        for col, (mesh, title) in enumerate(((result.scan.mesh, "initial scan"), (result.repaired, "repaired"))):
            if row == 1:
                mesh = below(mesh, hi[2] - 0.3)
            ax = axes[row, col]
            ax.imshow(render_mesh(mesh, pose, Camera(480, 360, 80 if row == 0 else 60)))
            ax.set_title(title if row == 0 else f"{title}, from above (ceiling cut away)")
            ax.axis("off")
    fig.tight_layout()
    path = Path(path)
    fig.savefig(path, dpi=80)
    plt.close(fig)
    return path


def below(mesh, z_max: float):
    """A copy of a mesh without the triangles above ``z_max`` (the ceiling, for a view from above)."""
    import copy

    out = copy.deepcopy(mesh)
    out.remove_triangles_by_mask(np.asarray(mesh.vertices)[np.asarray(mesh.triangles)][:, :, 2].max(axis=1) > z_max)
    return out


def resolve_source(source: str | Path) -> Scene | Path:
    """What the command line names, checked before any work: ``builtin`` (the living room) or a
    scene JSON file gives its :class:`Scene`; a folder is a user's scan (:func:`load_scan`), or
    a folder with one in ``scan/`` (what ``vrecho capture --poses`` writes)."""
    from .scene import builtin_scene, load_scene

    source = Path(source)
    if str(source) == "builtin":
        return builtin_scene()
    if source.is_dir():  # a scan folder, or the output of `vrecho capture` or `reconstruct --save-scan` holding one
        return source / "scan" if not (source / "frames.npz").exists() and (source / "scan" / "frames.npz").exists() \
            else source
    if source.is_file():
        return load_scene(source)
    raise VrechoError(f"scene: {source} is neither 'builtin', a scene JSON file nor a scan folder")


def open_source(source: str | Path | Scene, n_frames: int = 60, progress: bool = False) -> tuple[Scan, Scene | None]:
    """The scan of a source (see :func:`resolve_source`; a scene is scanned with ``n_frames``
    walkthrough frames), and the scene's truth where there is one."""
    if n_frames < 2:
        raise VrechoError(f"frames: expected at least 2, got {n_frames}")
    if not isinstance(source, Scene):
        source = resolve_source(source)
    if isinstance(source, Path):
        return load_scan(source, progress=progress), None
    return scan_scene(source, n_frames, progress=progress), source


def run(source: str | Path, out: str | Path, labels: str = "echocnn", variant: str = "simplified",
        n_frames: int = 60, seed: int = 0, save_scan: bool = False, progress: bool = True) -> Reconstruction:
    """What ``vrecho reconstruct`` does: scan (or load) a scene, repair it, write the results.

    ``source``: ``builtin`` (the living room), a scene JSON file, or a scan folder
    (:func:`load_scan`). Writes ``initial.ply``, ``repaired.ply``, ``report.json`` (surfaces,
    holes, decisions with their confidences and per-frame inferences, times; for a scene also
    the metrics against its truth, :func:`vrecho.scan_metrics.score`) and ``before_after.png``;
    with ``save_scan`` the scan itself (``scan/``, the folder format of :func:`load_scan`).
    """
    from .io import ensure_writable_dir

    if labels not in LABELS:
        raise VrechoError(f"labels: expected one of {LABELS}, got {labels!r}")
    if n_frames < 2:
        raise VrechoError(f"frames: expected at least 2, got {n_frames}")
    resolved = resolve_source(source)  # bad input answered before anything is written
    out = ensure_writable_dir(out)
    scan, scene = open_source(resolved, n_frames, progress)
    result = reconstruct(scan, scene, labels, variant, seed=seed, progress=progress)
    write(result, out, scene, save_scan)
    return result


def write(result: Reconstruction, out: Path, scene: Scene | None = None, save_scan: bool = False) -> None:
    """A run's files in ``out``: ``initial.ply``, ``repaired.ply``, ``report.json`` (with the
    metrics against a scene's truth), ``before_after.png`` and, with ``save_scan``, ``scan/``."""
    import json

    import open3d as o3d

    from .io import atomic_write_text

    scan = result.scan
    o3d.io.write_triangle_mesh(str(out / "initial.ply"), scan.mesh)
    o3d.io.write_triangle_mesh(str(out / "repaired.ply"), result.repaired)
    report = result.report()
    if scene is not None:
        from .scan_metrics import score

        report["metrics"] = score(scene, scan.mesh, result.repaired)
    atomic_write_text(out / "report.json", json.dumps(report, indent=1, default=float) + "\n")
    before_after(result, out / "before_after.png")
    if save_scan:
        scan.save(out / "scan")


def summary(result: Reconstruction) -> str:
    """A table of the holes and what was done, for people."""
    lines = ["| hole | wall | area m2 | decision | material | p(closed) | frames | action |", "|---|---|---|---|---|---|---|---|"]
    for h in result.report()["holes"]:
        d, a = h["decision"], h["action"]
        act = ("filled" if a["filled"] else "left open") + (f", {a['phantom_triangles_removed']} phantom triangles removed"
                                                           if a["phantom_triangles_removed"] else "")
        lines.append(f"| {h['id']} | {h['wall']} | {h['area_m2']:.2f} | {d['state']} | {d['material'] or '-'} | "
                     f"{d['p_closed']:.3f} | {len(d['frames'])} | {act} |")
    return "\n".join(lines)
