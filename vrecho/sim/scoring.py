"""The truth: what a perfect decider says of each hole (:class:`Oracle`), and how good a repaired
scan is against the scene (the benchmark of the reconstruction).

Every metric reads only meshes, so any method is judged alike (vrecho's repair, open3d's
generic hole filling, no repair at all):

- the surface a method *added* is the part of its mesh more than 2 cm from the initial scan;
  rasterised on each true glass, mirror or opening rectangle (3 cm cells, 0.5 m around it);
- ``closed_iou``: area IoU of the added surface with each true glass or mirror rectangle;
- ``openings_filled``: share of openings more than half covered by added surface;
- ``phantom_removed``: share of the initial scan's phantom area (behind the walls and farther
  than 15 cm from any real surface: what a mirror makes) that is gone;
- ``depth_error_cm``: per filled glass or mirror, the median distance of its added surface
  from the true plane;
- ``chamfer_cm``: symmetric Chamfer distance, the mean of (mesh to the true scene, outside
  included) and (the room's true boundary, openings excluded, to the mesh).
"""

from __future__ import annotations

import copy

import numpy as np

from ..geometry import distance_to_polygon, point_in_polygon, triangulate_polygon
from ..reconstruct.decide import Decision
from ..reconstruct.discontinuities import Hole
from ..scene import Scene
from .ambient import SimulatedCapture, hear_scene
from .render import World


def match_truth(scene: Scene, hole: Hole, *, max_offset_m: float = 0.15) -> int | None:
    """The scene's discontinuity a hole belongs to (largest overlap on the same wall), or None.

    A discontinuity counts where the hole's plane faces into the room from its wall (within
    10 degrees), lies within ``max_offset_m`` of the wall's plane, and the hole's extent along
    the wall and in height overlaps the discontinuity's rectangle.

    Parameters
    ----------
    scene : Scene
        The scene.
    hole : vrecho.reconstruct.discontinuities.Hole
        A hole found in a scan.
    max_offset_m : float
        Largest distance of the hole from the wall's plane in metres (default 0.15).

    Returns
    -------
    int or None
        Index of the discontinuity of largest overlap, or None where none overlaps.
    """
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
    """The true answer for each hole: what a perfect EchoCNN would say.

    A hole that is none of the scene's discontinuities is plain wall the camera failed to see:
    closed, material "wall", on the nearest of the room's walls.

    Parameters
    ----------
    scene : Scene
        The scene.
    holes_ : list of vrecho.reconstruct.discontinuities.Hole
        Holes found in a scan.

    Returns
    -------
    list of vrecho.reconstruct.decide.Decision
        One per hole, source "oracle", confidence 1: "open"; or "closed" with the material
        (glass, mirror or wall), the true wall's plane at the hole's centre as ``offset_m``
        (metres), and ``p_mirror`` 1 for a mirror, 0 otherwise.
    """
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


class Oracle:
    """The truth as a decider of :func:`vrecho.reconstruct.reconstruct`.

    ``decide=Oracle(scene)``, ``vrecho reconstruct --labels oracle``: :func:`oracle`'s answers,
    no recordings needed.

    Parameters
    ----------
    scene : Scene
        The scene whose truth decides.

    Attributes
    ----------
    label : str
        "oracle".
    hears : bool
        False: the decider needs no echoes.
    scene : Scene
        The scene.
    """

    label = "oracle"
    hears = False

    def __init__(self, scene: Scene):
        self.scene = scene

    def __call__(self, holes_: list[Hole], views=None, echoes=None, *, mesh=None, walls=()) -> list[Decision]:
        """:func:`oracle`'s answers for ``holes_``.

        Parameters
        ----------
        holes_ : list of vrecho.reconstruct.discontinuities.Hole
            Holes found in a scan.
        views, echoes, mesh, walls
            What the reconstruction passes every decider; ignored.

        Returns
        -------
        list of vrecho.reconstruct.decide.Decision
            One per hole.
        """
        return oracle(self.scene, holes_)


ADDED_M = 0.02


CELL_M = 0.03


PHANTOM_M = 0.15


def _rc(mesh):
    import open3d as o3d  # heavy (1.2 s to import): only where meshes are made or ray-cast

    rc = o3d.t.geometry.RaycastingScene()
    rc.add_triangles(o3d.t.geometry.TriangleMesh.from_legacy(mesh))
    return rc


