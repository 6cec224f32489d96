"""The camera's scan: walkthrough frames fused by open3d, with the sensor's glass and mirror failures."""

import numpy as np
import pytest
from scipy.spatial import cKDTree

import vrecho
from vrecho.errors import VrechoError
from vrecho.reconstruct import fuse
from vrecho.sim.scans import walkthrough
from vrecho.camera import Camera

from conftest import small_room


@pytest.fixture(scope="module")
def scan():
    scene = vrecho.builtin_scene()
    views = walkthrough(scene, n_frames=30, camera=Camera(160, 120))
    mesh = fuse(views, voxel_m=0.04)
    return scene, np.asarray(mesh.vertices), views


def _coverage(tree, origin, u, v, lo, hi, n=(30, 15)):
    """Share of a grid of points on a wall rectangle with a mesh vertex within 6 cm."""
    a, b = np.meshgrid(np.linspace(lo[0], hi[0], n[0]), np.linspace(lo[1], hi[1], n[1]))
    pts = origin + a.reshape(-1, 1) * u + b.reshape(-1, 1) * v
    return float(np.mean(tree.query(pts)[0] < 0.06))


def test_the_scan_covers_the_walls_but_not_glass_or_mirror(scan):
    scene, vertices, views = scan
    tree = cKDTree(vertices)
    up = np.array([0.0, 0.0, 1.0])
    walls = {}
    for i in range(len(scene.room.footprint)):
        o, u, _ = scene.room.wall_frame(i)
        length = np.linalg.norm(scene.room.footprint[(i + 1) % len(scene.room.footprint)] - scene.room.footprint[i])
        walls[i] = _coverage(tree, o, u, up, (0.1, 0.8), (length - 0.1, 2.2))  # the band the camera looks at
    assert sum(c > 0.6 for c in walls.values()) >= 3, walls
    for k, disc in enumerate(scene.discontinuities):
        if disc.kind in ("glass", "mirror"):
            o, u, _ = scene.room.wall_frame(disc.wall)
            c = scene.discontinuity_corners(k)
            lo, hi = ((c - o) @ u).min() + 0.1, ((c - o) @ u).max() - 0.1
            hole = _coverage(tree, o, u, up, (lo, c[:, 2].min() + 0.1), (hi, c[:, 2].max() - 0.1), (10, 10))
            assert hole < 0.3, (disc.kind, hole)  # the depth sensor sees through: a hole in the scan


def test_a_mirror_makes_a_phantom_room(scan):
    scene, vertices, views = scan
    k = next(i for i, d in enumerate(scene.discontinuities) if d.kind == "mirror")
    wall = scene.discontinuities[k].wall
    o, u, n = scene.room.wall_frame(wall)
    length = np.linalg.norm(scene.room.footprint[(wall + 1) % len(scene.room.footprint)] - scene.room.footprint[wall])
    along = (vertices - o) @ u
    behind = (vertices - o) @ n
    phantom = (behind > 0.3) & (along > 0) & (along < length)
    assert phantom.sum() > 1000  # surfaces reconstructed beyond a wall that has no window


def test_walkthrough_needs_a_path():
    scene = vrecho.builtin_scene()
    scene.camera_path = None
    with pytest.raises(VrechoError, match="camera_path"):
        walkthrough(scene)


def test_fusion_skips_frames_without_depth_and_says_when_none_has_any(scan):
    from vrecho.camera import View

    scene, vertices, views = scan
    blank = View(np.zeros_like(views[0].gray), np.zeros_like(views[0].depth), views[0].intrinsics, views[0].pose)
    mesh = fuse([blank, views[0], views[1], blank], voxel_m=0.06)  # open3d alone aborts on a frame with no depth
    assert len(mesh.triangles) > 100
    with pytest.raises(VrechoError, match="no frame has a depth"):
        fuse([blank, blank])


def test_holes_in_the_walls_are_the_glass_opening_and_mirror(scan):
    from vrecho.reconstruct import holes, wall_planes

    scene, vertices, views = scan
    walls = wall_planes(vertices, np.array([v.pose[:3, 3] for v in views]))
    found = [h for plane in walls for h in holes(plane, views, walls)]
    assert len(found) == len(scene.discontinuities)  # the phantom room's walls hold no holes
    for k, disc in enumerate(scene.discontinuities):
        c = scene.discontinuity_corners(k)
        best = 0.0
        for h in found:
            hc = h.corners()
            if np.abs((hc - c[0]) @ scene.room.wall_frame(disc.wall)[2]).max() > 0.1:
                continue  # another wall
            lo_t, hi_t = c.min(axis=0), c.max(axis=0)
            lo_h, hi_h = hc.min(axis=0), hc.max(axis=0)
            inter = np.prod([max(0.0, min(hi_t[i], hi_h[i]) - max(lo_t[i], lo_h[i])) for i in range(3) if hi_t[i] - lo_t[i] > 1e-6])
            union = np.prod([hi_t[i] - lo_t[i] for i in range(3) if hi_t[i] - lo_t[i] > 1e-6]) + h.area_m2 - inter
            best = max(best, inter / union)
        assert best > 0.6, (disc.kind, best)


