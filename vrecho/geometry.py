"""Plane geometry of polygons: their area and winding, which points fall inside, how far points
lie from their boundary, their triangles. Rooms (:mod:`vrecho.scene`), holes in a scan
(:mod:`vrecho.reconstruct`) and the simulator's surfaces all use it.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import Delaunay


def signed_area(polygon: np.ndarray) -> float:
    x, y = polygon[:, 0], polygon[:, 1]
    return 0.5 * float(np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y))


def point_in_polygon(points: np.ndarray, polygon: np.ndarray) -> np.ndarray:
    """Even-odd test of 2-D points (N, 2) against a polygon (K, 2); returns bool (N,)."""
    p = np.atleast_2d(points)[:, None, :]
    a, b = polygon[None, :, :], np.roll(polygon, -1, axis=0)[None, :, :]
    crosses = (a[..., 1] > p[..., 1]) != (b[..., 1] > p[..., 1])
    with np.errstate(divide="ignore", invalid="ignore"):
        x_at = a[..., 0] + (p[..., 1] - a[..., 1]) * (b[..., 0] - a[..., 0]) / (b[..., 1] - a[..., 1])
    return np.sum(crosses & (p[..., 0] < x_at), axis=1) % 2 == 1


def distance_to_polygon(points: np.ndarray, polygon: np.ndarray) -> np.ndarray:
    """Distance (N,) of 2-D points to the polygon's boundary."""
    p = np.atleast_2d(points)[:, None, :]
    a, b = polygon[None], np.roll(polygon, -1, axis=0)[None]
    ab = b - a
    t = np.clip(np.sum((p - a) * ab, -1) / np.sum(ab * ab, -1), 0, 1)
    return np.min(np.linalg.norm(p - (a + t[..., None] * ab), axis=-1), axis=1)


def triangulate_polygon(corners: np.ndarray) -> np.ndarray:
    """Triangles of a planar polygon (K, 3): a fan when convex, else Delaunay triangles whose
    centroids fall inside the polygon."""
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
    def orient(a, b, c):
        return np.sign((b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]))
    return orient(p1, p2, p3) * orient(p1, p2, p4) < 0 and orient(p3, p4, p1) * orient(p3, p4, p2) < 0
