import json

import numpy as np
import pytest

from vrecho.errors import VrechoError
from vrecho.device import MIC_ABOVE_EMITTER_M
from vrecho.scene import DEPTH_RANGE_M, MAX_INCIDENCE_DEG, builtin_scene, load_scene
from vrecho.sim.scenes import face, random_scene, walkthrough_path


def test_json_round_trip_is_exact(tmp_path):
    scene = random_scene(np.random.default_rng(3), "r", n_poses=5, n_sources=2)
    path = scene.save(tmp_path / "s.json")
    assert load_scene(path).to_json() == scene.to_json()


@pytest.mark.parametrize("seed", range(12))
def test_random_scenes_follow_the_protocol(seed):
    scene = random_scene(np.random.default_rng(seed), n_poses=8)
    lo, hi = scene.room.footprint.min(axis=0), scene.room.footprint.max(axis=0)
    assert np.all(hi - lo >= 2.5 - 1e-9) and np.all(hi - lo <= 6.0 + 1e-9)
    assert 2.4 <= scene.room.height_m <= 3.0
    for d in scene.discontinuities:
        assert 0.4 - 1e-6 <= d.width_m <= 2.5 + 1e-6 and 0.4 - 1e-6 <= d.height_m <= 2.5 + 1e-6
        assert d.is_open == (min(d.absorption) == 1.0)
    for pose in scene.poses:
        assert DEPTH_RANGE_M[0] - 1e-9 <= scene.depth_m(pose) <= DEPTH_RANGE_M[1] + 1e-9
        assert scene.incidence_deg(pose) <= MAX_INCIDENCE_DEG + 1e-6
        # the specular echo comes off the discontinuity: the emitter's foot lies on it
        d = scene.discontinuities[pose.target]
        origin, u, normal = scene.room.wall_frame(d.wall)
        foot = pose.emitter + scene.depth_m(pose) * normal
        u0, u1, z0, z1 = d.bounds()
        assert u0 <= np.dot(foot - origin, u) <= u1 and z0 <= foot[2] <= z1


def test_the_walkthrough_listens_to_each_discontinuity_clear_of_other_echoes():
    clear = []
    for seed in range(8):
        scene = random_scene(np.random.default_rng([3000, seed]), n_discontinuities=(2, 3))
        path, room = walkthrough_path(scene), scene.room
        for d in scene.discontinuities:
            origin, u, normal = room.wall_frame(d.wall)
            u0, u1, z0, z1 = d.bounds()
            if u0 < 0.4 or u1 > room.wall_lengths[d.wall] - 0.4 or z1 - z0 < 0.3 or z0 > 1.6:
                continue  # in a corner (no room to stand in front) or out of reach
            stands = []
            for pos in path.positions:
                e = pos - [0, 0, MIC_ABOVE_EMITTER_M]
                dist = float(np.dot(origin - e, normal))
                foot = e + dist * normal  # where the loudspeaker's echo comes from
                if 0.5 < dist < 2.3 and u0 + 0.1 <= np.dot(foot - origin, u) <= u1 - 0.1 and z0 + 0.1 <= foot[2] <= z1 - 0.1:
                    walls = [room.wall_frame(v) for v in range(len(room.wall_lengths)) if v != d.wall]
                    others = [e[2], room.height_m - e[2]] + [abs(float(np.dot(e - o, n))) for o, _, n in walls]
                    stands.append(min(abs(np.array(others) - dist)))
            assert stands, (seed, d, path.positions)
            clear.append(max(stands) >= 0.35)
    assert np.mean(clear) >= 0.6, clear  # mostly, the floor's, the ceiling's and the walls' echoes come apart


def test_patches_tile_each_wall():
    scene = builtin_scene()
    patches = scene.patches()
    for w, length in enumerate(scene.room.wall_lengths):
        area = sum(np.linalg.norm(np.cross(p.corners[1] - p.corners[0], p.corners[3] - p.corners[0]))
                   for p in patches if p.surface == w)
        assert np.isclose(area, length * scene.room.height_m)
    centre = np.r_[scene.room.footprint.mean(axis=0), 1.0]
    for p in patches:  # every normal points out of the room
        assert np.dot(p.normal, p.corners.mean(axis=0) - centre) > 0


