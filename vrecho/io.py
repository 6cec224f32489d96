"""Files written whole or not at all (a temporary file beside the target, renamed into place),
and a user's mesh read with one clear error."""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

import numpy as np

from .errors import VrechoError


def ensure_writable_dir(path: str | Path) -> Path:
    """Create ``path`` if needed and check that files can be written in it.

    The check writes and removes a hidden probe file (``.write-test-*``) in the folder.

    Parameters
    ----------
    path : str or pathlib.Path
        The output folder; missing parents are created too.

    Returns
    -------
    pathlib.Path
        ``path``, as a ``Path``.

    Raises
    ------
    VrechoError
        If the folder cannot be created or a file cannot be written in it.
    """
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
    """Write ``text`` to ``path`` whole or not at all.

    The text goes, UTF-8 encoded, to a temporary file beside the target, which is flushed to disk
    and renamed into place; on any failure the temporary file is removed and the target is left
    as it was. The file gets the usual permissions (0666 less the umask).

    Parameters
    ----------
    path : str or pathlib.Path
        The file to write; its folder must exist.
    text : str
        The whole content.

    Returns
    -------
    pathlib.Path
        ``path``, as a ``Path``.
    """
    return _atomic(Path(path), lambda f: f.write(text.encode()))


def atomic_save_npy(path: str | Path, array: np.ndarray) -> Path:
    """Save ``array`` in NumPy's ``.npy`` format to ``path``, whole or not at all.

    As :func:`atomic_write_text`: a temporary file beside the target, renamed into place. The
    file is written at ``path`` exactly (no ``.npy`` suffix is added).

    Parameters
    ----------
    path : str or pathlib.Path
        The file to write; its folder must exist.
    array : numpy.ndarray
        Any array ``numpy.save`` accepts.

    Returns
    -------
    pathlib.Path
        ``path``, as a ``Path``.
    """
    return _atomic(Path(path), lambda f: np.save(f, array))


def read_mesh(path: str | Path):
    """A user's triangle mesh (.ply or .obj), read with open3d; one error if it is not one.

    Parameters
    ----------
    path : str or pathlib.Path
        A ``.ply`` or ``.obj`` file (the suffix in any case).

    Returns
    -------
    open3d.geometry.TriangleMesh
        The mesh, with at least one triangle.

    Raises
    ------
    VrechoError
        If the suffix is neither ``.ply`` nor ``.obj``, the file does not exist, or it holds no
        triangles.
    """
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
