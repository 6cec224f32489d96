import numpy as np
import pytest

from vrecho.errors import VrechoError
from vrecho.camera import Camera, camera_pose
from vrecho.sim.render import World, crop, render_view
from vrecho.scene import builtin_scene
from vrecho.sim.scenes import face

CAM = Camera(64, 48, 50.0)


@pytest.fixture(scope="module")
def world():
    return World(builtin_scene())


def _centre_depth(world, index, depth):
    pose = face(world.scene, index, depth)
    view = render_view(world, camera_pose(pose.camera, pose.forward), camera=CAM)
    return view, view.depth[20:28, 28:36]


def test_mirror_shows_a_phantom_room_to_the_depth_sensor(world):
    # wall mirror (discontinuity 3) 1 m away: the sensor sees the room behind it, 1 m + the room's
    # width (6 m) away, as if through the wall; where the reflected ray meets the glass door
    # opposite (which this sensor cannot see), nothing
    view, centre = _centre_depth(world, 3, 1.0)
    assert np.all((centre > 6.0) | (centre == 0)) and (centre > 6.0).mean() > 0.3
    assert view.gray.min() >= 0 and view.gray.max() <= 1


def test_glass_that_the_sensor_sees_through_or_not(world):
    see_through = world.scene.discontinuities[0].depth_sensor_sees_through
    blind = world.scene.discontinuities[2].depth_sensor_sees_through
    assert see_through and not blind
    _, window = _centre_depth(world, 0, 1.0)
    assert np.all((window == 0) | (window > 1.05))  # beyond the pane, or out of range
    _, door = _centre_depth(world, 2, 1.0)
    assert np.all(door == 0)


def test_wall_depth_is_the_z_depth(world):
    scene = world.scene
    pose = face(scene, 0, 1.0, offset_u_m=1.6)  # beside the window: plain wall ahead
    view = render_view(world, camera_pose(pose.camera, pose.forward), camera=CAM)
    assert np.allclose(view.depth[22:26, 30:34], 1.0, atol=0.01)


def test_crop_looks_through_openings_and_into_mirrors(world):
    scene = world.scene
    crops = {i: crop(world, face(scene, i, 1.0)) for i in range(4)}
    for c in crops.values():
        assert c.shape == (64, 25) and c.dtype == np.uint8 and c.std() > 3
    # glass shows what lies beyond, dimmed: darker than the opening's view on average
    assert not np.array_equal(crops[0], crops[1])


def test_crop_needs_a_discontinuity(world):
    pose = face(world.scene, 0, 1.0)
    pose.target = None
    with pytest.raises(VrechoError, match="no discontinuity"):
        crop(world, pose)


def test_a_crop_from_a_camera_frame_matches_the_ray_traced_crop():
    from vrecho.camera import crop_view

    scene = builtin_scene()
    world = World(scene)
    pose = next(p for p in scene.poses if scene.depth_m(p) > 2.5)  # far enough for the frame to hold the region
    view = render_view(world, camera_pose(pose.camera, pose.forward), camera=Camera())
    image, inside = crop_view(view, scene.discontinuity_corners(pose.target))
    assert inside == 1.0
    assert np.abs(image.astype(int) - crop(world, pose)).mean() < 3  # of 255
