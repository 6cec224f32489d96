"""Issue 28: generation and training on Ray, a local cluster on this machine (no network).

Each command starts its own local cluster (``--ray``: 2 CPUs here, a 1 GiB object store, no
dashboard, token authentication off), as a user's would."""

import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest
import torch

from conftest import run_cli
from vrecho.learn.cluster import latest_checkpoint


def _same_arrays(a, b) -> None:
    import zarr

    x, y = zarr.open_group(a / "frames.zarr", mode="r"), zarr.open_group(b / "frames.zarr", mode="r")
    for name in ("audio", "logmel", "image", "ir"):
        assert np.array_equal(x[name][:].view(np.uint8), y[name][:].view(np.uint8)), name
    assert (a / "labels.csv").read_bytes() == (b / "labels.csv").read_bytes()


def _interrupt_when(argv, ready, timeout_s=300):
    """Start ``vrecho *argv``, SIGINT it once ``ready()`` holds; return its exit status and stderr."""
    p = subprocess.Popen([sys.executable, "-m", "vrecho", *map(str, argv)], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                         text=True, preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    start = time.time()
    while not ready() and p.poll() is None and time.time() - start < timeout_s:
        time.sleep(0.05)
    p.send_signal(signal.SIGINT)
    _, err = p.communicate(timeout=timeout_s)
    return p.returncode, err


def test_ray_missing_or_absent_is_one_line(tmp_path):
    """Without Ray, --ray says how to install it; where no cluster listens, one line, at once;
    nothing is written either way. --workers without --ray is refused."""
    code = ("import sys; sys.modules['ray'] = None; from vrecho.cli import main; "
            f"sys.exit(main(['generate', '--out', {str(tmp_path / 'a')!r}, '--ray']))")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert r.returncode == 2 and r.stderr.strip() == "vrecho: error: --ray needs Ray, an extra: pip install 'vrecho[ray]'"
    t = time.time()
    r = run_cli("generate", "--out", tmp_path / "b", "--ray", "127.0.0.1:1")
    assert r.returncode == 2 and r.stderr.count("\n") == 1 and "no Ray cluster answers at '127.0.0.1:1'" in r.stderr
    assert time.time() - t < 30
    r = run_cli("train", "--data", tmp_path, "--out", tmp_path / "c", "--workers", "2")
    assert r.returncode == 2 and "go with --ray" in r.stderr
    assert not any((tmp_path / n).exists() for n in "abc")


@pytest.mark.slow
def test_ray_generation_resumed_after_ctrl_c_is_the_local_run_bit_for_bit(tiny_dataset, tmp_path):
    """The tiny preset as Ray tasks on a local cluster, interrupted after its first room and run
    again: the same arrays and labels as the process pool's run, bit for bit (each simulated
    anew: a cache of its own)."""
    out, cache = tmp_path / "ds", tmp_path / "cache"
    argv = ["generate", "--out", out, "--cache", cache, "--ray", "--quiet"]
    def rooms_done():  # (a room's file whole: the temporary file it is written to first is not one)
        return sorted((out / "progress").glob("scene_*.csv"))
    code, err = _interrupt_when(argv, lambda: bool(rooms_done()))
    done = len(rooms_done())
    assert code == 130 and err.strip().splitlines()[-1].startswith("vrecho: interrupted"), err
    assert 1 <= done < 6 and not (out / "labels.csv").exists()  # some rooms kept, the dataset unfinished
    r = run_cli(*argv)
    assert r.returncode == 0, r.stderr
    _same_arrays(out, tiny_dataset)


def test_a_checkpoint_cut_short_is_passed_over(tmp_path):
    """A run interrupted while Ray copied its newest checkpoint into the run's folder leaves that
    state.pt cut short: a rerun resumes from the newest whole one (torch.load fails on the other)."""
    whole, cut = tmp_path / "checkpoint_1", tmp_path / "checkpoint_2"
    for d in (whole, cut):
        d.mkdir()
    torch.save({"epoch": 1}, whole / "state.pt")
    (cut / "state.pt").write_bytes((whole / "state.pt").read_bytes()[:-100])
    os.utime(cut, (time.time() + 5, time.time() + 5))  # (the newest folder)
    assert latest_checkpoint(tmp_path) == whole
    assert latest_checkpoint(tmp_path / "none") is None


@pytest.mark.slow
def test_ray_training_on_two_workers_checkpoints_and_resumes(tiny_dataset, tmp_path):
    """EchoCNN-A on two Ray Train workers (distributed data parallel, gloo): it trains (its
    validation loss is finite), checkpoints every epoch through Ray Train, and a run interrupted
    after an epoch and run again ends with the weights of one never interrupted, bit for bit."""
    whole, cut = tmp_path / "whole", tmp_path / "cut"
    argv = ["train", "--data", tiny_dataset, "--method", "EchoCNN-A", "--epochs", "4", "--patience", "10",
            "--ray", "--workers", "2", "--quiet"]
    r = run_cli(*argv, "--out", whole)
    assert r.returncode == 0, r.stderr
    import json

    rec = json.loads((whole / "training.json").read_text())["EchoCNN-A"]
    assert rec["epochs"] == 4 and rec["ray_workers"] == 2 and rec["n_train"] > 0
    assert list((whole / "ray" / "echocnn_a").glob("checkpoint_*/state.pt"))
    state = torch.load(next((whole / "ray" / "echocnn_a").glob("checkpoint_*/state.pt")), weights_only=False)
    assert state["best"] < float("inf") and state["config"] == torch.load(whole / "models" / "echocnn_a.pt")["config"]

    # Interrupted once a checkpoint is whole; another may be cut short as Ray copies it (the rerun
    # passes over it: it once failed here, the interrupt landing mid-copy).
    ckpts = cut / "ray" / "echocnn_a"
    code, err = _interrupt_when([*argv, "--out", cut], lambda: latest_checkpoint(ckpts) is not None)
    assert code == 130, err
    first = torch.load(latest_checkpoint(ckpts) / "state.pt", weights_only=False)["epoch"]
    assert 1 <= first < 4  # interrupted between epochs
    r = run_cli(*argv, "--out", cut)
    assert r.returncode == 0, r.stderr
    a, b = torch.load(whole / "models" / "echocnn_a.pt"), torch.load(cut / "models" / "echocnn_a.pt")
    assert all(torch.equal(a["state"][k], b["state"][k]) for k in a["state"])


@pytest.mark.slow
def test_the_headset_views_training_on_two_ray_workers(tmp_path):
    """The headset view's glass/mirror model the same way: its crops through Ray's object store,
    two workers, a checkpoint per epoch; it learns a cue a crop carries as the one-process path
    does."""
    from vrecho.learn.headset_view import train

    rng = np.random.default_rng(0)
    n = 400
    data = {"crops": rng.integers(0, 255, (n, 64, 25), dtype=np.uint8), "mirror": rng.integers(0, 2, n).astype(bool),
            "room": np.repeat(np.arange(40), 10)}
    data["crops"][data["mirror"], :, :12] = 250  # the mirrors' left half bright
    code = ("import sys, pickle, pathlib; from vrecho.learn.headset_view import train; "
            "data = pickle.load(open(sys.argv[1], 'rb')); "
            "model, figures = train(data, epochs=3, progress=False, ray='auto', workers=2, "
            "checkpoints=pathlib.Path(sys.argv[2])); print(figures['val_accuracy'], figures['epochs'])")
    import pickle

    (tmp_path / "data.pkl").write_bytes(pickle.dumps(data))
    r = subprocess.run([sys.executable, "-c", code, str(tmp_path / "data.pkl"), str(tmp_path / "ck")], capture_output=True,
                       text=True, timeout=600)
    assert r.returncode == 0, r.stderr
    accuracy, epochs = r.stdout.split()[-2:]
    assert float(accuracy) >= 0.9 and int(epochs) == 3
    assert list((tmp_path / "ck" / "headset_view").glob("checkpoint_*/state.pt"))
    local, figures = train(data, epochs=3, progress=False)
    assert figures["val_accuracy"] >= 0.9


@pytest.mark.slow
def test_the_mask_networks_walks_and_training_on_ray(tmp_path):
    """The mask network's training walks as Ray tasks, one per share: the same shards as the
    process pool's, bit for bit. Its training on two Ray Train workers, each reading its share
    of the examples from the shards: it trains (finite validation losses, weights that load),
    checkpoints each epoch, and a rerun reads the finished run instead of training again."""
    code = ("import sys, pathlib; from vrecho.learn.masknet import make_examples, train\n"
            "if __name__ == '__main__':\n"
            "    d = pathlib.Path(sys.argv[1])\n"
            "    make_examples(d / 'pool', rooms=2, jobs=2)\n"
            "    make_examples(d / 'ray', rooms=2, jobs=2, ray='auto')\n"
            "    for k in range(2):\n"
            "        h = train(d / f'mask{k}.pt', rooms=2, jobs=2, epochs=2, width=4, data_dir=d / 'ray', progress=False,\n"
            "                  ray='auto', workers=2, checkpoints=d / 'ck')\n"
            "        print('losses', *h)\n")
    (tmp_path / "make.py").write_text(code)
    r = subprocess.run([sys.executable, str(tmp_path / "make.py"), str(tmp_path)], capture_output=True, text=True,
                       timeout=600)
    assert r.returncode == 0, r.stderr
    for share in ("share0.npz", "share1.npz"):
        a, b = np.load(tmp_path / "pool" / share), np.load(tmp_path / "ray" / share)
        assert len(a["f"]) > 0
        assert all(np.array_equal(a[k].view(np.uint8), b[k].view(np.uint8)) for k in "fmt")
    first, again = (line.split()[1:] for line in r.stdout.splitlines() if line.startswith("losses"))
    assert len(first) == 2 and all(np.isfinite(float(v)) for v in first) and again == first
    checkpoints = list((tmp_path / "ck" / "masknet").glob("checkpoint_*/state.pt"))
    assert checkpoints and max(torch.load(c, weights_only=False)["epoch"] for c in checkpoints) == 2
    from localization.masknet import masknet_class

    a, b = torch.load(tmp_path / "mask0.pt"), torch.load(tmp_path / "mask1.pt")
    masknet_class()(4).load_state_dict({k: v.float() for k, v in a.items()})
    assert all(torch.equal(a[k], b[k]) for k in a)
