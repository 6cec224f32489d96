import subprocess
import sys

import pytest


@pytest.fixture(scope="session")
def tiny_dataset(tmp_path_factory):
    """The tiny preset, generated once per session with a cache of its own (so it is simulated)."""
    from vrecho.learn.datasets import generate

    root = tmp_path_factory.mktemp("tiny")
    return generate(root / "ds", preset="tiny", seed=0, workers=2, cache=root / "cache", progress=False)


def run_cli(*args, timeout=600):
    """Run the ``vrecho`` command in a fresh interpreter; returns the CompletedProcess."""
    return subprocess.run([sys.executable, "-m", "vrecho", *map(str, args)], capture_output=True, text=True,
                          timeout=timeout)


def small_room(sources: bool = False):
    """A 4.2 x 3.6 m room with one window, one mirror and one opening (and a sound source)."""
    from vrecho.scene import Scene

    wall = {"name": "plasterboard", "absorption": [0.15, 0.1, 0.06, 0.04, 0.04, 0.05, 0.05], "scattering": 0.1}
    floor = {"name": "carpet", "absorption": [0.05, 0.1, 0.2, 0.35, 0.5, 0.6, 0.6], "scattering": 0.1}
    return Scene.from_dict({
        "format": "vrecho-scene", "version": 1, "name": "small_room", "emitter_p": 0.7,
        "room": {"footprint": [[0, 0], [4.2, 0], [4.2, 3.6], [0, 3.6]], "height_m": 2.5,
                 "walls": [wall] * 4, "floor": floor, "ceiling": wall},
        "discontinuities": [
            {"wall": 0, "center_u_m": 2.1, "center_z_m": 1.4, "width_m": 1.2, "height_m": 1.0, "kind": "glass"},
            {"wall": 1, "center_u_m": 1.8, "center_z_m": 1.3, "width_m": 0.9, "height_m": 1.2, "kind": "mirror"},
            {"wall": 2, "center_u_m": 2.1, "center_z_m": 1.4, "width_m": 1.0, "height_m": 1.0, "kind": "open"}],
        "sources": [{"position": [1.5, 2.0, 1.1], "sound": "voice"}] if sources else []})


def export_small_room(tmp_path, out_name: str, sources: str) -> int:
    """``vrecho export`` (in this process) of :func:`small_room` with its source, oracle labels, 24
    frames, ``--sources`` as given, to ``tmp_path / out_name``; returns the exit status."""
    import json

    from vrecho.cli import main

    scene_file = tmp_path / "small.json"
    scene_file.write_text(json.dumps(small_room(sources=True).to_dict()))
    return main(["export", str(scene_file), "--out", str(tmp_path / out_name), "--labels", "oracle", "--frames", "24",
                 "--sources", sources, "--quiet"])
