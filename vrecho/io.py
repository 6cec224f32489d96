"""Files written whole or not at all (a temporary file beside the target, renamed into place),
output folders under one policy (:class:`OutputFolder`), and a user's mesh read with one clear
error."""

from __future__ import annotations

import contextlib
import errno
import json
import os
import shutil
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


def _write_failed(path: Path, e: OSError) -> VrechoError:
    """One line for an operating system's refusal to write (a full disk, a read-only folder)."""
    why = "the disk is full" if e.errno in (errno.ENOSPC, errno.EDQUOT, errno.EFBIG) else (e.strerror or str(e))
    return VrechoError(f"out: writing {path} failed ({why}); nothing was written")


def write_mesh(path: str | Path, mesh) -> Path:
    """Write a triangle mesh as binary PLY to ``path``, whole or not at all.

    Written here, with NumPy, rather than by open3d: open3d's writer reports success on a full
    disk (its PLY library prints a line per face it failed to write and leaves a truncated file).
    The layout is the one open3d writes and reads (vertices as doubles, normals and colours where
    the mesh has them, faces as lists of three ints); the file goes to a temporary name beside
    the target and is renamed into place when complete.

    Parameters
    ----------
    path : str or pathlib.Path
        The ``.ply`` file to write; its folder must exist.
    mesh : open3d.geometry.TriangleMesh
        Any mesh; normals and colours are written where it has them (colours in [0, 1]).

    Returns
    -------
    pathlib.Path
        ``path``, as a ``Path``.

    Raises
    ------
    VrechoError
        When the file cannot be written whole (a full disk, a read-only folder).

    Examples
    --------
    >>> import tempfile, open3d as o3d
    >>> tmp = tempfile.TemporaryDirectory()
    >>> box = o3d.geometry.TriangleMesh.create_box()
    >>> back = o3d.io.read_triangle_mesh(str(write_mesh(Path(tmp.name) / "box.ply", box)))
    >>> len(back.vertices), len(back.triangles), np.allclose(back.vertices, box.vertices)
    (8, 12, True)
    >>> tmp.cleanup()
    """
    path = Path(path)
    v = np.asarray(mesh.vertices, dtype="<f8")
    fields, columns = [("x", "<f8"), ("y", "<f8"), ("z", "<f8")], [v]
    if mesh.has_vertex_normals():
        fields += [("nx", "<f8"), ("ny", "<f8"), ("nz", "<f8")]
        columns.append(np.asarray(mesh.vertex_normals, dtype="<f8"))
    if mesh.has_vertex_colors():
        fields += [("red", "u1"), ("green", "u1"), ("blue", "u1")]
        columns.append(np.round(np.clip(np.asarray(mesh.vertex_colors), 0.0, 1.0) * 255))
    vertices = np.empty(len(v), dtype=fields)
    names = iter(n for n, _ in fields)
    for c in columns:
        for j in range(3):
            vertices[next(names)] = c[:, j]
    t = np.asarray(mesh.triangles)
    faces = np.empty(len(t), dtype=[("n", "u1"), ("i", "<i4", (3,))])
    faces["n"], faces["i"] = 3, t
    kinds = {"<f8": "double", "u1": "uchar"}
    header = ["ply", "format binary_little_endian 1.0", "comment written by vrecho", f"element vertex {len(v)}",
              *(f"property {kinds[k]} {n}" for n, k in fields), f"element face {len(t)}",
              "property list uchar int vertex_indices", "end_header"]

    def dump(f):
        f.write(("\n".join(header) + "\n").encode("ascii"))
        f.write(vertices.tobytes())
        f.write(faces.tobytes())

    try:
        return _atomic(path, dump)
    except OSError as e:
        raise _write_failed(path, e) from None


