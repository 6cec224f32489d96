"""Real captures (issue 9): pulses found in a phone's recording of the pulse train."""

import numpy as np
import pytest

from vrecho.errors import VrechoError


@pytest.fixture(scope="module")
def ir():
    from vrecho.sim.acoustics import device_impulse_response
    from vrecho.scene import builtin_scene

    scene = builtin_scene()
    return device_impulse_response(scene, scene.poses[0])[0]


@pytest.mark.parametrize("snr_db, clip", [(20, None), (10, 0.3)])
def test_onsets_are_found_to_a_sample_through_noise_clipping_drift_and_a_missing_pulse(ir, snr_db, clip):
    from vrecho.capture import find_onsets
    from vrecho.sim.captures import simulate_recording

    rng = np.random.default_rng(4)
    x, truth = simulate_recording(ir, 12, rng, snr_db=snr_db, drift=0.004, clip=clip, dropped=(6,))
    onsets = find_onsets(x, 44100)
    played = truth[~np.isnan(truth)]
    assert len(onsets.samples) == len(played)
    assert np.max(np.abs(onsets.samples - played)) <= 1.0
    assert len(onsets.missing) == 1 and abs(onsets.missing[0] - (truth[5] + truth[7]) / 2) < 0.01 * 44100
    assert abs(onsets.period_s - 1.004) < 1e-4


def test_no_pulses_is_one_clear_error():
    from vrecho.capture import find_onsets

    noise = np.random.default_rng(0).standard_normal(5 * 44100).astype(np.float32) * 0.01
    with pytest.raises(VrechoError, match="no pulse train"):
        find_onsets(noise, 44100)
    with pytest.raises(VrechoError, match="NaN"):
        find_onsets(np.full(44100, np.nan), 44100)


def test_frames_start_at_the_emission_like_the_simulators(ir):
    from vrecho.capture import cut_frames, find_onsets
    from vrecho.sim.captures import simulate_recording
    from vrecho.signals import probe

    rng = np.random.default_rng(5)
    x, truth = simulate_recording(ir, 5, rng, snr_db=60)
    frames = cut_frames(x, find_onsets(x, 44100))
    # the steady state of the train, from the emission: what the simulator's frames hold
    n = len(ir)
    expected = np.fft.irfft(np.fft.rfft(ir, n) * np.fft.rfft(probe(), n), n)
    assert frames.shape[1] == n and len(frames) >= 3
    for f in frames[1:]:  # the first has no earlier pulse's tail
        scale = np.dot(f, expected) / np.dot(expected, expected)  # the microphone's sensitivity
        # a twentieth of a sample off shifts 18 kHz by a third of a radian: a few per cent
        assert np.max(np.abs(f / scale - expected)) < 0.08 * np.max(np.abs(expected))
        assert np.corrcoef(f, expected)[0, 1] > 0.999


def test_a_paused_player_and_a_clap_lose_no_pulse(ir):
    """The player paused (or looping its file with a gap at the seam) restarts the train off the
    beat: nothing is missing there; a clap louder than the pulses is not one."""
    from vrecho.sim.acoustics import MIC_SENSITIVITY
    from vrecho.capture import find_onsets
    from vrecho.sim.captures import simulate_recording
    from vrecho.signals import emitted_sound

    rng = np.random.default_rng(11)
    x, truth = simulate_recording(ir, 12, rng, snr_db=20, pauses={4: 0.43, 8: 2.6}, dropped=(10,))
    clap = emitted_sound("clap", 44100, rng)
    at = int(truth[2] + 0.45 * 44100)
    x[at:at + clap.size] += 2 * MIC_SENSITIVITY * np.abs(ir).max() * clap / np.abs(clap).max()
    onsets = find_onsets(x, 44100)
    played = truth[~np.isnan(truth)]
    assert len(onsets.samples) == len(played) and np.max(np.abs(onsets.samples - played)) < 1
    assert len(onsets.missing) == 1 and abs(onsets.missing[0] - (truth[9] + truth[11]) / 2) < 0.005 * 44100