def test_the_walls_are_the_same_whatever_the_vertices_order_and_the_callers_threads(scan):
    """open3d's RANSAC on several threads found a mirror's wall in one run and its phantom room's
    in the next (bench_reconstruct's room 8 of seed 4500); and its fusion orders the vertices
    differently each run."""
    import open3d as o3d

    from vrecho.reconstruct import wall_planes
    from vrecho.reconstruct.scan import canonical

    scene, vertices, views = scan
    cameras = np.array([v.pose[:3, 3] for v in views])
    threads = o3d.utility.get_max_threads()
    try:
        answers = []
        for k, n in enumerate((1, 2, 2)):  # (open3d allows as many as the machine has cores)
            o3d.utility.set_max_threads(n)
            callers = o3d.utility.get_max_threads()
            order = np.random.default_rng(k).permutation(len(vertices))
            answers.append([(w.normal.tolist(), w.offset, len(w.inliers)) for w in wall_planes(vertices[order], cameras)])
            assert o3d.utility.get_max_threads() == callers  # the caller's setting given back
    finally:
        o3d.utility.set_max_threads(threads)
    assert answers[0] == answers[1] == answers[2] and len(answers[0]) >= 4
    mesh = fuse(views[:8], voxel_m=0.06)
    order = np.random.default_rng(0).permutation(len(mesh.vertices))
    shuffled = o3d.geometry.TriangleMesh(o3d.utility.Vector3dVector(np.asarray(mesh.vertices)[order]),
                                         o3d.utility.Vector3iVector(np.argsort(order)[np.asarray(mesh.triangles)][::-1]))
    again = canonical(shuffled)
    assert np.array_equal(np.asarray(again.vertices), np.asarray(mesh.vertices))
    assert np.array_equal(np.asarray(again.triangles), np.asarray(mesh.triangles))


def test_geometry_beyond_the_walls_is_found(scan):
    from vrecho.reconstruct import beyond_walls, wall_planes
    from vrecho.geometry import distance_to_polygon, point_in_polygon

    scene, vertices, views = scan
    beyond = beyond_walls(vertices, wall_planes(vertices, np.array([v.pose[:3, 3] for v in views])))
    fp = scene.room.footprint
    outside = ~point_in_polygon(vertices[:, :2], fp) & (distance_to_polygon(vertices[:, :2], fp) > 0.15)
    assert outside.sum() > 1000 and beyond[outside].mean() > 0.9  # seen through glass, or a phantom
    room = point_in_polygon(vertices[:, :2], fp) & (vertices[:, 2] > 0.05) & (vertices[:, 2] < scene.room.height_m - 0.05)
    assert room.sum() > 1000 and beyond[room].mean() < 0.01  # the room's own walls are kept


# -- The repair (Algorithm 1) on a small room: one window, one mirror, one opening ---------------

@pytest.fixture(scope="module")
def small():
    from vrecho.reconstruct import reconstruct
    from vrecho.sim.scans import hear_echoes, scan_scene

    scene = small_room()
    scan = scan_scene(scene, n_frames=36, camera=Camera(200, 150), voxel_m=0.04)
    result = reconstruct(scan, hear=hear_echoes(scene), decide="echocnn")
    assert scan.echoes is None and result.scan.echoes is not None  # the scan given is not changed
    return scene, scan, result


def _decision_of(scene, result, kind):
    from vrecho.sim.scoring import match_truth

    k = next(i for i, d in enumerate(scene.discontinuities) if d.kind == kind)
    found = [j for j, h in enumerate(result.holes) if match_truth(scene, h) == k]
    assert len(found) == 1, (kind, found)
    return result.holes[found[0]], result.decisions[found[0]], result.actions[found[0]]