def _distance(rc, points: np.ndarray) -> np.ndarray:
    import open3d as o3d  # heavy (1.2 s to import): only where meshes are made or ray-cast

    if not len(points):
        return np.zeros(0)
    return rc.compute_distance(o3d.core.Tensor(points.astype(np.float32))).numpy().astype(float)


def _area(mesh) -> float:
    v, t = np.asarray(mesh.vertices), np.asarray(mesh.triangles)
    if not len(t):
        return 0.0
    return float(np.nansum(0.5 * np.linalg.norm(np.cross(v[t[:, 1]] - v[t[:, 0]], v[t[:, 2]] - v[t[:, 0]]), axis=1)))


def capped_density(mesh, density_per_m2: float, *, max_points: int = 3_000_000) -> float:
    """``density_per_m2``, lowered where the mesh is so large that more than ``max_points``
    would be drawn.

    A generic hole filler's triangles can span the outdoors.

    Parameters
    ----------
    mesh : open3d.geometry.TriangleMesh
        The mesh to be sampled.
    density_per_m2 : float
        Wanted points per square metre.
    max_points : int
        Most points to draw (default 3 000 000).

    Returns
    -------
    float
        Points per square metre.
    """
    return min(density_per_m2, max_points / max(_area(mesh), 1e-9))


def sample_surface(mesh, density_per_m2: float, *, seed: int = 0) -> np.ndarray:
    """Points spread uniformly over a mesh's area, ``density_per_m2`` of them per square metre.

    Each triangle gets a Poisson number of points of mean its area times the density.

    Parameters
    ----------
    mesh : open3d.geometry.TriangleMesh
        The mesh.
    density_per_m2 : float
        Mean points per square metre.
    seed : int
        Seed of the draw (default 0).

    Returns
    -------
    numpy.ndarray [shape=(N, 3)], float64
        The points in metres; none for a mesh without triangles.
    """
    v, t = np.asarray(mesh.vertices), np.asarray(mesh.triangles)
    if not len(t):
        return np.zeros((0, 3))
    a, b, c = v[t[:, 0]], v[t[:, 1]], v[t[:, 2]]
    area = np.nan_to_num(0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1))
    rng = np.random.default_rng(seed)
    n = rng.poisson(area * density_per_m2)
    idx = np.repeat(np.arange(len(t)), n)
    r1, r2 = rng.random(len(idx)), rng.random(len(idx))
    s = np.sqrt(r1)
    return (1 - s)[:, None] * a[idx] + (s * (1 - r2))[:, None] * b[idx] + (s * r2)[:, None] * c[idx]


def _sample_polygons(polygons: list[np.ndarray], n: int, seed: int = 0) -> np.ndarray:
    """About ``n`` points spread uniformly over planar polygons (K, 3)."""
    import open3d as o3d  # heavy (1.2 s to import): only where meshes are made or ray-cast

    verts, tris = [], []
    for p in polygons:
        tris.append(triangulate_polygon(p) + sum(len(v) for v in verts))
        verts.append(p)
    mesh = o3d.geometry.TriangleMesh(o3d.utility.Vector3dVector(np.vstack(verts)),
                                     o3d.utility.Vector3iVector(np.vstack(tris).astype(np.int32)))
    return sample_surface(mesh, n / _area(mesh), seed=seed)


def added_surface(initial, mesh, *, near: tuple[np.ndarray, np.ndarray] | None = None,
                  density_per_m2: float = 10_000.0) -> np.ndarray:
    """Points (N, 3) on the parts of ``mesh`` more than 2 cm from ``initial``.

    Parameters
    ----------
    initial : open3d.geometry.TriangleMesh
        The scan before repair.
    mesh : open3d.geometry.TriangleMesh
        The repaired mesh.
    near : tuple of (numpy.ndarray, numpy.ndarray), optional
        A box (lo, hi), each (3,) in metres: only triangles whose centroid lies inside count.
    density_per_m2 : float
        Points per square metre (default 10 000), capped by :func:`capped_density`.

    Returns
    -------
    numpy.ndarray [shape=(N, 3)], float64
        The added surface's points in metres.
    """
    import open3d as o3d  # heavy (1.2 s to import): only where meshes are made or ray-cast

    rc = _rc(initial)
    v, t = np.asarray(mesh.vertices), np.asarray(mesh.triangles)
    centroids = v[t].mean(axis=1)
    # Candidates: triangles with a vertex or the centroid off the initial scan.
    far = _distance(rc, v) > ADDED_M
    cand = far[t].any(axis=1) | (_distance(rc, centroids) > ADDED_M)
    if near is not None:
        cand &= np.all((centroids > near[0]) & (centroids < near[1]), axis=1)
    sub = o3d.geometry.TriangleMesh(mesh.vertices, o3d.utility.Vector3iVector(t[cand]))
    pts = sample_surface(sub, capped_density(sub, density_per_m2))
    return pts[_distance(rc, pts) > ADDED_M]


