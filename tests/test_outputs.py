"""Outputs under one policy: nothing of a user's overwritten, nothing partial left (a full disk is a
real file-size limit of the operating system), one line for an interrupt."""

import json
import os
import resource
import signal
import subprocess
import sys
import time

import pytest
from conftest import run_cli, small_room

from vrecho.cli import main
from vrecho.errors import VrechoError
from vrecho.io import OutputFolder


def _write(folder, names):
    with folder.writing() as stage:
        for n in names:
            (stage / n).write_text(n)


def test_output_folder_policy(tmp_path):
    out = tmp_path / "run"
    with OutputFolder(out, "reconstruct") as f:
        _write(f, ["a.txt", "b.txt"])
    with OutputFolder(out, "reconstruct") as f:  # a rerun replaces its own files; b.txt is stale and goes
        _write(f, ["a.txt"])
    assert sorted(p.name for p in out.iterdir()) == [".vrecho-outputs.json", "a.txt"]
    (out / "mine.txt").write_text("the user's")
    with pytest.raises(VrechoError, match=r"mine.txt.*--force"):
        OutputFolder(out, "reconstruct")
    with pytest.raises(VrechoError, match="did not write"):  # another command's files are not its own
        OutputFolder(tmp_path / "run", "capture", force=False)
    with OutputFolder(out, "reconstruct", force=True) as f:
        _write(f, ["a.txt", "c.txt"])
    assert (out / "mine.txt").read_text() == "the user's" and (out / "c.txt").exists()
    # A failure while writing leaves the folder as it was, without a staging folder.
    before = {p.name: p.read_bytes() for p in out.iterdir()}
    with pytest.raises(RuntimeError), OutputFolder(out, "reconstruct", force=True) as f, f.writing() as stage:
        (stage / "a.txt").write_text("half")
        raise RuntimeError
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before
    # A folder made for a command that then fails is removed again; a file is no folder.
    with pytest.raises(RuntimeError), OutputFolder(tmp_path / "new", "demo"):
        raise RuntimeError
    assert not (tmp_path / "new").exists()
    with pytest.raises(VrechoError, match="is a file"):
        OutputFolder(out / "a.txt", "demo")


def _full_disk():
    # A file-size limit of 1 MB: every write past it fails as a full disk does (EFBIG, not a signal).
    signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
    resource.setrlimit(resource.RLIMIT_FSIZE, (1_000_000, 1_000_000))


def test_full_disk_writes_nothing_and_a_rerun_replaces_only_its_own(tmp_path):
    scene = tmp_path / "small.json"
    scene.write_text(json.dumps(small_room().to_dict()))
    out = tmp_path / "out"
    args = ["reconstruct", str(scene), "--out", str(out), "--frames", "6", "--labels", "oracle", "--quiet"]
    r = subprocess.run([sys.executable, "-m", "vrecho", *args], capture_output=True, text=True, preexec_fn=_full_disk,
                       timeout=600)
    lines = r.stderr.strip().splitlines()
    assert r.returncode == 2 and len(lines) == 1 and "the disk is full" in lines[0], r.stderr
    assert str(out / "initial.ply") in lines[0] and not out.exists()  # the final name, and nothing left
    # Without the limit: written whole; a user's file in the folder is refused, then kept with --force.
    assert main(args) == 0
    written = sorted(p.name for p in out.iterdir())
    assert written == [".vrecho-outputs.json", "before_after.png", "initial.ply", "repaired.ply", "report.json"]
    (out / "notes.txt").write_text("mine")
    assert main(args) == 2 and (out / "notes.txt").read_text() == "mine"
    assert main([*args, "--force"]) == 0 and (out / "notes.txt").read_text() == "mine"


def test_export_refuses_a_file_it_did_not_write(tmp_path):
    stage = tmp_path / "room.usda"
    stage.write_text("#usda 1.0\n(\n    doc = \"someone else's\"\n)\n")
    r = run_cli("export", "builtin", "--out", stage, "--quiet", timeout=120)
    assert r.returncode == 2 and "--force" in r.stderr and len(r.stderr.strip().splitlines()) == 1
    assert "someone else's" in stage.read_text()


def test_bad_sources_file_refused_before_any_work(tmp_path):
    bad = tmp_path / "sources.json"
    bad.write_text("[{\"position\": [1, 2], \"wav\": \"x.wav\"}]")
    start = time.perf_counter()
    r = run_cli("export", "builtin", "--out", tmp_path / "room.usda", "--sources", bad, "--quiet", timeout=120)
    assert r.returncode == 2 and "sources" in r.stderr and time.perf_counter() - start < 30
    assert not (tmp_path / "room.usda").exists()


def test_interrupted_generation_says_one_line(tmp_path):
    """Ctrl-C reaches the whole process group: the driver says one line, no worker a traceback."""
    p = subprocess.Popen([sys.executable, "-m", "vrecho", "generate", "--out", str(tmp_path / "ds"), "--workers", "2",
                          "--preset", "default", "--cache", str(tmp_path / "cache"), "--quiet"],
                         stderr=subprocess.PIPE, text=True, start_new_session=True,
                         # as a terminal starts it: a shell's background job (CI) inherits SIGINT ignored
                         preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    deadline = time.time() + 300
    while not list((tmp_path / "ds").glob("progress/scene_*.csv")) and time.time() < deadline:
        time.sleep(0.1)  # until a room is finished: the workers are at work (the tiny preset's six rooms can all
        # finish within that tenth of a second; the default's 160 cannot)
    os.killpg(p.pid, signal.SIGINT)
    _, err = p.communicate(timeout=900)  # the rooms under way finish first (seconds; minutes under load)
    assert p.returncode == 130, err
    assert err.strip().splitlines() == ["vrecho: interrupted; finished work is kept: rerun the same command to resume"]
