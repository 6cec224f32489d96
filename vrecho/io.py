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
import zipfile
import zlib
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


MAX_MESH_BYTES = 1 << 30
"""Largest mesh file read (1 GiB): a room's scan is well under; beyond it a file is refused
before it is read."""
MAX_MESH_ELEMENTS = 10_000_000
"""Most vertices, and most faces, a mesh may have (a phone's scan of a room has under a few
million); a file saying more is refused before anything is allocated."""
MAX_COORDINATE_M = 1e6
"""Largest vertex coordinate taken, in metres: a room is metres across; larger numbers (a
georeferenced model, or garbage) overflow the ray casting's single precision."""

_PLY_TYPES = {"char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1", "short": "i2", "int16": "i2",
              "ushort": "u2", "uint16": "u2", "int": "i4", "int32": "i4", "uint": "u4", "uint32": "u4",
              "float": "f4", "float32": "f4", "double": "f8", "float64": "f8"}


def read_mesh(path: str | Path):
    """A user's triangle mesh (.ply, ASCII or binary, or .obj), read and checked; one error if it
    is not one.

    The file is parsed here, not by open3d, whose PLY reader crashes the process on some damaged
    files (a truncated header, a list of the wrong length); only checked arrays reach open3d.
    Polygons are cut into triangles (fans); vertex colours (PLY's ``red``, ``green``, ``blue``,
    or OBJ's ``v x y z r g b``) are kept, normals and texture coordinates dropped. Degenerate
    triangles are kept.

    Parameters
    ----------
    path : str or pathlib.Path
        A ``.ply`` or ``.obj`` file (the suffix in any case), at most :data:`MAX_MESH_BYTES`.

    Returns
    -------
    open3d.geometry.TriangleMesh
        The mesh: at least one triangle, every index a vertex of it, every coordinate finite
        and within :data:`MAX_COORDINATE_M` metres.

    Raises
    ------
    VrechoError
        Naming the file, if the suffix is neither ``.ply`` nor ``.obj``, the file does not exist
        or cannot be read, is larger than :data:`MAX_MESH_BYTES` or says it holds more than
        :data:`MAX_MESH_ELEMENTS` vertices or faces, is not a well-formed PLY or OBJ file (not
        text where text is due, a truncated file, a face of fewer than 3 vertices), holds no
        triangle, a vertex index out of range, or a coordinate that is not finite or beyond
        :data:`MAX_COORDINATE_M`.
    """
    import open3d as o3d  # heavy (1.2 s to import): only where meshes are made or ray-cast

    path = Path(path)
    if path.suffix.lower() not in (".ply", ".obj"):
        raise VrechoError(f"mesh: {path} is not a .ply or .obj file")
    if not path.is_file():
        raise VrechoError(f"mesh: {path} does not exist")
    try:
        if path.stat().st_size > MAX_MESH_BYTES:
            raise VrechoError(f"mesh: {path} is {path.stat().st_size / 2**30:.1f} GiB, larger than the "
                              f"{MAX_MESH_BYTES / 2**30:.0f} GiB a room's mesh needs")
        data = path.read_bytes()
    except OSError as e:
        raise VrechoError(f"mesh: {path}: cannot read it ({e.strerror or e})") from None
    vertices, triangles, colours = (_read_ply if path.suffix.lower() == ".ply" else _read_obj)(data, path)
    if not len(triangles):
        raise VrechoError(f"mesh: {path} holds no triangles (expected a triangle mesh, .ply or .obj)")
    if not np.all(np.isfinite(vertices)):
        bad = int(np.flatnonzero(~np.isfinite(vertices).all(axis=1))[0])
        raise VrechoError(f"mesh: {path}: vertex {bad} is not finite ({vertices[bad].tolist()}); expected finite "
                          "coordinates in metres")
    if len(vertices) and np.abs(vertices).max() > MAX_COORDINATE_M:
        raise VrechoError(f"mesh: {path}: a coordinate is {np.abs(vertices).max():.3g}, beyond {MAX_COORDINATE_M:g} "
                          "m; expected a room in metres near the origin")
    out = (triangles < 0) | (triangles >= len(vertices))
    if out.any():
        k = int(np.flatnonzero(out.any(axis=1))[0])
        raise VrechoError(f"mesh: {path}: triangle {k} names vertex {int(triangles[out][0])}, outside 0 to "
                          f"{len(vertices) - 1} (the mesh has {len(vertices)} vertices)")
    mesh = o3d.geometry.TriangleMesh(o3d.utility.Vector3dVector(vertices),
                                     o3d.utility.Vector3iVector(triangles.astype(np.int32)))
    if colours is not None:
        mesh.vertex_colors = o3d.utility.Vector3dVector(colours)
    return mesh


