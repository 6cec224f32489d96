"""COLMAP's text model: read back what is written, and bad models answered with one clear error."""

import numpy as np
import pytest

from vrecho import colmap
from vrecho.errors import VrechoError
from vrecho.camera import Camera, camera_pose


def test_poses_round_trip_through_colmaps_text_format(tmp_path):
    cam = Camera(320, 240)
    poses = np.stack([camera_pose([1.0 + k, 2.0, 1.5], [np.cos(k), np.sin(k), 0.1 * k]) for k in range(4)])
    colmap.write_model(tmp_path, colmap.pinhole(cam.intrinsics, 320, 240), [f"{k + 1:06d}.png" for k in range(4)], poses)
    # COLMAP writes each image's 2-D points on the line after it: a line of triples, or empty
    lines = (tmp_path / "images.txt").read_text().splitlines()
    lines[4] = "10.5 20.5 -1 30.25 40.0 7 1.0 2.0 3 4.0 5.0 6"  # 12 numbers: four points, not a header
    (tmp_path / "images.txt").write_text("\n".join(lines) + "\n")
    cameras, images = colmap.read_model(tmp_path)
    assert [im.name for im in images] == ["000001.png", "000002.png", "000003.png", "000004.png"]
    assert np.allclose(np.stack([im.pose for im in images]), poses, atol=1e-9)
    assert np.allclose(cameras[1].intrinsics, cam.intrinsics)
    assert np.allclose(colmap.image_times([im.name for im in images], 2.0), [0, 0.5, 1.0, 1.5])


def test_what_colmap_models_vrecho_reads():
    simple = colmap.Camera("SIMPLE_RADIAL", 640, 480, np.array([500.0, 320.0, 240.0, 0.01]))
    assert np.allclose(simple.intrinsics, [[500, 0, 319.5], [0, 500, 239.5], [0, 0, 1]])
    opencv = colmap.Camera("OPENCV", 640, 480, np.array([500.0, 510.0, 321.0, 241.0, 0, 0, 0, 0]))
    assert np.allclose(opencv.intrinsics, [[500, 0, 320.5], [0, 510, 240.5], [0, 0, 1]])


@pytest.mark.parametrize("cameras, images, message", [
    (None, "1 1 0 0 0 0 0 0 1 a.png\n\n", "no cameras.txt"),
    ("1 OPENCV_FISHEYE 64 48 1 2 3 4 5 6 7 8\n", "", "OPENCV_FISHEYE"),
    ("1 PINHOLE 64 48 1 2 3\n", "", "3 parameters, expected 4"),
    ("1 PINHOLE 64 48 50 50 32 24\n", "1 1 0 0 0 0 0 0 2 a.png\n\n", "camera 2"),
    ("1 PINHOLE 64 48 50 50 32 24\n", "1 0 0 0 0 0 0 0 1 a.png\n\n", "no valid pose"),
    ("1 PINHOLE 64 48 50 50 32 24\n", "# nothing\n", "holds no image"),
])
def test_bad_models_say_what_is_wrong(tmp_path, cameras, images, message):
    if cameras is not None:
        (tmp_path / "cameras.txt").write_text(cameras)
    (tmp_path / "images.txt").write_text(images)
    with pytest.raises(VrechoError, match=message):
        colmap.read_model(tmp_path)


def test_pictures_need_a_frame_number():
    with pytest.raises(VrechoError, match="no frame number"):
        colmap.image_times(["kitchen.png"], 2.0)
