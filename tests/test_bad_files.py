"""What vrecho reads from disk apart from JSON, given bad files: meshes (.ply, .obj), COLMAP's
text model, scan folders (.npz), videos and pictures. Nothing but one VrechoError may come out,
and no native crash (those cases run in a child process)."""

import subprocess
import sys
import textwrap
import zipfile

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from vrecho import colmap
from vrecho.errors import VrechoError
from vrecho.io import read_mesh

CASES = settings(max_examples=60, deadline=2000, suppress_health_check=[HealthCheck.function_scoped_fixture])


def write_ply(path, vertices, faces, *, binary=False, list_type="uchar", index_type="int"):
    """A PLY file of ``vertices`` (V, 3) and ``faces`` (lists of indices), written as given: no
    check, so that any index or number reaches the reader."""
    head = (f"ply\nformat {'binary_little_endian' if binary else 'ascii'} 1.0\nelement vertex {len(vertices)}\n"
            "property float x\nproperty float y\nproperty float z\n"
            f"element face {len(faces)}\nproperty list {list_type} {index_type} vertex_indices\nend_header\n")
    if binary:
        with np.errstate(over="ignore"):  # 1e300 as float32: inf, as it comes
            body = np.asarray(vertices, "<f4").reshape(-1, 3).tobytes()
        for f in faces:
            body += np.array([len(f)], "<u1" if list_type == "uchar" else "<i4").tobytes()
            body += np.asarray(f, "<i4" if index_type == "int" else "<u4").tobytes()
        path.write_bytes(head.encode() + body)
    else:
        path.write_text(head + "".join(" ".join(map(repr, map(float, v))) + "\n" for v in vertices)
                        + "".join(" ".join(map(str, [len(f), *f])) + "\n" for f in faces))
    return path


def write_obj(path, vertices, faces):
    path.write_text("".join(f"v {x!r} {y!r} {z!r}\n" for x, y, z in np.asarray(vertices, float).tolist())
                    + "".join("f " + " ".join(str(i + 1 if i >= 0 else i) for i in f) + "\n" for f in faces))
    return path


BOX_V = [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]]
BOX_F = [[0, 1, 2], [0, 2, 3]]


def read_in_child(path):
    """read_mesh in a fresh interpreter: its exit status (negative for a signal) and stderr."""
    code = f"from vrecho.io import read_mesh\ntry:\n read_mesh({str(path)!r})\nexcept ValueError as e:\n print(e)"
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    return p.returncode, p.stdout + p.stderr


# -- Meshes: regressions ---------------------------------------------------------------------------

@pytest.mark.parametrize("binary", [False, True])
def test_negative_face_indices_are_one_error_not_a_crash(tmp_path, binary):
    """open3d read [[0, 1, -5]] and crashed later ("double free or corruption", SIGABRT)."""
    rc, out = read_in_child(write_ply(tmp_path / "m.ply", BOX_V, [[0, 1, -5], [0, 2, 3]], binary=binary))
    assert rc == 0 and "names vertex -5" in out


def test_out_of_range_indices_and_nan_vertices_are_one_error(tmp_path):
    with pytest.raises(VrechoError, match="names vertex 9, outside 0 to 3"):
        read_mesh(write_ply(tmp_path / "oob.ply", BOX_V, [[0, 1, 9]]))
    with pytest.raises(VrechoError, match="vertex 2 is not finite"):  # hung ray casting for the figure
        read_mesh(write_ply(tmp_path / "nan.ply", [[0, 0, 0], [1, 0, 0], [np.nan, 1, 0], [0, 1, 0]], BOX_F))
    with pytest.raises(VrechoError, match="beyond"):
        read_mesh(write_obj(tmp_path / "huge.obj", np.array(BOX_V) * 1e30, BOX_F))
    with pytest.raises(VrechoError, match="holds no triangles"):
        read_mesh(write_ply(tmp_path / "none.ply", BOX_V, []))