def _mesh_error(path: Path, what: str) -> VrechoError:
    return VrechoError(f"mesh: {path}: {what}; expected a triangle mesh (.ply or .obj)")


def _fans(counts: np.ndarray, flat: np.ndarray, path: Path) -> np.ndarray:
    """Triangles (T, 3) of polygons given as their sizes ``counts`` and their vertex indices one
    after another in ``flat``: each polygon cut into a fan from its first vertex."""
    counts = np.asarray(counts, np.int64)
    if (counts < 3).any():
        k = int(np.flatnonzero(counts < 3)[0])
        raise _mesh_error(path, f"face {k} has {counts[k]} vertices, fewer than a triangle's 3")
    start = np.cumsum(counts) - counts
    n_tri = counts - 2
    face = np.repeat(np.arange(len(counts)), n_tri)
    k = np.arange(int(n_tri.sum())) - np.repeat(np.cumsum(n_tri) - n_tri, n_tri)
    flat = np.asarray(flat)
    if flat.dtype.kind == "f":  # ASCII: whole numbers written as text; others are not indices
        if not np.all(np.isfinite(flat) & (flat == np.round(flat))):
            raise _mesh_error(path, "a vertex index is not a whole number")
        flat = flat.astype(np.float64)
    flat = np.clip(flat, -2**62, 2**62).astype(np.int64)  # uint32 and huge ASCII numbers: range-checked later
    return np.stack([flat[start[face]], flat[start[face] + k + 1], flat[start[face] + k + 2]], axis=1)


def _read_ply(data: bytes, path: Path):
    """PLY (http://paulbourke.net/dataformats/ply/): vertices (V, 3), triangles (T, 3), colours
    (V, 3) in [0, 1] or None."""
    end = data.find(b"end_header", 0, 1 << 16)
    newline = data.find(b"\n", end)
    if not data.startswith(b"ply") or end < 0 or newline < 0:
        raise _mesh_error(path, "not a PLY file (no 'ply' ... 'end_header' header)")
    try:
        header = data[:end].decode("ascii").replace("\r", "").split("\n")
    except UnicodeDecodeError:
        raise _mesh_error(path, "its header is not text") from None
    fmt, elements = None, []  # elements: [name, count, [(property, type, list count type or None)]]
    for n, line in enumerate(header[1:], start=2):
        t = line.split()
        if not t or t[0] in ("comment", "obj_info"):
            continue
        if t[0] == "format" and len(t) == 3 and t[1] in ("ascii", "binary_little_endian", "binary_big_endian"):
            fmt = t[1]
        elif t[0] == "element" and len(t) == 3 and t[2].isdigit():
            if int(t[2]) > MAX_MESH_ELEMENTS:
                raise _mesh_error(path, f"its header says {int(t[2])} {t[1]!r} elements, more than {MAX_MESH_ELEMENTS}")
            elements.append((t[1], int(t[2]), []))
        elif t[0] == "property" and elements and len(t) == 3 and t[1] in _PLY_TYPES:
            elements[-1][2].append((t[2], _PLY_TYPES[t[1]], None))
        elif (t[0] == "property" and elements and len(t) == 5 and t[1] == "list" and t[2] in _PLY_TYPES
              and _PLY_TYPES[t[2]][0] in "iu" and t[3] in _PLY_TYPES):
            elements[-1][2].append((t[4], _PLY_TYPES[t[3]], _PLY_TYPES[t[2]]))
        else:
            raise _mesh_error(path, f"header line {n} ({line[:40]!r}) is not PLY")
    if fmt is None:
        raise _mesh_error(path, "its header has no 'format' line")
    body = data[newline + 1:]
    read = _ply_ascii if fmt == "ascii" else _ply_binary
    values = read(body, elements, "<" if fmt == "binary_little_endian" else ">", path)
    vertex = values.get("vertex", {})
    if not {"x", "y", "z"} <= vertex.keys() or any(isinstance(vertex[c], tuple) for c in "xyz"):
        raise _mesh_error(path, "it has no vertex element with x, y and z")
    vertices = np.stack([np.asarray(vertex[c], np.float64) for c in "xyz"], axis=1)
    colours = None
    if {"red", "green", "blue"} <= vertex.keys() and not any(isinstance(vertex[c], tuple) for c in ("red", "green", "blue")):
        types = {name: dt for name, dt, _ in next(e for e in elements if e[0] == "vertex")[2]}
        colours = np.stack([np.asarray(vertex[c], np.float64) / (np.iinfo(types[c]).max if types[c][0] in "iu" else 1)
                            for c in ("red", "green", "blue")], axis=1)
        colours = np.clip(np.nan_to_num(colours), 0, 1)
    face = values.get("face", {})
    lists = [face[k] for k in ("vertex_indices", "vertex_index") if isinstance(face.get(k), tuple)]
    triangles = _fans(*lists[0], path) if lists else np.zeros((0, 3), np.int64)
    return vertices, triangles, colours


