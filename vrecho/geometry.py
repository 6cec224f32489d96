"""Plane geometry of polygons: their area and winding, which points fall inside, how far points
lie from their boundary, their triangles, a wall's rectangles around its holes. Rooms (:mod:`vrecho.scene`), holes in a scan
(:mod:`vrecho.reconstruct`) and the simulator's surfaces all use it.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import Delaunay


def signed_area(polygon: np.ndarray) -> float:
    """Signed area of a plane polygon (the shoelace formula): positive when counter-clockwise.

    Parameters
    ----------
    polygon : numpy.ndarray, shape (K, 2), float
        Corners in order, in metres; the last joins the first.

    Returns
    -------
    float
        Area in square metres; negative when the corners run clockwise.

    Examples
    --------
    >>> square = np.array([[0.0, 0.0], [2.0, 0.0], [2.0, 1.0], [0.0, 1.0]])
    >>> signed_area(square)
    2.0
    >>> signed_area(square[::-1])
    -2.0
    """
    x, y = polygon[:, 0], polygon[:, 1]
    return 0.5 * float(np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y))


def point_in_polygon(points: np.ndarray, polygon: np.ndarray) -> np.ndarray:
    """Even-odd test of 2-D points against a polygon.

    Parameters
    ----------
    points : numpy.ndarray, shape (N, 2) or (2,), float
        Points in the polygon's plane, in metres.
    polygon : numpy.ndarray, shape (K, 2), float
        Corners in order, either winding, in metres.

    Returns
    -------
    numpy.ndarray, shape (N,), bool
        True for each point inside the polygon.

    Examples
    --------
    >>> square = np.array([[0.0, 0.0], [2.0, 0.0], [2.0, 1.0], [0.0, 1.0]])
    >>> point_in_polygon(np.array([[1.0, 0.5], [3.0, 0.5]]), square)
    array([ True, False])
    """
    p = np.atleast_2d(points)[:, None, :]
    a, b = polygon[None, :, :], np.roll(polygon, -1, axis=0)[None, :, :]
    crosses = (a[..., 1] > p[..., 1]) != (b[..., 1] > p[..., 1])
    with np.errstate(divide="ignore", invalid="ignore"):
        x_at = a[..., 0] + (p[..., 1] - a[..., 1]) * (b[..., 0] - a[..., 0]) / (b[..., 1] - a[..., 1])
    return np.sum(crosses & (p[..., 0] < x_at), axis=1) % 2 == 1


def distance_to_polygon(points: np.ndarray, polygon: np.ndarray) -> np.ndarray:
    """Distance of 2-D points to the polygon's boundary, inside or out.

    Parameters
    ----------
    points : numpy.ndarray, shape (N, 2) or (2,), float
        Points in the polygon's plane, in metres.
    polygon : numpy.ndarray, shape (K, 2), float
        Corners in order, in metres.

    Returns
    -------
    numpy.ndarray, shape (N,), float
        Distance in metres to the nearest edge (unsigned).
    """
    p = np.atleast_2d(points)[:, None, :]
    a, b = polygon[None], np.roll(polygon, -1, axis=0)[None]
    ab = b - a
    t = np.clip(np.sum((p - a) * ab, -1) / np.sum(ab * ab, -1), 0, 1)
    return np.min(np.linalg.norm(p - (a + t[..., None] * ab), axis=-1), axis=1)


def triangulate_polygon(corners: np.ndarray) -> np.ndarray:
    """Triangles of a planar polygon in 3-D space.

    A fan from the first corner when the polygon is convex, else the Delaunay triangles of its
    corners whose centroids fall inside the polygon.

    Parameters
    ----------
    corners : numpy.ndarray, shape (K, 3), float
        Corners of a planar polygon in order, in metres; K >= 3.

    Returns
    -------
    numpy.ndarray, shape (T, 3), int
        Indices into ``corners`` of each triangle's corners (K - 2 triangles for a convex
        polygon).
    """
    k = len(corners)
    if k == 3:
        return np.array([[0, 1, 2]])
    normal = np.cross(corners[1] - corners[0], corners[-1] - corners[0])
    normal /= np.linalg.norm(normal)
    e1 = (corners[1] - corners[0]) / np.linalg.norm(corners[1] - corners[0])
    e2 = np.cross(normal, e1)
    p2 = np.stack([(corners - corners[0]) @ e1, (corners - corners[0]) @ e2], axis=1)
    edges = np.roll(p2, -1, axis=0) - p2
    cross = edges[:, 0] * np.roll(edges, -1, axis=0)[:, 1] - edges[:, 1] * np.roll(edges, -1, axis=0)[:, 0]
    if np.all(cross >= -1e-12) or np.all(cross <= 1e-12):
        return np.array([[0, i, i + 1] for i in range(1, k - 1)])
    tri = Delaunay(p2).simplices
    keep = point_in_polygon(p2[tri].mean(axis=1), p2)
    return tri[keep]


def segments_cross(p1, p2, p3, p4) -> bool:
    """Whether the 2-D segments p1-p2 and p3-p4 cross each other.

    Only a proper crossing counts: segments that merely touch (an end on the other segment, a
    shared end) or that lie on one line do not cross.

    Parameters
    ----------
    p1, p2 : array_like, shape (2,), float
        Ends of the first segment, in metres.
    p3, p4 : array_like, shape (2,), float
        Ends of the second segment, in metres.

    Returns
    -------
    bool
        True when the segments cross.
    """
    def orient(a, b, c):
        return np.sign((b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]))
    return orient(p1, p2, p3) * orient(p1, p2, p4) < 0 and orient(p3, p4, p1) * orient(p3, p4, p2) < 0


def rectangles_around(length: float, height: float, holes: list) -> list[tuple]:
    """Rectangles covering a rectangle (a wall) except the holes in it.

    A grid on every hole edge, its free cells merged along each row.

    Parameters
    ----------
    length, height : float
        The wall's size, in metres; it spans u in [0, length], z in [0, height].
    holes : list of (float, float, float, float)
        Each hole's (u0, u1, z0, z1), in metres, inside the wall.

    Returns
    -------
    list of (float, float, float, float)
        The covering rectangles' (u0, u1, z0, z1), row by row from the floor.

    Examples
    --------
    >>> rectangles_around(3.0, 2.0, [(1.0, 2.0, 0.5, 1.5)])
    [(0.0, 3.0, 0.0, 0.5), (0.0, 1.0, 0.5, 1.5), (2.0, 3.0, 0.5, 1.5), (0.0, 3.0, 1.5, 2.0)]
    """
    us = sorted({0.0, length, *[v for h in holes for v in h[:2]]})
    zs = sorted({0.0, height, *[v for h in holes for v in h[2:]]})
    rects = []
    for z0, z1 in zip(zs[:-1], zs[1:]):
        if z1 - z0 < 1e-9:
            continue
        start = None
        for u0, u1 in zip(us[:-1], us[1:]):
            um, zm = (u0 + u1) / 2, (z0 + z1) / 2
            free = not any(h[0] < um < h[1] and h[2] < zm < h[3] for h in holes)
            if free and start is None:
                start = u0
            if not free and start is not None:
                rects.append((start, u0, z0, z1))
                start = None
        if start is not None:
            rects.append((start, us[-1], z0, z1))
    return [r for r in rects if r[1] - r[0] > 1e-9]