def test_files_that_crashed_open3ds_reader_are_one_error(tmp_path):
    """open3d's PLY reader segfaulted on these (a truncated header, a face of one index)."""
    (tmp_path / "header.ply").write_bytes(b"ply\nformat ascii 1.0\ncomment")
    write_ply(tmp_path / "one.ply", BOX_V, [[0]])
    for name in ("header.ply", "one.ply"):
        rc, out = read_in_child(tmp_path / name)
        assert rc == 0 and out.startswith("mesh:"), (name, rc, out)


def test_counts_beyond_the_file_or_any_room_are_refused_before_allocating(tmp_path):
    path = tmp_path / "big.ply"
    path.write_bytes(b"ply\nformat binary_little_endian 1.0\nelement vertex 99999999999\nproperty float x\n"
                     b"property float y\nproperty float z\nend_header\n" + bytes(12))
    with pytest.raises(VrechoError, match="more than 10000000"):
        read_mesh(path)
    write_ply(path, BOX_V, BOX_F, binary=True)
    path.write_bytes(path.read_bytes()[:-10])
    with pytest.raises(VrechoError, match="truncated"):
        read_mesh(path)


def test_good_meshes_read_as_open3d_writes_them(tmp_path):
    import open3d as o3d

    m = o3d.geometry.TriangleMesh.create_box(2, 3, 1).subdivide_midpoint(1)
    m.vertex_colors = o3d.utility.Vector3dVector(np.random.default_rng(0).random((len(m.vertices), 3)))
    for name, kw in (("a.ply", {"write_ascii": True}), ("b.ply", {}), ("c.obj", {})):
        o3d.io.write_triangle_mesh(str(tmp_path / name), m, **kw)
        back = read_mesh(tmp_path / name)
        corners = np.sort(np.asarray(back.vertices)[np.asarray(back.triangles)].reshape(-1, 9), axis=0)
        assert np.allclose(corners, np.sort(np.asarray(m.vertices)[np.asarray(m.triangles)].reshape(-1, 9), axis=0))
        assert back.has_vertex_colors()
    quads = write_obj(tmp_path / "q.obj", BOX_V, [[0, 1, 2, 3], [-4, -3, -1]])  # a quad, relative indices
    assert np.asarray(read_mesh(quads).triangles).tolist() == [[0, 1, 2], [0, 2, 3], [0, 1, 3]]


# -- Meshes: properties ----------------------------------------------------------------------------

coordinate = st.one_of(st.floats(-10, 10), st.sampled_from([np.nan, np.inf, -np.inf, 1e300, -1e38]))
index = st.one_of(st.integers(-3, 8), st.sampled_from([-2**31, 2**31 - 1, 10**6]))


@CASES
@given(vertices=st.lists(st.tuples(coordinate, coordinate, coordinate), max_size=8),
       faces=st.lists(st.lists(index, min_size=0, max_size=5), max_size=6),
       form=st.sampled_from(["ascii", "binary", "obj"]))
def test_any_mesh_is_read_whole_or_refused_with_one_error(tmp_path, vertices, faces, form):
    path = tmp_path / ("m.obj" if form == "obj" else "m.ply")
    if form == "obj":
        write_obj(path, np.reshape(np.array(vertices, float), (-1, 3)), [[i for i in f if i != -1] for f in faces])
    else:
        write_ply(path, np.reshape(np.array(vertices, float), (-1, 3)), faces, binary=form == "binary")
    try:
        mesh = read_mesh(path)
    except VrechoError as e:
        assert str(e).startswith("mesh: ") and "\n" not in str(e)
        return
    v, t = np.asarray(mesh.vertices), np.asarray(mesh.triangles)
    assert len(t) and np.all(np.isfinite(v)) and t.min() >= 0 and t.max() < len(v)


@CASES
@given(cut=st.floats(0, 1), flips=st.lists(st.tuples(st.floats(0, 1), st.integers(0, 255)), max_size=6),
       form=st.sampled_from(["a.ply", "b.ply", "c.obj"]))