def phantom_area_m2(scene: Scene, mesh, *, world: World | None = None, density_per_m2: float = 400.0) -> float:
    """Area of a mesh behind the room's walls and farther than 15 cm from any real surface.

    Behind the walls: more than 10 cm outside the room's footprint; the real surfaces are the
    room's and the exterior's (:class:`~vrecho.sim.render.World`).

    Parameters
    ----------
    scene : Scene
        The scene.
    mesh : open3d.geometry.TriangleMesh
        The mesh.
    world : World, optional
        The scene's :class:`~vrecho.sim.render.World`, to reuse (made here when not given).
    density_per_m2 : float
        Sampling density in points per square metre (default 400), capped by
        :func:`capped_density`.

    Returns
    -------
    float
        The phantom area in square metres.
    """
    world = World(scene) if world is None else world
    density_per_m2 = capped_density(mesh, density_per_m2)
    pts = sample_surface(mesh, density_per_m2, seed=1)
    fp = scene.room.footprint
    outside = ~point_in_polygon(pts[:, :2], fp) & (distance_to_polygon(pts[:, :2], fp) > 0.1)
    pts = pts[outside]
    return float(np.sum(_distance(world._rc, pts) > PHANTOM_M)) / density_per_m2


def _finite(mesh):
    """A copy without the triangles that touch a non-finite vertex or one more than 10 km away
    (open3d's ``fill_holes`` makes both)."""
    v = np.asarray(mesh.vertices)
    with np.errstate(invalid="ignore"):
        bad = ~np.all(np.isfinite(v) & (np.abs(v) < 1e4), axis=1)
    if not bad.any():
        return mesh
    out = copy.deepcopy(mesh)
    out.remove_triangles_by_mask(bad[np.asarray(mesh.triangles)].any(axis=1))
    out.remove_unreferenced_vertices()
    return out