def test_the_shipped_pulse_train_is_the_probe_once_a_second_and_loops():
    import soundfile as sf

    from vrecho.capture import PULSE_TRAIN_WAV, find_onsets
    from vrecho.signals import probe, pulse_train

    x, fs = sf.read(PULSE_TRAIN_WAV, dtype="float32")
    assert fs == 44100 and x.ndim == 1 and len(x) == 30 * 44100
    assert np.max(np.abs(x - pulse_train(probe(), 30))) <= 1 / 32767  # 16-bit of the very probe
    seam = np.zeros(int(0.137 * fs), np.float32)  # a player looping the file with a gap
    looped = np.concatenate([seam, x, seam, x, x]) + 1e-3 * np.random.default_rng(0).standard_normal(90 * fs + 2 * seam.size)
    onsets = find_onsets(looped, fs)
    assert len(onsets.samples) == 90 and len(onsets.missing) == 0


@pytest.mark.parametrize("codec, ext", [("flac", "mkv"), ("aac", "mp4")])
def test_a_video_round_trip_gives_the_simulated_frames_answers(ir, tmp_path, codec, ext):
    """The simulator's capture muxed into a real video (PyAV); `vrecho capture` reads it back and
    answers as EchoCNN does on the frames of the sound the file holds, found where the simulated
    recording's own pulses are; FLAC's sound is the recording's (the same answers as its frames
    passed directly), AAC's (what phones write) the surface's echo in most frames."""
    import csv

    from vrecho.capture import cut_frames, find_onsets, read_video, write_video
    from vrecho.sim.captures import simulate_recording
    from vrecho.classifier import load_classifier
    from vrecho.cli import main
    from vrecho.camera import Camera, camera_pose
    from vrecho.sim.render import render_view
    from vrecho.scene import builtin_scene
    from vrecho.signals import probe

    scene = builtin_scene()
    pose = scene.poses[0]
    x, truth = simulate_recording(ir, 5, np.random.default_rng(6), snr_db=30)
    x = 0.5 * x / np.abs(x).max()
    view = render_view(scene, camera_pose(pose.camera, pose.forward), camera=Camera(160, 120))
    gray = np.repeat((255 * view.gray).astype(np.uint8)[None], int(len(x) / 44100 * 10), axis=0)
    video = tmp_path / f"capture.{ext}"
    write_video(video, gray, 10, x, 44100, audio_codec=codec)
    assert main(["capture", str(video), "--out", str(tmp_path / "out")]) == 0
    rows = list(csv.DictReader(open(tmp_path / "out" / "frames.csv")))
    clf = load_classifier()
    direct = find_onsets(x, 44100)
    expected = clf.predict_batch(cut_frames(x, direct), 44100, images=None, emitted=probe())
    y, fs, _ = read_video(video)
    heard = clf.predict_batch(cut_frames(y, find_onsets(y, fs)), fs, images=None, emitted=probe())
    assert len(rows) == len(expected) == len(heard) >= 3  # the same frames found
    moved = []
    for r, t, p, q in zip(rows, direct.seconds, expected, heard):
        assert abs(float(r["time_s"]) - t) < 1 / 44100
        assert abs(float(r["p_open"]) - q.probabilities["open"]) < 1e-3
        assert abs(float(r["p_mirror"]) - q.probabilities["mirror"]) < 1e-3
        assert (r["open"] == "True") == q.is_open and abs(float(r["depth_m"]) - q.depth_m) < 1e-3
        if codec == "flac":  # lossless
            assert abs(q.probabilities["open"] - p.probabilities["open"]) < 1e-3 and q.is_open == p.is_open
            assert abs(q.depth_m - p.depth_m) < 1e-3
        elif not (p.is_open or q.is_open):
            moved.append(abs(q.depth_m - p.depth_m))
    # AAC moves EchoCNN's probabilities (the AAC rows in the Results), and now and then its pick
    # of the echo (the shipped EchoCNN-E: 3 frames of 20 of this room's, 2026-12-06); most
    # frames keep the surface's echo
    assert codec == "flac" or (len(moved) >= 3 and np.median(moved) < 0.03)
    images = np.load(tmp_path / "out" / "images.npz")["gray"]
    assert images.shape == (len(rows), 120, 160) and abs(images.mean() - gray.mean()) < 3


