"""Files written whole or not at all (a temporary file beside the target, renamed into place),
and a user's mesh read with one clear error."""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

import numpy as np

from .errors import VrechoError


def ensure_writable_dir(path: str | Path) -> Path:
    """Create ``path`` if needed and check that files can be written in it."""
    path = Path(path)
    try:
        path.mkdir(parents=True, exist_ok=True)
        fd, probe = tempfile.mkstemp(dir=path, prefix=".write-test-")
        os.close(fd)
        os.unlink(probe)
    except OSError as e:
        raise VrechoError(f"output folder {path}: not writable ({e.strerror or e})") from None
    return path


def _atomic(path: Path, write) -> Path:
    path = Path(path)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as f:
            write(f)
            f.flush()
            os.fsync(f.fileno())
        mask = os.umask(0)
        os.umask(mask)
        os.chmod(tmp, 0o666 & ~mask)  # mkstemp's 0600 would hide results from other users
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise
    return path


def atomic_write_text(path: str | Path, text: str) -> Path:
    return _atomic(Path(path), lambda f: f.write(text.encode()))


def atomic_save_npy(path: str | Path, array: np.ndarray) -> Path:
    return _atomic(Path(path), lambda f: np.save(f, array))


def read_mesh(path: str | Path):
    """A user's triangle mesh (.ply or .obj) with open3d; one error if it is not one."""
    import open3d as o3d  # heavy (1.2 s to import): only where meshes are made or ray-cast

    path = Path(path)
    if path.suffix.lower() not in (".ply", ".obj"):
        raise VrechoError(f"mesh: {path} is not a .ply or .obj file")
    if not path.is_file():
        raise VrechoError(f"mesh: {path} does not exist")
    mesh = o3d.io.read_triangle_mesh(str(path))
    if not len(mesh.triangles):
        raise VrechoError(f"mesh: {path} holds no triangles (expected a triangle mesh, .ply or .obj)")
    return mesh