def test_damaged_mesh_files_are_one_error(tmp_path, cut, flips, form):
    """Truncated and byte-flipped copies of a good file (the damage that crashed open3d)."""
    path = tmp_path / form
    if form == "c.obj":
        write_obj(path, BOX_V, BOX_F)
    else:
        write_ply(path, BOX_V, BOX_F, binary=form == "b.ply")
    data = bytearray(path.read_bytes())
    for at, byte in flips:
        data[int(at * (len(data) - 1))] = byte
    path.write_bytes(bytes(data[:max(1, int(cut * len(data)))]))
    try:
        mesh = read_mesh(path)
    except VrechoError:
        return
    assert np.all(np.isfinite(np.asarray(mesh.vertices))) and np.asarray(mesh.triangles).max() < len(mesh.vertices)


# -- COLMAP's text model ---------------------------------------------------------------------------

GOOD_CAMERAS = "# Camera list\n1 PINHOLE 640 480 500 500 320 240\n"
GOOD_IMAGES = ("# Image list\n1 1 0 0 0 0 0 0 1 000001.png\n\n"
               "2 0.9950042 0 0.0998334 0 0.1 0 0 1 000002.png\n1.5 2.5 -1 3.5 4.5 7\n")


def model(folder, cameras=GOOD_CAMERAS, images=GOOD_IMAGES):
    folder.mkdir(exist_ok=True)
    for name, text in (("cameras.txt", cameras), ("images.txt", images)):
        (folder / name).write_bytes(text if isinstance(text, bytes) else text.encode())
    return folder


@pytest.mark.parametrize("cameras, images, message", [
    (GOOD_CAMERAS, b"\x89PNG\r\n\x1a\n\x00\x00\xff\xfe binary", "images.txt: line 1 is not text"),
    (b"1 PINHOLE 640 480 500 500 320 240\n\xff\xd8", GOOD_IMAGES, "cameras.txt: line 2 is not text"),
    ("1 PINHOLE 640 480 nan 500 320 240\n", GOOD_IMAGES, "line 1, PARAMS: expected finite numbers"),
    ("1 PINHOLE 0 480 500 500 320 240\n", GOOD_IMAGES, "0 x 480 pixels"),  # was ZeroDivisionError
    ("1 PINHOLE 640 480 -5 500 320 240\n", GOOD_IMAGES, "focal length must be positive"),
    ("1 PINHOLE 640 480 500 500 320 240\n1 PINHOLE 64 48 50 50 32 24\n", GOOD_IMAGES, "camera 1 again"),
    ("1 PINHOLE\n", GOOD_IMAGES, "line 1: cannot read"),
    ("1 PINHOLE 640 480 500 500 320 240 1\n", GOOD_IMAGES, "5 parameters, expected 4"),
    ("1 FOV 640 480 500 500 320 240 1\n", GOOD_IMAGES, "camera 1 is FOV"),
    (GOOD_CAMERAS, "1 1 0 0 0 0 0 0 1 a1.png\n\n1 1 0 0 0 0 0 0 1 a2.png\n", "line 3: image 1 .* again"),
    (GOOD_CAMERAS, "1 1 0 0 0 0 0 0 1 a1.png\n\n2 1 0 0 0 0 0 0 1 a1.png\n", "again"),
    (GOOD_CAMERAS, "1 1 0 0 inf 0 0 0 1 a1.png\n", "line 1, QW QX QY QZ: expected finite"),
    (GOOD_CAMERAS, "1 1e300 1e300 0 0 0 0 0 1 a1.png\n", None),  # a huge quaternion is still a rotation
    (GOOD_CAMERAS, "1 1 0 0 0 0 0 1e9 1 a1.png\n", "no valid pose"),
    (GOOD_CAMERAS, "x 1 0 0 0 0 0 0 1 a1.png\n", "IMAGE_ID: expected a whole number"),
    (GOOD_CAMERAS, "1 1 0 0 0 0 0 0 1 a1.png\nthis line is junk\n", "line 2: cannot read"),
    (GOOD_CAMERAS, "1 1 0 0 0 0 0 0 1 a\x01.png\n", "control characters"),
    (GOOD_CAMERAS, "\x00" * 64, "line 1: cannot read"),
    # an image line that lost a field looks like a points line: refused where no header precedes it
    (GOOD_CAMERAS, "1 1 0 0 0 0 0 0 1 a1.png\n\n2 1 0 0 0 0 0 0 a2.png\n\n", "line 3: cannot read"),
])
def test_bad_colmap_models_name_the_file_and_line(tmp_path, cameras, images, message):
    folder = model(tmp_path / "m", cameras, images)
    if message is None:
        r = colmap.read_model(folder)[1][0].pose[:3, :3]
        assert np.allclose(r.T @ r, np.eye(3)) and np.isclose(np.linalg.det(r), 1)
        return
    with pytest.raises(VrechoError, match=message):
        colmap.read_model(folder)