def test_bad_captures_are_one_clear_error(tmp_path):
    import av
    import soundfile as sf

    from vrecho.app.captures import capture
    from vrecho.cli import main

    mute = tmp_path / "mute.mp4"
    with av.open(str(mute), "w") as c:  # a video without a sound track
        v = c.add_stream("libx264", rate=10)
        v.width, v.height, v.pix_fmt = 32, 32, "yuv420p"
        for i in range(5):
            f = av.VideoFrame.from_ndarray(np.zeros((32, 32, 3), np.uint8), format="rgb24")
            f.pts = i
            for p in v.encode(f):
                c.mux(p)
        for p in v.encode(None):
            c.mux(p)
    not_video = tmp_path / "notes.mp4"
    not_video.write_text("not a video")
    noise = tmp_path / "noise.wav"
    sf.write(noise, np.random.default_rng(0).standard_normal(3 * 44100) * 0.01, 44100)
    for video, audio, message in ((mute, None, "no audio track"), (not_video, None, "cannot decode"),
                                  (None, noise, "no pulse train"), (None, None, "give a video"),
                                  (mute, noise, "give a video")):
        with pytest.raises(VrechoError, match=message):
            capture(tmp_path / "o", video, audio)
    assert main(["capture", str(mute), "--out", str(tmp_path / "o2")]) == 2


# -- A posed capture: COLMAP's poses and the user's mesh, repaired --------------------------------

@pytest.fixture(scope="module")
def posed(tmp_path_factory):
    """The small room's capture as a user brings it: a video (pictures and the pulses' sound,
    each pulse heard where the device then was), COLMAP's poses of its pictures, the scan's mesh."""
    from vrecho.sim.captures import simulate_capture
    from vrecho.camera import Camera

    from conftest import small_room

    scene = small_room()
    folder = tmp_path_factory.mktemp("posed")
    return scene, simulate_capture(scene, folder, n_pulses=16, fps=3, camera=Camera(200, 150), seed=3)


@pytest.mark.slow
def test_a_posed_capture_repairs_the_users_mesh_and_exports(posed, tmp_path):
    import csv
    import json

    from vrecho.cli import main
    from vrecho.sim.scoring import phantom_area_m2

    from pxr import Usd

    scene, sim = posed
    out = tmp_path / "out"
    assert main(["capture", str(sim["video"]), "--poses", str(sim["poses"]), "--mesh", str(sim["mesh"]),
                 "--image-fps", "3", "--out", str(out), "--quiet"]) == 0
    rows = list(csv.DictReader(open(out / "frames.csv")))
    assert len(rows) == 16
    errors = []
    for r, t, pose in zip(rows, sim["onsets_s"], sim["pulse_poses"]):  # each pulse found, and posed where it was
        assert abs(float(r["time_s"]) - t) < 1 / 44100
        errors.append(np.linalg.norm([float(r[k]) for k in ("x_m", "y_m", "z_m")] - pose[:3, 3]))
    # interpolated between pictures a third of a second apart (a phone's tracking gives 30 a second)
    assert np.median(errors) < 0.005 and max(errors) < 0.05, errors
    report = json.loads((out / "report.json").read_text())
    heard = [h for h in report["holes"] if h["decision"]["state"] != "unknown"]
    assert sorted((h["decision"]["state"], h["decision"]["material"]) for h in heard) == \
        [("closed", "glass"), ("closed", "mirror"), ("open", None)]
    assert {int(r["hole"]) for r in rows if r["hole"]} >= {h["id"] for h in heard}
    # a frame facing a hole with its specular point in it is asked with the mesh's distance, as
    # the repair asks: its open/closed is the hole's
    state = {h["id"]: h["decision"]["state"] == "open" for h in heard}
    asked = [r for r in rows if r["hole"] and r["model"].endswith("echo at surface_m")]
    assert asked and all((r["open"] == "True") == state[int(r["hole"])] for r in asked if int(r["hole"]) in state)
    glass = next(h for h in heard if h["decision"]["material"] == "glass")
    assert abs(glass["decision"]["offset_m"] - 0.0) < 0.03  # wall 0 is the plane y = 0
    import open3d as o3d

    before = phantom_area_m2(scene, o3d.io.read_triangle_mesh(str(sim["mesh"])))
    after = phantom_area_m2(scene, o3d.io.read_triangle_mesh(str(out / "repaired.ply")))
    assert before > 1.0 and after < 0.1 * before, (before, after)
    # The same capture as separate files (--audio WAV --images DIR): the same answers
    import soundfile as sf
    from PIL import Image

    from vrecho.capture import read_video, video_images

    x, fs, times = read_video(sim["video"])
    sf.write(tmp_path / "capture.wav", x, fs, subtype="FLOAT")
    (tmp_path / "pictures").mkdir()
    for k, g in enumerate(video_images(sim["video"], (np.arange(len(times)) + 0.5) / 3)):
        Image.fromarray(g).save(tmp_path / "pictures" / f"{k + 1:06d}.png")
    assert main(["capture", "--audio", str(tmp_path / "capture.wav"), "--images", str(tmp_path / "pictures"),
                 "--poses", str(sim["poses"]), "--mesh", str(sim["mesh"]), "--image-fps", "3",
                 "--out", str(tmp_path / "files"), "--quiet"]) == 0
    again = json.loads((tmp_path / "files" / "report.json").read_text())
    # The same answers for the holes heard. Not the same list of unheard ones: the same capture run
    # twice in one process gives its small holes slightly different areas (0.136 and 0.135 m2), so
    # one near the size threshold comes and goes (the reconstruction's own run-to-run spread).
    assert sorted((h["decision"]["state"], h["decision"]["material"]) for h in again["holes"]
                  if h["decision"]["state"] != "unknown") == sorted(
        (h["decision"]["state"], h["decision"]["material"]) for h in heard)
    assert main(["export", str(out), "--out", str(tmp_path / "room.usda"), "--quiet"]) == 0
    stage = Usd.Stage.Open(str(tmp_path / "room.usda"))
    states = {p.GetName(): p.GetAttribute("vrecho:state").Get() for p in stage.Traverse()
              if p.HasAttribute("vrecho:state")}
    assert sorted(v for v in states.values() if v != "unknown") == ["closed", "closed", "open"]