def _ply_ascii(body: bytes, elements, _, path: Path) -> dict:
    """Each element's properties from PLY's ASCII body, one instance a line: a scalar property as
    an array (floats), a list as (counts, values one after another)."""
    try:
        lines = [line for line in body.decode("ascii").split("\n") if line.strip()]
    except UnicodeDecodeError:
        raise _mesh_error(path, "its ASCII data is not text") from None
    out, row = {}, 0
    for name, count, props in elements:
        rows = [line.split() for line in lines[row:row + count]]
        if len(rows) < count:
            raise _mesh_error(path, f"the file ends after {len(rows)} of its {count} {name!r} elements (truncated)")
        try:
            out[name] = _ply_ascii_table(rows, props) or _ply_ascii_rows(rows, props)
        except (ValueError, OverflowError, IndexError):
            raise _mesh_error(path, f"its {name!r} elements (data lines {row + 1} to {row + count}) hold something "
                                    "other than the numbers its header says") from None
        row += count
    return out


def _ply_ascii_table(rows, props) -> dict | None:
    """An element read as one array, where its lines are alike: scalars only, or one list of one
    length (faces all triangles, the usual case); None otherwise."""
    width = len(rows[0]) if rows else 0
    if any(len(r) != width for r in rows):
        return None
    if all(p[2] is None for p in props) and width == len(props):
        table = np.array(rows, np.float64).reshape(len(rows), width)
        return {p[0]: table[:, j] for j, p in enumerate(props)}
    if len(props) == 1 and props[0][2] is not None and rows and all(r[0] == rows[0][0] for r in rows):
        table = np.array(rows, np.float64).reshape(len(rows), width)
        if table[0, 0] == width - 1:
            return {props[0][0]: (table[:, 0], table[:, 1:].ravel())}
    return None


def _ply_ascii_rows(rows, props) -> dict:
    columns = {p[0]: [] for p in props}
    lists = {p[0]: [] for p in props if p[2] is not None}
    for r in rows:
        j = 0
        for prop, _, list_type in props:
            if list_type is None:
                columns[prop].append(float(r[j]))
                j += 1
            else:
                c = int(r[j])
                if c < 0 or j + 1 + c > len(r):
                    raise ValueError
                lists[prop].append(c)
                columns[prop].extend(float(v) for v in r[j + 1:j + 1 + c])
                j += 1 + c
        if j != len(r):
            raise ValueError
    return {p: (np.array(lists[p]), np.array(columns[p])) if p in lists else np.array(columns[p]) for p in columns}