def test_poses_with_bad_rates_and_frame_numbers_are_one_error(tmp_path):
    from vrecho.capture import read_poses

    folder = model(tmp_path / "m")
    for fps in (float("inf"), "2", 0, -1, True):
        with pytest.raises(VrechoError, match="image-fps"):
            read_poses(folder, fps, 10.0)
    with pytest.raises(VrechoError, match="no frame number"):  # int() of 5000 digits raised ValueError
        colmap.image_times(["9" * 5000 + ".png"], 2.0)
    model(folder, cameras="1 PINHOLE 64000 48 500 500 320 24\n")
    with pytest.raises(VrechoError, match="10 times as"):  # was 0-pixel-high views
        read_poses(folder, 2.0, 10.0)


@CASES
@given(data=st.binary(max_size=300), which=st.sampled_from(["cameras.txt", "images.txt"]))
def test_random_bytes_as_a_colmap_file_are_one_error(tmp_path, data, which):
    folder = model(tmp_path / "m")
    (folder / which).write_bytes(data)
    try:
        colmap.read_model(folder)
    except VrechoError as e:
        assert str(e).startswith("poses") and "\n" not in str(e)


token = st.one_of(st.sampled_from(["nan", "inf", "-1", "0", "1e400", "99999999999", "1.5", "PINHOLE", "OPENCV",
                                   "", "x", "１", "#", "\t", "1_0"]), st.text(max_size=6))


@CASES
@given(which=st.sampled_from(["cameras.txt", "images.txt"]), cut=st.floats(0, 1),
       edits=st.lists(st.tuples(st.integers(0, 40), token), max_size=4))
def test_truncated_and_mutated_colmap_files_are_one_error(tmp_path, which, cut, edits):
    folder = model(tmp_path / "m")
    fields = (folder / which).read_text().split(" ")
    for at, tok in edits:
        fields[at % len(fields)] = tok
    text = " ".join(fields)
    (folder / which).write_text(text[:int(cut * len(text)) + 1])
    try:
        cameras, images = colmap.read_model(folder)
    except VrechoError:
        return
    assert all(np.all(np.isfinite(im.pose)) for im in images)
    assert all(c.width >= 1 and c.height >= 1 and np.all(np.isfinite(c.intrinsics)) for c in cameras.values())


# -- Scan folders ----------------------------------------------------------------------------------

def scan_folder(folder, n=3, h=12, w=16, **override):
    from vrecho.camera import Camera, camera_pose

    folder.mkdir(exist_ok=True)
    frames = {"depth": np.full((n, h, w), 1.5, np.float32), "gray": np.full((n, h, w), 128, np.uint8),
              "pose": np.stack([camera_pose([1.0, 1.0, 1.2], [np.cos(k), np.sin(k), 0]) for k in range(n)]),
              "intrinsics": Camera(w, h).intrinsics}
    echoes = {"frame": np.arange(n), "audio": np.zeros((n, 441), np.float32), "fs": 44100, "emitted": np.ones(44)}
    for name, arrays in (("frames.npz", frames), ("echoes.npz", echoes)):
        arrays = {k: v for k, v in (arrays | override.get(name, {})).items() if v is not None}
        np.savez(folder / name, **arrays)
    return folder


