"""The scan's discontinuities: its walls (:func:`wall_planes`, RANSAC; the nearest plane to the
cameras in each direction that is not seen only through another), the holes in them
(:func:`holes`, free space carved by the depth frames), the geometry behind them
(:func:`beyond_walls`, :func:`seen_through`) and the frames that look at a hole (:func:`facing`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import ndimage
from scipy.spatial import ConvexHull

from ..camera import View, project
from ..geometry import signed_area


@dataclass
class Plane:
    """A planar surface found in the scan.

    Parameters
    ----------
    normal : numpy.ndarray [shape=(3,)], float
        Unit normal, pointing into the room (toward the cameras).
    offset : float
        The plane's offset in metres: points x with normal . x + offset = 0.
    inliers : numpy.ndarray [shape=(M, 3)], float
        The scan's vertices on the plane, world coordinates in metres.
    """

    normal: np.ndarray
    offset: float
    inliers: np.ndarray  # (M, 3)

    @property
    def vertical(self) -> bool:
        """Whether the plane is vertical: its normal's z below 0.1 (6 degrees off horizontal)."""
        return abs(self.normal[2]) < 0.1

    def frame(self) -> tuple[np.ndarray, np.ndarray]:
        """In-plane unit axes of a vertical plane: along the wall, and up.

        Along the wall is the direction of the scene's own wall axis (normal x up), so crops are
        not mirrored.

        Returns
        -------
        along, up : numpy.ndarray [shape=(3,)], float
            Unit vectors in world coordinates; ``up`` is the world's z.
        """
        up = np.array([0.0, 0.0, 1.0])
        along = np.cross(self.normal, up)
        return along / np.linalg.norm(along), up

    def to_wall(self, points: np.ndarray) -> np.ndarray:
        """Wall coordinates of world points.

        Parameters
        ----------
        points : numpy.ndarray [shape=(N, 3) or (3,)], float
            World points in metres.

        Returns
        -------
        numpy.ndarray [shape=(N, 2)], float
            Their coordinates along the wall and up (see :meth:`frame`): dot products with
            those axes, in metres.
        """
        return np.atleast_2d(points) @ np.stack(self.frame(), axis=1)

    def to_world(self, uz: np.ndarray, offset: float | None = None) -> np.ndarray:
        """World points of wall coordinates, on the plane (or at another ``offset``).

        Parameters
        ----------
        uz : numpy.ndarray [shape=(N, 2) or (2,)], float
            Coordinates along the wall and up (see :meth:`frame`), in metres.
        offset : float, optional
            Offset in metres of a parallel plane to place the points on (same normal); the
            plane's own by default.

        Returns
        -------
        numpy.ndarray [shape=(N, 3)], float
            World points in metres.
        """
        along, up = self.frame()
        offset = self.offset if offset is None else offset
        uz = np.atleast_2d(uz)
        return -offset * self.normal + uz[:, :1] * along + uz[:, 1:] * up


