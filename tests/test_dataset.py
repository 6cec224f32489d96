import json
import signal
import subprocess
import sys
import time

import numpy as np
import pytest
import zarr

from vrecho.learn.datasets import LABEL_COLUMNS, generate, open_dataset, read_labels
from vrecho.errors import VrechoError
from vrecho.signals import SOUNDS, TRAIN_SOUNDS


def test_tiny_dataset_reopens_with_zarr_alone(tiny_dataset):
    root = zarr.open_group(tiny_dataset / "frames.zarr", mode="r")
    labels = read_labels(tiny_dataset / "labels.csv")
    n = len(labels["frame"])
    assert n == 384
    assert root["audio"].shape == (n, 44100) and root["audio"].dtype == np.float16
    assert root["logmel"].shape == (n, 62, 25) and root["image"].shape == (n, 64, 25)
    audio = root["audio"][:]
    assert np.all(np.isfinite(audio)) and np.all(np.abs(audio).max(axis=1) > 0)  # every frame written (noise at least)
    assert np.array_equal(labels["frame"], np.arange(n))


def test_labels_match_the_scene_files(tiny_dataset):
    ds = open_dataset(tiny_dataset)
    lab = ds.labels
    for i in range(len(ds)):
        scene = ds.scene(lab["scene"][i])
        pose = scene.poses[lab["pose"][i]]
        if lab["kind"][i] == "echo":
            disc = scene.discontinuities[lab["surface"][i]]
            assert lab["surface"][i] == pose.target
            assert lab["is_open"][i] == int(disc.is_open)
            assert lab["material"][i] == (disc.material or "")
            assert abs(lab["depth_m"][i] - scene.depth_m(pose)) < 1e-4
        else:
            k = lab["ir"][i] - lab["scene"][i] * 4 - 3  # tiny: 3 poses, then 1 source
            rel = pose.rotation.T @ (scene.sources[k].position - pose.emitter)
            assert np.allclose([lab["src_x"][i], lab["src_y"][i], lab["src_z"][i]], rel, atol=1e-4)
        assert lab["heard"][i] == int(lab["sound"][i] in TRAIN_SOUNDS)


def test_splits_are_by_room_and_the_paper_protocol(tiny_dataset):
    ds = open_dataset(tiny_dataset)
    lab = ds.labels
    rooms = {s: set(lab["scene"][lab["split"] == s]) for s in ("train", "val", "test")}
    assert all(rooms.values()) and not (rooms["train"] & rooms["test"]) and not (rooms["train"] & rooms["val"])
    test = ds.paper_split("test")
    assert set(lab["sound"][test]) == {"voice", "whistle", "chirp", "white_noise"}
    assert set(lab["sound"][ds.paper_split("train")]) == set(TRAIN_SOUNDS)
    # every frame's emitted sound can be regenerated exactly
    assert ds.emitted(0).shape == (4410,)
    assert set(lab["sound"]) == set(SOUNDS)


@pytest.mark.slow
def test_interrupted_generate_resumes_and_the_seed_fixes_every_array(tiny_dataset, tmp_path):
    out = tmp_path / "ds"
    # One worker makes the interruption deterministic: rooms run one after another.
    cmd = [sys.executable, "-m", "vrecho", "generate", "--out", str(out), "--preset", "tiny", "--seed", "0",
           "--workers", "1", "--cache", str(tmp_path / "cache"), "--quiet"]
    # A shell that starts jobs in the background (nohup, CI runners) passes SIGINT on as ignored;
    # restore the default so the child turns it into KeyboardInterrupt like a terminal's Ctrl-C.
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    deadline = time.time() + 300
    while not list((out / "progress").glob("*.csv")) if (out / "progress").exists() else True:
        assert proc.poll() is None and time.time() < deadline
        time.sleep(0.2)
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=300)
    assert proc.returncode == 130 and "rerun" in err
    finished = {p.name: p.read_bytes() for p in (out / "progress").glob("*.csv")}
    assert 1 <= len(finished) <= 2
    assert not json.loads((out / "manifest.json").read_text())["complete"]
    with pytest.raises(VrechoError, match="unfinished"):
        open_dataset(out)
    stamps = {p.name: p.stat().st_mtime_ns for p in (out / "progress").glob("*.csv")}
    generate(out, preset="tiny", seed=0, workers=2, cache=tmp_path / "cache", progress=False)
    for name, stamp in stamps.items():  # finished rooms were not redone
        assert (out / "progress" / name).stat().st_mtime_ns == stamp
    a, b = open_dataset(tiny_dataset), open_dataset(out)
    for name in ("audio", "logmel", "image", "ir"):
        assert np.array_equal(getattr(a, name)[:], getattr(b, name)[:]), name
    assert (tiny_dataset / "labels.csv").read_text() == (out / "labels.csv").read_text()


def test_other_dataset_in_the_folder_is_refused(tiny_dataset):
    with pytest.raises(VrechoError, match="holds another dataset"):
        generate(tiny_dataset, preset="tiny", seed=1)


def test_foreign_folder_is_refused(tmp_path):
    (tmp_path / "notes.txt").write_text("mine")
    with pytest.raises(VrechoError, match="not empty"):
        generate(tmp_path, preset="tiny")
    assert [p.name for p in tmp_path.iterdir()] == ["notes.txt"]  # nothing written


def test_label_columns_documented():
    assert "depth_m" in LABEL_COLUMNS and "is_open" in LABEL_COLUMNS and "material" in LABEL_COLUMNS