@pytest.mark.parametrize("name, arrays, message", [
    ("frames.npz", {"depth": np.array([None] * 6, object).reshape(1, 2, 3)}, "a pickle"),
    ("frames.npz", {"pose": None}, r"lacks \['pose'\]"),
    ("frames.npz", {"gray": np.full((3, 12, 16), "a")}, "gray holds <U1 values"),
    ("frames.npz", {"depth": np.full((3, 12, 16), np.nan)}, "depth must be finite"),
    ("frames.npz", {"gray": np.full((3, 12, 16), 7.0)}, "gray must be uint8, or floats in 0 to 1"),
    ("frames.npz", {"intrinsics": np.zeros((3, 3))}, "pinhole matrix"),
    ("frames.npz", {"pose": np.zeros((3, 4, 4))}, "pose 0 is not a camera-to-world rigid motion"),
    ("frames.npz", {"depth": np.zeros((3, 0, 16), np.float32), "gray": np.zeros((3, 0, 16))}, "expected depth"),
    ("echoes.npz", {"frame": np.array([0.5, 1, 2])}, "expected frame"),
    ("echoes.npz", {"fs": np.array([44100, 1])}, "expected frame"),
    ("echoes.npz", {"fs": 0}, "fs .Hz.: must be from 1 to"),
    ("echoes.npz", {"audio": np.full((3, 441), np.inf)}, "must be finite"),
    ("echoes.npz", {"frame": np.array([0, 1, 7])}, "outside 0..2"),
    ("echoes.npz", {"emitted": np.array([[1.0]])}, "expected frame"),
])
def test_bad_scan_folders_are_one_error(tmp_path, name, arrays, message):
    from vrecho.reconstruct import load_scan

    with pytest.raises(VrechoError, match=message):
        load_scan(scan_folder(tmp_path / "s", **{name: arrays}))