@dataclass
class Hole:
    """An empty region of a wall plane, seen through by the depth camera.

    Parameters
    ----------
    plane : Plane
        The wall the hole is in.
    outline : numpy.ndarray [shape=(K, 2)], float
        A convex polygon in the wall's frame (``u`` along the wall, ``z`` up, metres; see
        :meth:`Plane.frame`).
    area_m2 : float
        Its area in square metres (of the empty cells found, :func:`holes`).

    Examples
    --------
    A 1 m square hole in a wall at x = 2 m, facing a room at the origin:

    >>> import numpy as np
    >>> from vrecho.reconstruct import Hole, Plane
    >>> wall = Plane(np.array([-1.0, 0.0, 0.0]), 2.0, np.zeros((0, 3)))
    >>> hole = Hole(wall, np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]]), 1.0)
    >>> hole.contains(np.array([[2.0, 0.5, 0.5], [2.0, 1.5, 0.5]]))
    array([ True, False])
    >>> hole.corners().shape
    (4, 3)
    """

    plane: Plane
    outline: np.ndarray
    area_m2: float

    @property
    def u(self) -> tuple[float, float]:
        """The outline's extent along the wall (lowest, highest), in metres."""
        return float(self.outline[:, 0].min()), float(self.outline[:, 0].max())

    @property
    def z(self) -> tuple[float, float]:
        """The outline's extent up the wall (lowest, highest), in metres."""
        return float(self.outline[:, 1].min()), float(self.outline[:, 1].max())

    def corners(self) -> np.ndarray:
        """The outline's bounding rectangle in the world.

        Returns
        -------
        numpy.ndarray [shape=(4, 3)], float
            World corners in metres, wound like the scene's walls: (u0, z0), (u1, z0), (u1, z1),
            (u0, z1), with ``u0, u1 =`` :attr:`u` and ``z0, z1 =`` :attr:`z`.
        """
        (u0, u1), (z0, z1) = self.u, self.z
        return self.plane.to_world(np.array([[u0, z0], [u1, z0], [u1, z1], [u0, z1]]))

    def polygon(self, offset: float | None = None) -> np.ndarray:
        """The outline in world coordinates.

        Parameters
        ----------
        offset : float, optional
            Offset in metres of a parallel plane to place it on (see :meth:`Plane.to_world`);
            the wall's own by default.

        Returns
        -------
        numpy.ndarray [shape=(K, 3)], float
            The outline's vertices in metres.
        """
        return self.plane.to_world(self.outline, offset)

    def contains(self, points: np.ndarray, *, margin_m: float = 0.0) -> np.ndarray:
        """Whether world points project into the outline (convex; widened by about ``margin_m``).

        Parameters
        ----------
        points : numpy.ndarray [shape=(N, 3) or (3,)], float
            World points in metres; they are projected on the wall along its normal.
        margin_m : float
            How far, in metres, each edge is moved outward (negative: inward) before the test
            (default 0).

        Returns
        -------
        numpy.ndarray [shape=(N,)], bool
        """
        uz = self.plane.to_wall(points)
        a = self.outline
        e = np.roll(a, -1, axis=0) - a
        e = e / np.linalg.norm(e, axis=1, keepdims=True)
        cross = e[:, 0] * (uz[:, None, 1] - a[:, 1]) - e[:, 1] * (uz[:, None, 0] - a[:, 0])
        sign = 1.0 if signed_area(a) > 0 else -1.0
        return np.all(sign * cross >= -margin_m, axis=1)


def wall_planes(vertices: np.ndarray, cameras: np.ndarray, *, distance_m: float = 0.03, min_share: float = 0.003,
                max_planes: int = 20, seed: int = 0) -> list[Plane]:
    """The room's walls: planes found by RANSAC (open3d ``segment_plane``), one after another, of
    which the vertical ones nearest the cameras in each direction are kept (a phantom room
    behind a mirror, or buildings through a window, lie farther along the same directions).

    Of the vertical planes, only dense surfaces are kept (at least a tenth as dense as the
    densest); points seen only through another plane are dropped; a plane much smaller than
    another facing the same way, or with a camera behind it, is no wall; coplanar pieces of a
    wall (a door splits it) are merged. Walls are refitted exactly vertical. The vertices are
    put in a canonical order first, so the result does not depend on theirs.

    Parameters
    ----------
    vertices : numpy.ndarray [shape=(N, 3)], float
        The scan's mesh vertices, world coordinates in metres (z up).
    cameras : numpy.ndarray [shape=(M, 3)], float
        Camera positions of the walkthrough, in metres.
    distance_m : float
        RANSAC's inlier distance to a plane, in metres (default 0.03).
    min_share : float
        Fewest inliers of a plane, as a share of ``vertices`` (default 0.003).
    max_planes : int
        Most planes RANSAC draws (default 20).
    seed : int
        open3d's random seed, for repeatable walls.

    Returns
    -------
    list of Plane
        One vertical wall per direction, normals toward the cameras, nearest the cameras'
        centre first.
    """
    import open3d as o3d  # heavy (1.2 s to import): only where meshes are made or ray-cast

    o3d.utility.random.seed(seed)
    rest = np.asarray(vertices, float)
    # RANSAC draws by index, so a canonical order of the vertices makes the walls repeatable
    # whatever order they come in; and it runs on one thread (the caller's setting restored):
    # open3d's threads each draw from the one seeded generator, so which planes it finds
    # depended on their timing and on the machine's cores (a mirror's wall found, or its
    # phantom room's taken for it, from run to run of one scan).
    rest = rest[np.lexsort(rest.T[::-1])]
    centre = np.asarray(cameras, float).mean(axis=0)
    found = []
    threads = o3d.utility.get_max_threads()
    o3d.utility.set_max_threads(1)
    try:
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
    finally:
        o3d.utility.set_max_threads(threads)
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