def test_builtin_scene_has_the_demo_surfaces():
    scene = builtin_scene()
    kinds = [d.kind for d in scene.discontinuities]
    assert kinds.count("glass") == 2 and "open" in kinds and "mirror" in kinds
    assert 2 <= len(scene.sources) <= 3 and scene.camera_path is not None


def _bad(tmp_path, mutate):
    d = json.loads(builtin_scene().to_json())
    mutate(d)
    path = tmp_path / "bad.json"
    path.write_text(json.dumps(d))
    return path


@pytest.mark.parametrize("mutate, message", [
    (lambda d: d["room"].update(height_m=-2.7), "room.height_m"),
    (lambda d: d["room"].update(footprint=d["room"]["footprint"][::-1]), "counter-clockwise"),
    (lambda d: d["discontinuities"][0].update(kind="door"), r"discontinuities\[0\].kind"),
    (lambda d: d["discontinuities"][1].update(absorption=[0.5] * 7), r"discontinuities\[1\].absorption"),
    (lambda d: d["discontinuities"][0].update(width_m=9.0), r"discontinuities\[0\]: spans"),
    (lambda d: d["poses"][0].update(emitter=[1.0, -0.5, 1.0]), r"poses\[0\].emitter.*outside the room"),
    (lambda d: d["poses"][0].update(emitter=[3.0, 2.0, 2.66]), r"poses\[0\]: microphone 0 .* outside the room"),
    (lambda d: d["poses"][0].update(forward=[0, 0, 0]), r"poses\[0\].forward"),
    (lambda d: d["sources"][0].update(sound="trumpet"), r"sources\[0\].sound"),
    (lambda d: d["room"]["walls"][0].update(absorption=[0.1] * 3), r"room.walls\[0\].absorption"),
    (lambda d: d["room"].pop("floor"), "room.floor: missing"),
])
def test_invalid_scene_file_names_the_field(tmp_path, mutate, message):
    with pytest.raises(VrechoError, match=message):
        load_scene(_bad(tmp_path, mutate))


def test_not_json(tmp_path):
    path = tmp_path / "x.json"
    path.write_text("{room: ")
    with pytest.raises(VrechoError, match="not valid JSON"):
        load_scene(path)


def test_negative_depth():
    with pytest.raises(VrechoError, match="positive depth"):
        face(builtin_scene(), 0, -0.5)


def test_depth_beyond_the_room():
    with pytest.raises(VrechoError, match="outside the room"):
        face(builtin_scene(), 0, 8.0)


def test_furniture_round_trips_and_stays_in_the_room(tmp_path):
    from vrecho.furniture import Furniture

    scene = builtin_scene()
    scene.furniture = [Furniture("table", (2.0, 2.5), (1.2, 0.8, 0.04), z0=0.72, yaw_deg=20.0),
                       Furniture("shelf", (1.0, 1.0), (0.9, 0.35, 1.9))]
    scene.validate()
    back = load_scene(scene.save(tmp_path / "s.json"))
    assert back.furniture == scene.furniture
    faces = [p for p in back.patches() if p.kind == "furniture"]
    assert len(faces) == 6 + 5  # the shelf stands on the floor: no underside
    for f, piece in ((faces[:6], back.furniture[0]), (faces[6:], back.furniture[1])):
        inside = np.r_[piece.center, piece.z0 + piece.size[2] / 2]
        for p in f:  # every face's normal points into its box, out of the room's air
            assert np.dot(p.normal, inside - p.corners.mean(axis=0)) > 0
    d = scene.to_dict()
    d["furniture"][1]["center"] = [-1.0, 1.0]
    with pytest.raises(VrechoError, match=r"furniture\[1\] \(shelf\): not wholly inside the room"):
        type(scene).from_dict(d)
    d["furniture"][1]["size"] = [0.9, 0.0, 1.9]
    with pytest.raises(VrechoError, match=r"furniture\[1\].*size"):
        type(scene).from_dict(d)