def _ply_binary(body: bytes, elements, order: str, path: Path) -> dict:
    """Each element's properties from PLY's binary body, as :func:`_ply_ascii`. An element with a
    list is read in one go when every instance's lists are as long as the first one's."""
    out, pos = {}, 0
    for name, count, props in elements:
        if count == 0:
            out[name] = {p[0]: (np.zeros(0), np.zeros(0)) if p[2] else np.zeros(0) for p in props}
            continue
        # lengths of the first instance's lists, read as they come
        fields, at = [], pos
        for j, (prop, dt, list_type) in enumerate(props):
            if list_type is None:
                fields.append((f"p{j}", order + dt))
                at += np.dtype(dt).itemsize
            else:
                if at + np.dtype(list_type).itemsize > len(body):
                    raise _mesh_error(path, f"the file ends inside its {name!r} elements (truncated)")
                c = int(np.frombuffer(body, order + list_type, 1, at)[0])
                if not 0 <= c <= len(body):
                    raise _mesh_error(path, f"a list of its {name!r} elements has {c} entries")
                fields += [(f"n{j}", order + list_type), (f"p{j}", order + dt, (c,))]
                at += np.dtype(list_type).itemsize + c * np.dtype(dt).itemsize
        fixed = np.dtype(fields)
        if pos + count * fixed.itemsize <= len(body):
            table = np.frombuffer(body, fixed, count, pos)
            if all(np.all(table[f"n{j}"] == table[f"n{j}"][0]) for j, p in enumerate(props) if p[2]):
                out[name] = {p[0]: (table[f"n{j}"], table[f"p{j}"].ravel()) if p[2] else table[f"p{j}"]
                             for j, p in enumerate(props)}
                pos += count * fixed.itemsize
                continue
        if all(p[2] is None for p in props):
            raise _mesh_error(path, f"the file ends inside its {name!r} elements (truncated)")
        out[name], pos = _ply_binary_rows(body, pos, count, props, order, name, path)
    return out


def _ply_binary_rows(body: bytes, pos: int, count: int, props, order: str, name: str, path: Path):
    columns = {p[0]: [] for p in props}
    lists = {p[0]: [] for p in props if p[2] is not None}
    for _ in range(count):
        for prop, dt, list_type in props:
            n = 1
            if list_type is not None:
                size = np.dtype(list_type).itemsize
                if pos + size > len(body):
                    raise _mesh_error(path, f"the file ends inside its {name!r} elements (truncated)")
                n = int(np.frombuffer(body, order + list_type, 1, pos)[0])
                if not 0 <= n <= len(body):
                    raise _mesh_error(path, f"a list of its {name!r} elements has {n} entries")
                lists[prop].append(n)
                pos += size
            size = n * np.dtype(dt).itemsize
            if pos + size > len(body):
                raise _mesh_error(path, f"the file ends inside its {name!r} elements (truncated)")
            columns[prop].append(np.frombuffer(body, order + dt, n, pos))
            pos += size
    return {p: (np.array(lists[p]), np.concatenate(columns[p])) if p in lists else np.concatenate(columns[p])
            for p in columns}, pos