def test_damaged_npz_files_are_one_error_and_pickles_are_never_loaded(tmp_path):
    import pickle

    from vrecho.io import read_arrays

    folder = scan_folder(tmp_path / "s")
    good = (folder / "frames.npz").read_bytes()
    for data in (good[:len(good) // 2], good[:30], b"", pickle.dumps({"depth": 1}), b"\x93NUMPY" + bytes(100)):
        (folder / "frames.npz").write_bytes(data)
        with pytest.raises(VrechoError, match="frames.npz"):
            read_arrays(folder / "frames.npz", ("depth",))
    with zipfile.ZipFile(folder / "frames.npz", "w") as z:  # a header saying 8 TB
        z.writestr("depth.npy", b"\x93NUMPY\x01\x00v\x00{'descr': '<f8', 'fortran_order': False, 'shape': "
                   b"(1000000000000,), }" + b" " * 50 + b"\n")
    with pytest.raises(VrechoError, match="over 4 GiB"):
        read_arrays(folder / "frames.npz", ("depth",))


@CASES
@given(cut=st.floats(0, 1), flips=st.lists(st.tuples(st.floats(0, 1), st.integers(0, 255)), max_size=4),
       which=st.sampled_from(["frames.npz", "echoes.npz"]))
def test_damaged_scan_folders_are_one_error(tmp_path, cut, flips, which):
    from vrecho.reconstruct import load_scan

    folder = scan_folder(tmp_path / "s")  # made afresh for each example
    write_ply(folder / "mesh.ply", BOX_V, BOX_F)
    data = bytearray((folder / which).read_bytes())
    for at, byte in flips:
        data[int(at * (len(data) - 1))] = byte
    (folder / which).write_bytes(bytes(data[:int(cut * len(data))]))
    try:
        scan = load_scan(folder)
    except VrechoError:
        return
    assert all(np.all(np.isfinite(v.depth)) and np.all(np.isfinite(v.pose)) for v in scan.views)


def test_a_scan_folders_bad_mesh_is_exit_2_with_one_line(tmp_path, capsys):
    """`vrecho reconstruct FOLDER` aborted in open3d on negative indices (run in a child)."""
    folder = scan_folder(tmp_path / "s")
    write_ply(folder / "mesh.ply", BOX_V, [[0, 1, -5], [0, 2, 3]])
    code = textwrap.dedent(f"""
        import sys
        from vrecho.cli import main
        sys.exit(main(["reconstruct", {str(folder)!r}, "--out", {str(tmp_path / 'o')!r}, "--quiet"]))""")
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert p.returncode == 2, p.stderr[-500:]
    lines = p.stderr.strip().splitlines()
    assert len(lines) == 1 and "mesh.ply: triangle 0 names vertex -5" in lines[0]


# -- Media -----------------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def video(tmp_path_factory):
    from vrecho.capture.media import write_video

    path = tmp_path_factory.mktemp("video") / "v.mkv"
    write_video(path, (np.random.default_rng(0).random((12, 48, 64)) * 255).astype(np.uint8), 3,
                np.zeros(4 * 44100, np.float32), 44100)
    return path


def test_a_truncated_video_is_one_error(video, tmp_path):
    from vrecho.capture.media import read_video, video_images

    data = video.read_bytes()
    half = tmp_path / "half.mkv"
    half.write_bytes(data[:len(data) // 2])
    with pytest.raises(VrechoError, match="truncated or damaged"):  # was read as a shorter recording
        read_video(half)
    head = tmp_path / "head.mkv"
    head.write_bytes(data[:len(data) // 20])
    with pytest.raises(VrechoError, match="none of its pictures decodes"):  # was AttributeError
        video_images(head, [0.5, 1.0])
    audio, fs, times = read_video(video)
    assert audio.size == 4 * fs and len(times) == 12


@settings(max_examples=25, deadline=5000)
@given(flips=st.lists(st.tuples(st.floats(0, 1), st.binary(min_size=1, max_size=8)), min_size=1, max_size=20),
       cut=st.floats(0.05, 1))
def test_damaged_videos_are_one_error(video, tmp_path_factory, flips, cut):
    from vrecho.capture.media import read_video, video_images

    data = bytearray(video.read_bytes())
    for at, chunk in flips:
        i = int(at * (len(data) - 8))
        data[i:i + len(chunk)] = chunk
    path = tmp_path_factory.mktemp("bad") / "bad.mkv"
    path.write_bytes(bytes(data[:int(cut * len(data))]))
    for read in (lambda: read_video(path), lambda: video_images(path, [0.2, 2.0, 3.9], width=32)):
        try:
            read()
        except VrechoError:
            pass


def test_pictures_that_are_not_pictures_are_one_error_before_any_work(tmp_path):
    import soundfile as sf
    from PIL import Image

    from vrecho.capture import open_capture

    sound = tmp_path / "a.wav"
    sf.write(sound, np.zeros(44100, np.float32), 44100)
    images = tmp_path / "images"
    images.mkdir()
    Image.fromarray(np.zeros((48, 64), np.uint8)).save(images / "000001.png")
    (images / "000002.png").write_bytes(b"not a picture")
    with pytest.raises(VrechoError, match="000002.png: cannot read it as a picture"):
        open_capture(audio=sound, images=images, image_fps=2.0)
    Image.fromarray(np.zeros((40, 64), np.uint8)).save(images / "000002.png")
    with pytest.raises(VrechoError, match="000002.png is 64 x 40 pixels"):
        open_capture(audio=sound, images=images, image_fps=2.0)
    good = (images / "000001.png").read_bytes()
    (images / "000002.png").write_bytes(good[:len(good) // 2])  # a header, then nothing
    from vrecho.capture.media import load_pictures
    with pytest.raises(VrechoError, match="000002.png: cannot decode it"):
        load_pictures(sorted(images.iterdir()), 32)
    with pytest.raises(VrechoError, match="image-fps"):
        open_capture(audio=sound, images=images, image_fps=float("inf"))
    with pytest.raises(VrechoError, match="emitter-distance"):
        open_capture(audio=sound, emitter_distance_m="7 cm")
