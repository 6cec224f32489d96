"""The repair, the paper's Algorithm 1: fill what is closed, empty what a mirror made, leave
openings open (:func:`repair`, both its variants).
"""

from __future__ import annotations

import copy
from dataclasses import dataclass

import numpy as np
from scipy.spatial import ConvexHull

from ..errors import VrechoError
from ..geometry import distance_to_polygon, point_in_polygon
from .decide import Decision
from .discontinuities import Hole, seen_through

SURFACE_COLOURS = {"glass": (0.55, 0.75, 0.95), "mirror": (0.85, 0.85, 0.9), "wall": (0.6, 0.6, 0.6)}


VARIANTS = ("simplified", "per_vertex")


@dataclass
class Surface:
    """A surface the repair added.

    Parameters
    ----------
    hole : int
        Index of the hole it fills, in the holes given to :func:`repair`.
    material : str
        ``"glass"``, ``"mirror"`` or ``"wall"`` (a closed hole of no material given).
    polygon : numpy.ndarray [shape=(K, 3)], float
        Its outline, world coordinates in metres.
    normal : numpy.ndarray [shape=(3,)], float
        Unit normal of the hole's wall, into the room.
    confidence : float
        The decision's confidence.
    triangles : numpy.ndarray [shape=(F, 3)], int
        Its triangles, as indices into the repaired mesh's vertices.
    """

    hole: int
    material: str
    polygon: np.ndarray
    normal: np.ndarray
    confidence: float
    triangles: np.ndarray

    @property
    def area_m2(self) -> float:
        """The polygon's area in square metres."""
        p = self.polygon - self.polygon[0]
        return float(0.5 * np.linalg.norm(np.cross(p[1:-1], p[2:]).sum(axis=0)))


def repair(mesh, holes_: list[Hole], decisions: list[Decision], cameras: np.ndarray, *, variant: str = "simplified",
           min_component_triangles: int = 200, rim_m: float = 0.06):
    """The paper's Algorithm 1: fill what is closed, empty what a mirror made, leave openings open.

    Parameters
    ----------
    mesh : open3d.geometry.TriangleMesh
        The initial reconstruction (not modified).
    holes_ : list of :class:`~.discontinuities.Hole`
        The holes found (:func:`~.discontinuities.holes`).
    decisions : list of :class:`~.decide.Decision`
        What each hole is (:func:`~.decide.infer` or :func:`vrecho.sim.scoring.oracle`), one per
        hole, in the same order.
    cameras : numpy.ndarray [shape=(N, 3)], float
        Camera positions of the walkthrough in metres (which phantom geometry was seen through
        a mirror).
    variant : {"simplified", "per_vertex"}
        ``simplified`` (the default): a new face, the convex hull of the hole's outline, at the
        decided plane. ``per_vertex``: the mesh's own vertices around the hole (within 5 cm of
        the wall's plane and ``rim_m`` of its outline, outside it) on the convex hull are moved
        to the decided plane and the hull is filled from them, so the patch is stitched to the
        scan; with fewer than three such vertices the hole is filled as ``simplified`` (and
        ``actions`` records it).
    min_component_triangles : int
        Connected pieces with fewer triangles are removed (loose fragments; default 200).
    rim_m : float
        Width of the rim around a hole's outline, in metres, whose vertices ``per_vertex``
        takes (default 0.06).

    Returns
    -------
    repaired : open3d.geometry.TriangleMesh
        The repaired mesh, with vertex normals; added surfaces are coloured by material
        (:data:`SURFACE_COLOURS`), and a mesh without vertex colours gets grey ones.
    surfaces : list of :class:`Surface`
        One per closed hole, in the holes' order.
    actions : list of dict
        One per hole: what was done (``filled``; ``phantom_triangles_removed`` behind a mirror;
        ``fragment_triangles_removed`` floating in an opening, within 0.1 m of its plane; and
        for a filled hole ``fill``, the variant used, and ``fill_vertices``).

    Raises
    ------
    VrechoError
        For an unknown ``variant``, or when ``holes_`` and ``decisions`` differ in length.
    """
    import open3d as o3d  # heavy (1.2 s to import): only where meshes are made or ray-cast

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