def _read_obj(data: bytes, path: Path):
    """Wavefront OBJ: ``v x y z [r g b]`` and ``f i[/t[/n]] ...`` lines (indices from 1, or
    negative: counted back from the latest vertex); every other line is ignored."""
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError:
        raise _mesh_error(path, "not text (an OBJ file is)") from None
    vertices, colours, counts, flat = [], [], [], []
    for n, line in enumerate(text.splitlines(), start=1):
        t = line.split()
        if not t or t[0] not in ("v", "f"):
            continue
        try:
            if t[0] == "v":
                if len(t) not in (4, 5, 7):
                    raise ValueError
                vertices.append([float(x) for x in t[1:4]])
                colours.append([float(x) for x in t[4:7]] if len(t) == 7 else None)
            else:
                idx = [int(x.split("/")[0]) for x in t[1:]]
                if 0 in idx:
                    raise ValueError
                counts.append(len(idx))
                flat += [i - 1 if i > 0 else len(vertices) + i for i in idx]
        except ValueError:
            raise _mesh_error(path, f"line {n} ({line[:40]!r}) is not a vertex (v x y z) or a face (f i j k) of "
                                    "whole indices from 1") from None
        if len(vertices) > MAX_MESH_ELEMENTS or len(counts) > MAX_MESH_ELEMENTS:
            raise _mesh_error(path, f"it holds more than {MAX_MESH_ELEMENTS} vertices or faces")
    v = np.array(vertices, np.float64).reshape(-1, 3)
    c = np.clip(np.nan_to_num(np.array(colours, np.float64)), 0, 1) if colours and None not in colours else None
    return v, _fans(counts, np.array(flat, np.int64), path), c


MAX_ARRAY_BYTES = 1 << 32
"""Largest array read from a user's ``.npz`` file (4 GiB), checked from its header before it is
read."""


def read_arrays(path: str | Path, required: tuple[str, ...], optional: tuple[str, ...] = ()) -> dict:
    """Named arrays of a NumPy ``.npz`` file, read without pickles; one error if it is not one.

    Each array's header is read first: object arrays (pickles) and arrays over
    :data:`MAX_ARRAY_BYTES` are refused before their data is read.

    Parameters
    ----------
    path : str or pathlib.Path
        The ``.npz`` file (``numpy.savez`` or ``numpy.savez_compressed``).
    required : tuple of str
        The arrays it must hold.
    optional : tuple of str
        Arrays read where present.

    Returns
    -------
    dict of str to numpy.ndarray
        The arrays found, by name; other arrays in the file are not read.

    Raises
    ------
    VrechoError
        Naming the file and array, if the file cannot be read, is not an ``.npz`` (a zip of
        ``.npy`` files), lacks a required array, or holds one that is an object array, is
        larger than :data:`MAX_ARRAY_BYTES`, or is truncated or damaged.
    """
    path = Path(path)
    fmt = np.lib.format
    try:
        with open(path, "rb") as f:
            if f.read(4) != b"PK\x03\x04":
                raise VrechoError(f"{path}: not an .npz file (numpy.savez's zip of arrays)")
        with zipfile.ZipFile(path) as z:
            names = set(z.namelist())
            missing = [k for k in required if k + ".npy" not in names]
            if missing:
                raise VrechoError(f"{path}: lacks {missing}")
            out = {}
            for key in [k for k in required + optional if k + ".npy" in names]:
                with z.open(key + ".npy") as member:
                    version = fmt.read_magic(member)
                    if version not in ((1, 0), (2, 0)):
                        raise ValueError(f"npy format version {version}")
                    read_header = fmt.read_array_header_1_0 if version == (1, 0) else fmt.read_array_header_2_0
                    shape, _, dtype = read_header(member)
                    if dtype.hasobject:
                        raise VrechoError(f"{path}: {key} holds Python objects (a pickle); expected numbers")
                    if dtype.itemsize * float(np.prod(shape)) > MAX_ARRAY_BYTES:
                        raise VrechoError(f"{path}: {key} is {shape}, over {MAX_ARRAY_BYTES >> 30} GiB")
                with z.open(key + ".npy") as member:
                    out[key] = fmt.read_array(member, allow_pickle=False)
    except VrechoError:
        raise
    except OSError as e:  # zipfile.BadZipFile is not one
        raise VrechoError(f"{path}: cannot read it ({e.strerror or e})") from None
    except (ValueError, EOFError, zipfile.BadZipFile, zlib.error, NotImplementedError, RuntimeError) as e:
        raise VrechoError(f"{path}: truncated or damaged ({type(e).__name__}: {str(e)[:80]}); expected numpy.savez's "
                          ".npz") from None
    return out
