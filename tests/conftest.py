import os
import shutil
import subprocess
import sys

import pytest


@pytest.fixture(scope="session")
def tiny_dataset(tmp_path_factory):
    """The tiny preset, generated once per session with a cache of its own (so it is simulated)."""
    from vrecho.data import generate

    root = tmp_path_factory.mktemp("tiny")
    return generate(root / "ds", "tiny", seed=0, workers=2, cache=root / "cache", progress=False)


def run_cli(*args, timeout=600):
    """Run the ``vrecho`` command in a fresh interpreter; returns the CompletedProcess."""
    return subprocess.run([sys.executable, "-m", "vrecho", *map(str, args)], capture_output=True, text=True,
                          timeout=timeout)
