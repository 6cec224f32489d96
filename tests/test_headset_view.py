"""vrecho.headset.view: the headset camera's answer about the surface an echo found."""

import numpy as np
import pytest

from conftest import small_room
from vrecho.errors import VrechoError
from vrecho.sim.walks import HEADSET_CAMERA
from vrecho.headset.view import load_model, look, pane_crop, save
from vrecho.learn.headset_view import make_dataset, train
from vrecho.sim.render import World, render_view
from vrecho.camera import camera_pose


@pytest.fixture(scope="module")
def world():
    return World(small_room())


def _view(world, wall: int, u_m: float, distance_m: float, yaw_deg: float = 0.0):
    """The headset camera's frame ``distance_m`` in front of a wall of the small room, 1.55 m up."""
    origin, u, normal = world.scene.room.wall_frame(wall)
    emitter = origin + u_m * u + [0.0, 0.0, 1.55] - distance_m * normal
    yaw = np.radians(yaw_deg)
    forward = np.cos(yaw) * normal + np.sin(yaw) * u
    return render_view(world, camera_pose(emitter + [0.0, 0.0, 0.07], forward), camera=HEADSET_CAMERA)


@pytest.mark.parametrize("wall, u_m, distance_m, yaw, expected", [
    (0, 2.1, 1.5, 0.0, "glass"), (0, 2.1, 0.8, 10.0, "glass"), (1, 1.8, 1.2, 0.0, "mirror"),
    (1, 1.8, 2.5, -5.0, "mirror"), (3, 1.8, 1.5, 0.0, "wall"), (0, 0.7, 1.0, 0.0, "wall")])
def test_the_camera_tells_wall_glass_and_mirror(world, wall, u_m, distance_m, yaw, expected):
    view = _view(world, wall, u_m, distance_m, yaw)
    v = look(view.gray, view.depth, view.intrinsics, distance_m)
    assert v is not None and v.surface == expected and v.confidence > 0.5
    assert (v.crop is None) == (expected == "wall")
    if v.crop is not None:
        assert v.crop.shape == (64, 25) and v.crop.dtype == np.uint8


def test_the_pane_is_what_the_depth_camera_sees_past(world):
    # The glass in view from 1.5 m: straight ahead the sensor reads past the echo's plane; the
    # crop is the pane with a margin of wall around it (the wall's texture at the crop's edges).
    view = _view(world, 0, 2.1, 1.5)
    agree, crop = pane_crop(view.gray, view.depth, view.intrinsics, 1.5)
    assert agree < 0.1 and crop is not None
    assert crop[0].mean() > 20 and crop[-1].mean() > 20  # the margin: wall, in the frame (not black)


def test_frames_that_cannot_tell_and_bad_input(world):
    view = _view(world, 3, 1.8, 1.5)
    assert look(view.gray, np.zeros_like(view.depth), view.intrinsics, 1.5) is None  # the sensor returned nothing
    assert look((255 * view.gray).astype(np.uint8), view.depth, view.intrinsics, 1.5).surface == "wall"
    with pytest.raises(VrechoError, match="one size"):
        look(view.gray, view.depth[:-1], view.intrinsics, 1.5)
    with pytest.raises(VrechoError, match="intrinsics"):
        look(view.gray, view.depth, np.eye(2), 1.5)
    with pytest.raises(VrechoError, match="distance_m"):
        look(view.gray, view.depth, view.intrinsics, -1.0)
    with pytest.raises(VrechoError, match="image"):
        look(2 * view.gray, view.depth, view.intrinsics, 1.5)


def test_training_on_a_few_rooms_round_trips(tmp_path):
    data = make_dataset(4, seed=123, jobs=1, progress=False)
    assert len(data["crops"]) > 0 and data["crops"].shape[1:] == (64, 25)
    model, figures = train(data, epochs=1, progress=False)
    assert figures["epochs"] == 1 and figures["train_crops"] + figures["val_crops"] == len(data["crops"])
    save(model, tmp_path / "view.pt")
    again = load_model(tmp_path / "view.pt")
    view = _view(World(small_room()), 1, 1.8, 1.2)
    a = look(view.gray, view.depth, view.intrinsics, 1.2, model=model)
    b = look(view.gray, view.depth, view.intrinsics, 1.2, model=again)
    assert a.surface == b.surface and abs(a.confidence - b.confidence) < 1e-2  # half precision on disk
    (tmp_path / "bad.pt").write_bytes(b"not a model")
    with pytest.raises(VrechoError, match="not a headset-view model"):
        load_model(tmp_path / "bad.pt")