def holes(plane: Plane, views: list[View], walls: list[Plane] = (), *, cell_m: float = 0.03, min_area_m2: float = 0.1,
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
    in this plane too. Single empty cells (at depth edges) are removed by a morphological opening
    before the empty cells are grouped into connected regions.

    Parameters
    ----------
    plane : Plane
        The wall (from :func:`wall_planes`).
    views : list of :class:`~vrecho.camera.View`
        The depth frames (z-depth in metres, 0 where the sensor returned nothing).
    walls : list of Plane
        The room's walls (``plane`` may be among them); none by default.
    cell_m : float
        Side of a raster cell in metres (default 0.03).
    min_area_m2 : float
        Smallest hole kept, in square metres (default 0.1).
    margin_m : float
        Tolerance in metres: a depth reading within it of a cell agrees with the wall, one more
        than it beyond the cell saw through; and how far behind another wall a cell must lie to
        be left out (default 0.1).

    Returns
    -------
    list of Hole
        One per connected region of empty cells, its outline the convex hull of the cells.
    """
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


def beyond_walls(vertices: np.ndarray, walls: list[Plane], *, margin_m: float = 0.1) -> np.ndarray:
    """Which vertices lie more than ``margin_m`` behind a wall plane: what the camera saw through
    glass or an opening, or the phantom room a mirror makes (the repair tells them apart).

    Parameters
    ----------
    vertices : numpy.ndarray [shape=(N, 3)], float
        World points in metres.
    walls : list of Plane
        The room's walls, normals into the room.
    margin_m : float
        How far behind a wall, in metres, a vertex must lie (default 0.1).

    Returns
    -------
    numpy.ndarray [shape=(N,)], bool
        True for vertices behind any wall.
    """
    v = np.asarray(vertices, float)
    out = np.zeros(len(v), bool)
    for w in walls:
        out |= v @ w.normal + w.offset < -margin_m
    return out


def facing(views: list[View], hole: Hole, *, max_incidence_deg: float = 25.0,
           depth_range_m: tuple[float, float] = (0.25, 3.5), margin_m: float = 0.05) -> list[int]:
    """Frames that look at a hole: the camera's axis meets its outline (widened by ``margin_m``)
    within ``max_incidence_deg`` of the wall's normal, from ``depth_range_m`` (about EchoCNN's
    range).

    Parameters
    ----------
    views : list of :class:`~vrecho.camera.View`
        The frames, camera-to-world poses in metres.
    hole : Hole
        The hole.
    max_incidence_deg : float
        Largest angle, in degrees, between the camera's axis and the wall's normal (default 25).
    depth_range_m : tuple of float
        Nearest and farthest distance in metres from the camera to the wall's plane, along the
        normal (default 0.25 to 3.5 m).
    margin_m : float
        How far the outline is widened, in metres (default 0.05).

    Returns
    -------
    list of int
        Indices into ``views``, in their order.
    """
    n, offset = hole.plane.normal, hole.plane.offset
    out = []
    for i, view in enumerate(views):
        c, f = view.pose[:3, 3], view.pose[:3, 2]
        cos = -float(n @ f)
        depth = float(n @ c + offset)
        if cos < np.cos(np.radians(max_incidence_deg)) or not depth_range_m[0] <= depth <= depth_range_m[1]:
            continue
        if hole.contains((c + depth / cos * f)[None], margin_m=margin_m)[0]:
            out.append(i)
    return out


def seen_through(points: np.ndarray, hole: Hole, cameras: np.ndarray, *, margin_m: float = 0.1,
                 max_cameras: int = 12) -> np.ndarray:
    """Which points lie behind a hole's plane where a camera saw them through the hole: the line
    from some camera (at most ``max_cameras`` of those in front, evenly spread) to the point
    crosses the hole's outline (widened by 5 cm).

    Parameters
    ----------
    points : numpy.ndarray [shape=(N, 3)], float
        World points in metres.
    hole : Hole
        The hole.
    cameras : numpy.ndarray [shape=(M, 3)], float
        Camera positions in metres; those less than 0.1 m in front of the hole's plane are not
        used.
    margin_m : float
        How far behind the plane, in metres, a point must lie (default 0.1).
    max_cameras : int
        Most cameras tried (default 12).

    Returns
    -------
    numpy.ndarray [shape=(N,)], bool
    """
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
        out[idx[hole.contains(c + t[:, None] * (p - c), margin_m=0.05)]] = True
    return out