class OutputFolder:
    """An output folder under vrecho's one policy, checked before any work, written all at once.

    The policy: a command writes into a folder that is new, empty, or holds only what the same
    command wrote there before (listed in the folder's ``.vrecho-outputs.json``); a folder
    holding anything else is refused unless ``force``, so a user's files are never overwritten
    or mixed with a run's. The run's files are written into a hidden staging folder inside it
    (:meth:`writing`) and moved into place only when all are complete; files of an earlier run
    that this one does not write are removed, so none is left stale beside the new ones. A
    failed write (a full disk, a read-only folder) leaves the folder as it was, and a folder
    this object created is removed again if the command fails.

    Parameters
    ----------
    path : str or pathlib.Path
        The output folder; created (with its parents) if missing.
    command : str
        The command that writes it (e.g. ``"reconstruct"``), recorded in the listing.
    force : bool
        Write beside files the command did not write (same names are replaced).

    Raises
    ------
    VrechoError
        If ``path`` is a file, cannot be created or written in, or holds files the command did
        not write (without ``force``).

    Examples
    --------
    >>> import tempfile
    >>> tmp = tempfile.TemporaryDirectory()
    >>> with OutputFolder(Path(tmp.name) / "run", "reconstruct") as folder:
    ...     with folder.writing() as stage:
    ...         _ = (stage / "report.json").write_text("{}")
    >>> sorted(p.name for p in (Path(tmp.name) / "run").iterdir())
    ['.vrecho-outputs.json', 'report.json']
    >>> tmp.cleanup()
    """

    LISTING = ".vrecho-outputs.json"
    _STAGING = ".vrecho-staging-"

    def __init__(self, path: str | Path, command: str, *, force: bool = False):
        self.path, self.command = Path(path), command
        if self.path.exists() and not self.path.is_dir():
            raise VrechoError(f"out: {self.path} is a file, not a folder")
        self.created = not self.path.exists()
        ensure_writable_dir(self.path)
        self.previous = self._listing()
        foreign = sorted(p.name for p in self.path.iterdir()
                         if p.name != self.LISTING and not p.name.startswith(self._STAGING)
                         and p.name not in self.previous)
        if foreign and not force:
            self._discard()
            names = ", ".join(foreign[:3]) + (f" and {len(foreign) - 3} more" if len(foreign) > 3 else "")
            raise VrechoError(f"out: {self.path} holds files `vrecho {command}` did not write ({names}); "
                              "choose a new or empty folder, or pass --force to write beside them")

    def _listing(self) -> list[str]:
        try:
            d = json.loads((self.path / self.LISTING).read_text())
        except (OSError, ValueError, RecursionError):
            return []
        ok = isinstance(d, dict) and d.get("command") == self.command and isinstance(d.get("files"), list)
        return [f for f in d["files"] if isinstance(f, str) and "/" not in f and f not in ("", ".", "..")] if ok else []

    def _discard(self) -> None:
        if self.created:
            with contextlib.suppress(OSError):
                self.path.rmdir()  # only if still empty: nothing of the user's is ever removed

    def __enter__(self) -> "OutputFolder":
        return self

    def __exit__(self, kind, value, tb) -> None:
        if kind is not None:
            self._discard()

    @contextlib.contextmanager
    def writing(self):
        """A staging folder to write the run's files into; moved into place when the block ends.

        Yields
        ------
        pathlib.Path
            The staging folder (hidden, inside the output folder): write every file there, with
            the names they should have in the output folder.

        Raises
        ------
        VrechoError
            When a file cannot be written (a full disk: ``OSError`` from any writer in the
            block); the output folder is left as it was.
        """
        try:
            stage = Path(tempfile.mkdtemp(dir=self.path, prefix=self._STAGING))
        except OSError as e:
            raise _write_failed(self.path, e) from None
        try:
            yield stage
            names = sorted(p.name for p in stage.iterdir())
            atomic_write_text(stage / self.LISTING, json.dumps({"command": self.command, "files": names}, indent=1))
            old = stage / ".previous"
            old.mkdir()
            for name in set(names) | set(self.previous):  # this run's names and the last run's stale ones
                target = self.path / name
                if target.is_dir() and not target.is_symlink():
                    os.replace(target, old / name)  # a folder cannot be renamed over: move it out first
                elif name not in names and target.exists():
                    target.unlink()
            for name in (*names, self.LISTING):
                os.replace(stage / name, self.path / name)  # renames within one folder: cannot fill the disk
        except OSError as e:
            raise _write_failed(self.path, e) from None
        except VrechoError as e:  # a writer's own one line names the final place, not the staging folder
            raise VrechoError(str(e).replace(str(stage), str(self.path))) from None
        finally:
            shutil.rmtree(stage, ignore_errors=True)


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