def test_the_window_is_filled_at_the_right_depth(small):
    scene, scan, result = small
    hole, decision, action = _decision_of(scene, result, "glass")
    assert decision.state == "closed" and decision.material == "glass" and action["filled"]
    origin, _, normal = scene.room.wall_frame(0)
    true_offset = -float(hole.plane.normal @ origin)
    assert abs(decision.offset_m - true_offset) < 0.03  # the echo's plane, within 3 cm


def test_the_mirror_is_filled_and_its_phantom_room_is_gone(small):
    from vrecho.sim.scoring import phantom_area_m2

    scene, scan, result = small
    _, decision, action = _decision_of(scene, result, "mirror")
    assert decision.state == "closed" and decision.material == "mirror" and action["filled"]
    before, after = phantom_area_m2(scene, scan.mesh), phantom_area_m2(scene, result.repaired)
    assert before > 2.0 and after < 0.05 * before, (before, after)


def test_the_opening_stays_open(small):
    scene, scan, result = small
    _, decision, action = _decision_of(scene, result, "open")
    assert decision.state == "open" and not action["filled"]
    assert {s.hole for s in result.surfaces} == {k for k, d in enumerate(result.decisions) if d.state == "closed"}


def test_metrics_rank_the_repair_above_no_repair_and_per_vertex_works(small):
    from vrecho.sim.scoring import oracle
    from vrecho.reconstruct import repair
    from vrecho.sim.scoring import score

    scene, scan, result = small
    none = score(scene, scan.mesh, scan.mesh)
    ours = score(scene, scan.mesh, result.repaired)
    assert none["closed_iou"] == 0 and ours["closed_iou"] > 0.85
    assert ours["openings_filled"] == 0 and ours["chamfer_cm"] < none["chamfer_cm"]
    assert max(ours["depth_error_cm"]) < 3
    repaired, surfaces, actions = repair(scan.mesh, result.holes, oracle(scene, result.holes), scan.cameras, variant="per_vertex")
    pv = score(scene, scan.mesh, repaired)
    assert pv["closed_iou"] > 0.8 and all(a["fill"] == "per_vertex" for a in actions if a["filled"])


def test_a_scan_folder_round_trips_and_bad_ones_say_why(small, tmp_path):
    from vrecho.reconstruct import Echoes, load_scan

    scene, _, result = small
    scan = result.scan  # with what the device heard
    scan.save(tmp_path / "scan")
    back = load_scan(tmp_path / "scan")
    assert len(back.views) == len(scan.views) and len(back.mesh.triangles) == len(scan.mesh.triangles)
    assert np.allclose(back.views[3].pose, scan.views[3].pose) and np.allclose(back.views[3].depth, scan.views[3].depth)
    assert isinstance(back.echoes, Echoes) and np.array_equal(back.echoes.frame, scan.echoes.frame)
    with pytest.raises(VrechoError, match="frames.npz"):
        load_scan(tmp_path)
    np.savez(tmp_path / "frames.npz", depth=np.zeros((2, 4, 4)), gray=np.zeros((2, 4, 5)), pose=np.zeros((2, 4, 4)),
             intrinsics=np.eye(3))
    with pytest.raises(VrechoError, match="expected depth and gray"):
        load_scan(tmp_path)


def test_reconstruct_command_answers_bad_input_with_one_line(tmp_path, capsys):
    from vrecho.cli import main

    assert main(["reconstruct", str(tmp_path / "nothing.json"), "--out", str(tmp_path / "o"), "--quiet"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "neither" in err[0]
    assert not (tmp_path / "o").exists()


def test_the_repair_exports_to_usd(small, tmp_path):
    """The repaired small room as OpenUSD: the fills are their own prims (not also in the room
    mesh), the opening is kept with its labels, and OpenUSD's validators find nothing."""
    from pxr import Usd

    import usd_export
    from localization import PlacedSource

    scene, scan, result = small
    room, surfaces = usd_export.from_reconstruction(result)
    added = sum(len(s.triangles) for s in result.surfaces)
    assert added > 0 and len(room[1]) == len(result.repaired.triangles) - added
    assert sorted(s.state for s in surfaces) == ["closed", "closed", "open"]
    source = PlacedSource(np.array([2.0, 1.8, 1.2]), np.sin(np.arange(44100) / 9.0), 44100, 0.9, "hum")
    path = usd_export.write_scene(tmp_path / "small.usdc", room, surfaces, [source])
    assert usd_export.validate(path) == []
    stage = Usd.Stage.Open(str(path))
    assert len(stage.GetPrimAtPath("/World/Surfaces").GetChildren()) == 3
    assert [p.GetName() for p in stage.GetPrimAtPath("/World/Sources").GetChildren()] == ["hum"]