@pytest.mark.slow
def test_poses_that_do_not_fit_the_capture_are_one_clear_error(posed, tmp_path):
    import shutil

    import open3d as o3d

    from vrecho.app.captures import capture

    _, sim = posed
    far = tmp_path / "far.ply"  # the mesh of somewhere else
    o3d.io.write_triangle_mesh(str(far), o3d.io.read_triangle_mesh(str(sim["mesh"])).translate([50.0, 0, 0]))
    upside = tmp_path / "upside"  # a model neither levelled nor z up
    shutil.copytree(sim["poses"], upside)
    lines = (upside / "images.txt").read_text().splitlines()
    for k, line in enumerate(lines):
        t = line.split()
        if len(t) == 10 and not line.startswith("#"):
            q = np.array(t[1:5], float)  # the world turned upside down about x: q' = q * (0, 1, 0, 0)
            w, x, y, z = q
            t[1:5] = map(str, [-x, w, z, -y])
            lines[k] = " ".join(t)
    (upside / "images.txt").write_text("\n".join(lines) + "\n")
    cases = [(dict(poses=sim["poses"], mesh=sim["mesh"], image_fps=0.5), "do not match the recording"),
             (dict(poses=sim["poses"], mesh=far, image_fps=3), "meets the mesh"),
             (dict(poses=upside, mesh=sim["mesh"], image_fps=3), "up axes"),
             (dict(poses=sim["poses"], image_fps=3), "go together"),
             (dict(poses=sim["poses"], mesh=sim["poses"] / "images.txt", image_fps=3), "not a .ply or .obj"),
             (dict(poses=sim["poses"], mesh=sim["mesh"]), "image-fps")]
    for kwargs, message in cases:
        with pytest.raises(VrechoError, match=message):
            capture(tmp_path / "o", sim["video"], **kwargs)


@pytest.mark.slow
def test_a_y_up_model_is_turned_z_up(posed, tmp_path):
    from vrecho import colmap
    from vrecho.capture import read_poses

    _, sim = posed
    cameras, images = colmap.read_model(sim["poses"])
    y_up = np.eye(4)
    y_up[:3, :3] = [[1, 0, 0], [0, 0, 1], [0, -1, 0]]  # ARKit's world: z up becomes y up
    colmap.write_model(tmp_path, cameras[1], [im.name for im in images], np.stack([y_up @ im.pose for im in images]))
    a, b = read_poses(sim["poses"], 3, 20.0), read_poses(tmp_path, 3, 20.0)
    assert np.allclose(a.pose, b.pose) and np.allclose(b.to_z_up @ y_up, np.eye(4))