def score(scene: Scene, initial, mesh, *, world: World | None = None, n_chamfer: int = 40_000) -> dict:
    """The metrics of the module's docstring for ``mesh``, a repair of the scan ``initial``.

    Triangles with a non-finite vertex or one more than 10 km away are left out of both meshes
    first.

    Parameters
    ----------
    scene : Scene
        The scene scanned.
    initial : open3d.geometry.TriangleMesh
        The scan before repair.
    mesh : open3d.geometry.TriangleMesh
        The repaired mesh.
    world : World, optional
        The scene's :class:`~vrecho.sim.render.World`, to reuse (made here when not given).
    n_chamfer : int
        About how many points the Chamfer distance samples on each side (default 40 000).

    Returns
    -------
    dict
        "closed_iou" (mean over glass and mirrors, None without any) and "closed_ious" (each);
        "openings_filled" (None without openings) and "n_openings"; "phantom_m2_initial" and
        "phantom_m2" (square metres); "phantom_removed" (None where the initial phantom area is
        0.1 m2 or less); "depth_error_cm" (a list, per glass or mirror with more than 10 added
        points on it); "chamfer_cm".
    """
    world = World(scene) if world is None else world
    initial, mesh = _finite(initial), _finite(mesh)
    fp = scene.room.footprint
    box = (np.r_[fp.min(axis=0) - 1.0, -1.0], np.r_[fp.max(axis=0) + 1.0, scene.room.height_m + 1.0])
    added = added_surface(initial, mesh, near=box)
    ious, depth_errors, open_cover = [], [], []
    for k, d in enumerate(scene.discontinuities):
        origin, u, normal = scene.room.wall_frame(d.wall)
        u0, u1, z0, z1 = d.bounds()
        rel = added - origin
        off = rel @ normal
        uz = np.stack([rel @ u, rel[:, 2]], axis=1)
        near = (np.abs(off) < 0.3) & (uz[:, 0] > u0 - 0.5) & (uz[:, 0] < u1 + 0.5) & (uz[:, 1] > z0 - 0.5) & (uz[:, 1] < z1 + 0.5)
        lo = np.array([u0 - 0.5, z0 - 0.5])
        shape = tuple(np.ceil((np.array([u1 + 0.5, z1 + 0.5]) - lo) / CELL_M).astype(int))
        filled = np.zeros(shape, bool)
        ij = np.clip(((uz[near] - lo) / CELL_M).astype(int), 0, np.array(shape) - 1)
        filled[ij[:, 0], ij[:, 1]] = True
        cu = lo[0] + CELL_M * (np.arange(shape[0]) + 0.5)
        cz = lo[1] + CELL_M * (np.arange(shape[1]) + 0.5)
        truth = ((cu > u0) & (cu < u1))[:, None] & ((cz > z0) & (cz < z1))[None, :]
        inter = (filled & truth).sum()
        if d.is_open:
            open_cover.append(inter / truth.sum())
            continue
        ious.append(inter / (filled | truth).sum())
        inside = near & (uz[:, 0] > u0) & (uz[:, 0] < u1) & (uz[:, 1] > z0) & (uz[:, 1] < z1)
        if inside.sum() > 10:
            depth_errors.append(100 * float(np.median(np.abs(off[inside]))))
    shell = [p.corners for p in scene.patches() if p.kind != "open"]
    truth_pts = _sample_polygons(shell, n_chamfer, seed=2)
    mesh_pts = sample_surface(mesh, n_chamfer / max(mesh.get_surface_area(), 1e-9), seed=3)
    chamfer = 0.5 * (_distance(world._rc, mesh_pts).mean() + _distance(_rc(mesh), truth_pts).mean())
    phantom0 = phantom_area_m2(scene, initial, world=world)
    phantom = phantom_area_m2(scene, mesh, world=world)
    return {
        "closed_iou": float(np.mean(ious)) if ious else None,
        "closed_ious": [float(x) for x in ious],
        "openings_filled": float(np.mean(np.array(open_cover) > 0.5)) if open_cover else None,
        "n_openings": len(open_cover),
        "phantom_m2_initial": phantom0,
        "phantom_m2": phantom,
        "phantom_removed": 1 - phantom / phantom0 if phantom0 > 0.1 else None,
        "depth_error_cm": depth_errors,
        "chamfer_cm": 100 * float(chamfer),
    }


class SceneTruth:
    """What the simulator knows of a scene that a command may ask.

    The answers (:meth:`oracle`), the repair's metrics (:meth:`score`) and its sources heard
    along the walkthrough (:meth:`captures`).

    Parameters
    ----------
    scene : Scene
        The scene.
    """

    def __init__(self, scene: Scene):
        self.scene = scene

    def oracle(self) -> Oracle:
        """The scene's :class:`Oracle`, a decider for the reconstruction.

        Returns
        -------
        Oracle
            The truth as a decider.
        """
        return Oracle(self.scene)

    def score(self, initial, repaired) -> dict:
        """:func:`score` of a repair of the scan ``initial``.

        Parameters
        ----------
        initial : open3d.geometry.TriangleMesh
            The scan before repair.
        repaired : open3d.geometry.TriangleMesh
            The repaired mesh.

        Returns
        -------
        dict
            The metrics, as :func:`score`.
        """
        return score(self.scene, initial, repaired)

    def captures(self, rng, *, n_poses: int = 8) -> SimulatedCapture:
        """The scene's sources heard by the headset along its walkthrough (:func:`~.ambient.hear_scene`).

        Parameters
        ----------
        rng : numpy.random.Generator
            Source of the sounds and the noise.
        n_poses : int
            Number of captures along the walkthrough (default 8).

        Returns
        -------
        SimulatedCapture
            The captures and each source's image at every microphone.

        Raises
        ------
        VrechoError
            If the scene has no sound sources.
        """
        return hear_scene(self.scene, rng, n_poses=n_poses)
