"""OpenUSD stages of a repaired room: its mesh, its glass, mirrors and openings with vrecho's
labels, and its sound sources as spatial audio.

Conventions of the written stage: metres (``metersPerUnit`` 1), Y up (vrecho's world is Z up:
a point (x, y, z) is written as (x, z, -y)), default prim ``/World``::

    /World                      Xform
        Looks/Wall|Glass|Mirror Material (UsdPreviewSurface; Wall reads the scan's colours)
        Room                    Mesh: the scan, normals and displayColor per vertex
        Surfaces/<name>         Mesh per discontinuity, vrecho:state|material|depth_m|confidence
                                (an opening is a guide: labelled, never rendered)
        Sources/<name>          Xform at the source, vrecho:confidence|uncertainty_m
            Audio               UsdMedia.SpatialAudio, filePath ./<stem>_audio/<name>.wav

Writes are atomic: everything is built and validated in a temporary folder beside the target
and moved into place only when OpenUSD's validators find no error.
"""

from __future__ import annotations

import os
import re
import shutil
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import soundfile as sf

from vrecho.errors import VrechoError
from vrecho.reconstruct import SURFACE_COLOURS

SUFFIXES = (".usda", ".usdc", ".usd", ".usdz")
STATES = ("open", "closed", "unknown")
MATERIALS = ("glass", "mirror", "wall")
TIME_CODES_PER_SECOND = 24.0


@dataclass
class LabeledSurface:
    """A discontinuity of the scan as vrecho decided it.

    Parameters
    ----------
    name : str
        Its name; made a valid, unique prim name for ``/World/Surfaces/<name>``.
    polygon : numpy.ndarray [shape=(K, 3)]
        A planar polygon in vrecho's world frame (metres, Z up), K >= 3, wound
        counter-clockwise seen from the room.
    state : str
        "open", "closed" or "unknown" (a hole no listening frame faced: left as the scan had
        it).
    material : str or None
        "glass", "mirror" or "wall" when closed (None when open).
    depth_m : float or None
        The plane's distance in metres the echoes gave (None if unknown).
    confidence : float
        In [0, 1].
    """

    name: str
    polygon: np.ndarray
    state: str
    material: str | None
    depth_m: float | None
    confidence: float


@dataclass
class Problem:
    """One finding of :func:`validate`.

    Parameters
    ----------
    severity : str
        "error", "warning" or "info".
    validator : str
        The name of the validator that found it (vrecho's own: ``vrecho:AudioResolves``).
    message : str
        What it found.
    sites : list of str
        The paths of the prims concerned (may be empty).
    """

    severity: str
    validator: str
    message: str
    sites: list[str]

    def __str__(self) -> str:
        where = f" at {', '.join(self.sites)}" if self.sites else ""
        return f"{self.severity}: {self.message} [{self.validator}]{where}"


def y_up(points: np.ndarray) -> np.ndarray:
    """vrecho's Z-up world points in the stage's Y-up frame: (x, y, z) -> (x, z, -y).

    Parameters
    ----------
    points : numpy.ndarray [shape=(..., 3)]
        Points (N, 3), or one (3,), in metres.

    Returns
    -------
    numpy.ndarray [shape=(..., 3), dtype=float64]
        The same points in the stage's frame (never -0).

    Examples
    --------
    >>> import numpy as np
    >>> from usd_export import y_up
    >>> y_up(np.array([[1.0, 2.0, 3.0]]))
    array([[ 1.,  3., -2.]])
    """
    p = np.asarray(points, float)
    return np.stack([p[..., 0], p[..., 2], 0.0 - p[..., 1]], axis=-1) + 0.0  # no -0 in the file


# -- Input checks ----------------------------------------------------------------------------------

def _mesh_arrays(mesh) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    if isinstance(mesh, (tuple, list)):
        if len(mesh) not in (2, 3):
            raise VrechoError("mesh: expected an open3d TriangleMesh or (vertices, faces[, colours])")
        vertices, faces = mesh[0], mesh[1]
        colours = mesh[2] if len(mesh) == 3 else None
    elif hasattr(mesh, "vertices") and hasattr(mesh, "triangles"):
        vertices, faces = np.asarray(mesh.vertices), np.asarray(mesh.triangles)
        colours = np.asarray(mesh.vertex_colors) if mesh.has_vertex_colors() else None
    else:
        raise VrechoError(f"mesh: expected an open3d TriangleMesh or (vertices, faces[, colours]), got {type(mesh).__name__}")
    v = np.asarray(vertices, float)
    f = np.asarray(faces)
    if v.ndim != 2 or v.shape[1] != 3 or not len(v):
        raise VrechoError(f"mesh: vertices must be (N, 3) with N > 0, got shape {v.shape}")
    bad = ~np.all(np.isfinite(v), axis=1)
    if bad.any():
        raise VrechoError(f"mesh: {int(bad.sum())} vertices are not finite (first: index {int(np.argmax(bad))})")
    if f.ndim != 2 or f.shape[1] != 3 or not np.issubdtype(f.dtype, np.integer):
        raise VrechoError(f"mesh: faces must be integer (F, 3), got shape {f.shape} of {f.dtype}")
    if len(f) and (f.min() < 0 or f.max() >= len(v)):
        raise VrechoError(f"mesh: face indices must lie in 0..{len(v) - 1}, got {int(f.min())}..{int(f.max())}")
    if colours is not None:
        c = np.asarray(colours, float)
        if c.shape != v.shape or not np.all(np.isfinite(c)):
            raise VrechoError(f"mesh: colours must be finite (N, 3) like the vertices, got shape {c.shape}")
        colours = np.clip(c, 0.0, 1.0)
    return v, f.astype(np.int64), colours


def _check_surface(s: LabeledSurface, i: int) -> None:
    where = f"surfaces[{i}] ({getattr(s, 'name', '?')})"
    p = np.asarray(s.polygon, float)
    if p.ndim != 2 or p.shape[1] != 3 or len(p) < 3 or not np.all(np.isfinite(p)):
        raise VrechoError(f"{where}: polygon must be finite (K >= 3, 3), got shape {p.shape}")
    if s.state not in STATES:
        raise VrechoError(f"{where}: state must be one of {STATES}, got {s.state!r}")
    if s.state == "closed" and s.material not in MATERIALS:
        raise VrechoError(f"{where}: a closed surface's material must be one of {MATERIALS}, got {s.material!r}")
    if not 0.0 <= float(s.confidence) <= 1.0:
        raise VrechoError(f"{where}: confidence must lie in [0, 1], got {s.confidence}")


def check_sources(sources) -> list[tuple[np.ndarray, int]]:
    """Each source's position checked and its signal read, as :func:`write_scene` will: a caller
    with minutes of work before the write calls it first.

    Parameters
    ----------
    sources : list of :class:`localization.PlacedSource`

    Returns
    -------
    list of (numpy.ndarray, int)
        Each source's signal (mono, float) and rate.

    Raises
    ------
    VrechoError
        For a position that is not 3 finite numbers, a WAV that is missing or not audio, or a
        signal that is not finite, empty or at a rate outside 8000 to 192000 Hz.
    """
    return [_source_audio(s, i) for i, s in enumerate(sources)]


def _source_audio(s, i: int) -> tuple[np.ndarray, int]:
    """A source's signal (float, at most 1 channel) and rate, read from its WAV if it names one."""
    where = f"sources[{i}] ({getattr(s, 'name', '?')})"
    pos = np.asarray(s.position, float)
    if pos.shape != (3,) or not np.all(np.isfinite(pos)):
        raise VrechoError(f"{where}: position must be 3 finite numbers, got {s.position!r}")
    if isinstance(s.signal, (str, Path)):
        path = Path(s.signal)
        if not path.is_file():
            raise VrechoError(f"{where}: WAV file {path} does not exist")
        try:
            x, fs = sf.read(path, dtype="float64", always_2d=True)
        except (RuntimeError, sf.LibsndfileError) as e:
            raise VrechoError(f"{where}: cannot read {path} as audio ({e})") from None
        x = x.mean(axis=1)
    else:
        x, fs = np.asarray(s.signal, float), s.fs
    if x.ndim != 1 or not len(x) or not np.all(np.isfinite(x)):
        raise VrechoError(f"{where}: signal must be a non-empty finite 1-D array, got shape {x.shape}")
    if not (isinstance(fs, (int, np.integer)) and 8000 <= fs <= 192000):
        raise VrechoError(f"{where}: fs must be an integer sample rate from 8000 to 192000 Hz, got {fs!r}")
    if not 0.0 <= float(s.confidence) <= 1.0:
        raise VrechoError(f"{where}: confidence must lie in [0, 1], got {s.confidence}")
    return x, int(fs)


def _prim_names(names: list[str], fallback: str) -> list[str]:
    """Valid, unique prim names (also used for WAV file names)."""
    out = []
    for n in names:
        n = re.sub(r"[^A-Za-z0-9_]", "_", str(n)) or fallback
        if n[0].isdigit():
            n = f"{fallback}_{n}"
        base, k = n, 1
        while n in out:
            k += 1
            n = f"{base}_{k}"
        out.append(n)
    return out


# -- Writing ---------------------------------------------------------------------------------------

def vertex_normals(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Area-weighted unit vertex normals; a vertex in no face gets +Z.

    Parameters
    ----------
    vertices : numpy.ndarray [shape=(N, 3), dtype=float64]
        The mesh's vertices in metres.
    faces : numpy.ndarray [shape=(F, 3), dtype=int]
        Its triangles, as vertex indices (each face's normal by the right-hand rule).

    Returns
    -------
    numpy.ndarray [shape=(N, 3), dtype=float64]
        Unit normals, in the vertices' frame.
    """
    n = np.zeros_like(vertices)
    if len(faces):
        t = vertices[faces]
        fn = np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0])
        for k in range(3):
            np.add.at(n, faces[:, k], fn)
    length = np.linalg.norm(n, axis=1, keepdims=True)
    return np.where(length > 0, n / np.maximum(length, 1e-30), [0.0, 0.0, 1.0])


def _materials(stage, root: str) -> dict:
    from pxr import Gf, Sdf, UsdShade  # OpenUSD: only when a stage is written or read

    out = {}
    specs = {  # NOTES.md: glass and mirror as UsdPreviewSurface describes them
        "Glass": {"diffuseColor": Gf.Vec3f(0.9, 0.95, 1.0), "opacity": 0.1, "ior": 1.5, "roughness": 0.02,
                  "metallic": 0.0, "opacityThreshold": 0.0},
        "Mirror": {"diffuseColor": Gf.Vec3f(0.95, 0.95, 0.95), "metallic": 1.0, "roughness": 0.02},
        "Wall": {"roughness": 0.8, "metallic": 0.0},
    }
    types = {"diffuseColor": Sdf.ValueTypeNames.Color3f}
    for name, inputs in specs.items():
        mat = UsdShade.Material.Define(stage, f"{root}/Looks/{name}")
        shader = UsdShade.Shader.Define(stage, f"{root}/Looks/{name}/Surface")
        shader.CreateIdAttr("UsdPreviewSurface")
        for key, value in inputs.items():
            shader.CreateInput(key, types.get(key, Sdf.ValueTypeNames.Float)).Set(value)
        if name == "Wall":  # the scan's own colours
            reader = UsdShade.Shader.Define(stage, f"{root}/Looks/{name}/DisplayColor")
            reader.CreateIdAttr("UsdPrimvarReader_float3")
            reader.CreateInput("varname", Sdf.ValueTypeNames.String).Set("displayColor")
            reader.CreateInput("fallback", Sdf.ValueTypeNames.Float3).Set(Gf.Vec3f(0.6, 0.6, 0.6))
            out_rgb = reader.CreateOutput("result", Sdf.ValueTypeNames.Float3)
            shader.CreateInput("diffuseColor", Sdf.ValueTypeNames.Color3f).ConnectToSource(out_rgb)
        mat.CreateSurfaceOutput().ConnectToSource(shader.ConnectableAPI(), "surface")
        out[name.lower()] = mat
    return out


def _bind(prim, material) -> None:
    from pxr import UsdShade  # OpenUSD: only when a stage is written or read

    UsdShade.MaterialBindingAPI.Apply(prim).Bind(material)


def _mesh(stage, path: str, vertices, faces_counts, faces_indices, normals, normal_interp, colours, colour_interp):
    from pxr import UsdGeom, Vt  # OpenUSD: only when a stage is written or read

    mesh = UsdGeom.Mesh.Define(stage, path)
    pts = y_up(vertices).astype(np.float32)
    mesh.CreatePointsAttr(Vt.Vec3fArray.FromNumpy(pts))
    mesh.CreateFaceVertexCountsAttr(Vt.IntArray.FromNumpy(np.asarray(faces_counts, np.int32)))
    mesh.CreateFaceVertexIndicesAttr(Vt.IntArray.FromNumpy(np.asarray(faces_indices, np.int32).ravel()))
    mesh.CreateNormalsAttr(Vt.Vec3fArray.FromNumpy(y_up(normals).astype(np.float32)))
    mesh.SetNormalsInterpolation(normal_interp)
    mesh.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)
    mesh.CreateOrientationAttr(UsdGeom.Tokens.rightHanded)
    mesh.CreateExtentAttr(Vt.Vec3fArray.FromNumpy(np.stack([pts.min(axis=0), pts.max(axis=0)])))
    if colours is not None:
        primvar = mesh.CreateDisplayColorPrimvar(colour_interp)
        primvar.Set(Vt.Vec3fArray.FromNumpy(np.asarray(colours, np.float32).reshape(-1, 3)))
    return mesh


def _write_stage(stage_path: Path, audio_dir: Path, vertices, faces, colours, surfaces, sources, audio) -> None:
    from pxr import Gf, Sdf, Usd, UsdGeom, UsdMedia  # OpenUSD: only when a stage is written or read

    stage = Usd.Stage.CreateNew(str(stage_path))
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.y)
    UsdGeom.SetStageMetersPerUnit(stage, 1.0)
    world = UsdGeom.Xform.Define(stage, "/World")
    stage.SetDefaultPrim(world.GetPrim())
    stage.SetMetadata("comment", COMMENT)
    UsdGeom.Scope.Define(stage, "/World/Looks")
    looks = _materials(stage, "/World")

    room = _mesh(stage, "/World/Room", vertices, np.full(len(faces), 3), faces, vertex_normals(vertices, faces),
                 UsdGeom.Tokens.vertex, colours, UsdGeom.Tokens.vertex)
    _bind(room.GetPrim(), looks["wall"])

    UsdGeom.Scope.Define(stage, "/World/Surfaces")
    for s, name in zip(surfaces, _prim_names([s.name for s in surfaces], "surface")):
        p = np.asarray(s.polygon, float)
        n = np.cross(p[1] - p[0], p[2] - p[0])
        n = n / max(np.linalg.norm(n), 1e-12)
        colour = SURFACE_COLOURS.get(s.material, SURFACE_COLOURS["wall"])  # as the repaired mesh shows them
        mesh = _mesh(stage, f"/World/Surfaces/{name}", p, [len(p)], np.arange(len(p)), n[None], UsdGeom.Tokens.uniform,
                     colour, UsdGeom.Tokens.constant)
        prim = mesh.GetPrim()
        prim.CreateAttribute("vrecho:state", Sdf.ValueTypeNames.Token, custom=True).Set(s.state)
        prim.CreateAttribute("vrecho:material", Sdf.ValueTypeNames.Token, custom=True).Set(s.material or "none")
        prim.CreateAttribute("vrecho:depth_m", Sdf.ValueTypeNames.Double, custom=True).Set(
            float("nan") if s.depth_m is None else float(s.depth_m))
        prim.CreateAttribute("vrecho:confidence", Sdf.ValueTypeNames.Double, custom=True).Set(float(s.confidence))
        if s.state != "closed":  # nothing is there (or nothing known): kept for its labels, never rendered
            mesh.CreatePurposeAttr(UsdGeom.Tokens.guide)
        else:
            _bind(prim, looks[s.material])

    UsdGeom.Scope.Define(stage, "/World/Sources")
    names = _prim_names([s.name for s in sources], "source")
    peaks = [float(np.max(np.abs(x))) for x, _ in audio]
    loudest = max(peaks, default=0.0)
    longest = 0.0
    for s, name, (x, fs), peak in zip(sources, names, audio, peaks):
        xf = UsdGeom.Xform.Define(stage, f"/World/Sources/{name}")
        xf.AddTranslateOp().Set(Gf.Vec3d(*y_up(np.asarray(s.position, float)).tolist()))
        prim = xf.GetPrim()
        prim.CreateAttribute("vrecho:confidence", Sdf.ValueTypeNames.Double, custom=True).Set(float(s.confidence))
        if getattr(s, "uncertainty_m", None) is not None:
            prim.CreateAttribute("vrecho:uncertainty_m", Sdf.ValueTypeNames.Double, custom=True).Set(float(s.uncertainty_m))
        # Each WAV is normalised (16-bit keeps its detail); gain restores the sources' relative levels.
        wav = audio_dir / f"{name}.wav"
        sf.write(wav, x / peak * 0.9 if peak > 0 else x, fs, subtype="PCM_16")
        longest = max(longest, len(x) / fs)
        sa = UsdMedia.SpatialAudio.Define(stage, f"/World/Sources/{name}/Audio")
        sa.CreateFilePathAttr(Sdf.AssetPath(f"./{audio_dir.name}/{wav.name}"))
        sa.CreateAuralModeAttr(UsdMedia.Tokens.spatial)
        sa.CreatePlaybackModeAttr(UsdMedia.Tokens.loopFromStage)
        sa.CreateGainAttr(peak / loudest if loudest > 0 else 1.0)
    if sources:  # loopFromStage plays over the stage's time range: the longest source
        stage.SetTimeCodesPerSecond(TIME_CODES_PER_SECOND)
        stage.SetStartTimeCode(0.0)
        stage.SetEndTimeCode(float(np.ceil(longest * TIME_CODES_PER_SECOND)))
    stage.GetRootLayer().Save()


COMMENT = "written by vrecho's usd_export: a repaired scan with spatial audio"
"""The stage's ``comment`` metadata: how :func:`is_vrecho_stage` knows a stage this package wrote."""


def is_vrecho_stage(path: str | Path) -> bool:
    """Whether ``path`` is a stage (or package) :func:`write_scene` wrote.

    Looks for :data:`COMMENT` in the file's bytes: a ``.usda`` holds it as text, a ``.usdc``
    in its string table, a ``.usdz`` in its uncompressed layer.

    Parameters
    ----------
    path : str or pathlib.Path

    Returns
    -------
    bool
        False for a missing or unreadable file, or anyone else's.
    """
    try:
        with open(path, "rb") as f:
            return COMMENT.encode() in f.read()
    except OSError:
        return False


def check_target(path: str | Path) -> Path:
    """The stage's path, checked before any work: a known suffix, in an existing folder.

    Parameters
    ----------
    path : str or pathlib.Path
        The stage to write.

    Returns
    -------
    pathlib.Path

    Raises
    ------
    VrechoError
        For a suffix not in :data:`SUFFIXES` (``.usda``, ``.usdc``, ``.usd``, ``.usdz``), or a
        folder that does not exist.
    """
    path = Path(path)
    if path.suffix.lower() not in SUFFIXES:
        raise VrechoError(f"export: {path} must end in one of {', '.join(SUFFIXES)}")
    if not path.parent.is_dir():
        raise VrechoError(f"export: folder {path.parent} does not exist")
    return path


def write_scene(path: str | Path, mesh, surfaces=(), sources=(), *, check: bool = True) -> Path:
    """Write a repaired room as an OpenUSD stage (``.usda``, ``.usdc``, ``.usd``) or a ``.usdz``
    package.

    Parameters
    ----------
    path : str or Path
        The stage to write. For a layer, each source's WAV goes to ``<stem>_audio/`` beside it;
        a ``.usdz`` holds its WAVs inside.
    mesh : open3d.geometry.TriangleMesh or (vertices (N, 3), faces (F, 3)[, colours (N, 3)])
        The room, in vrecho's world frame (metres, Z up): finite float vertices, N > 0,
        integer faces indexing them, colours in [0, 1] (clipped there).
    surfaces : list of :class:`LabeledSurface`
        The discontinuities and their labels (:func:`usd_export.from_reconstruction` makes them).
    sources : list of :class:`localization.PlacedSource`
        Sound sources, each written as a WAV and a ``UsdMedia.SpatialAudio`` prim. A signal
        given as an array is taken at the source's ``fs`` (8000 to 192000 Hz); a WAV file at
        its own rate, its channels averaged. Each WAV is normalised to a 0.9 peak (16-bit), and
        the prim's gain restores the sources' relative levels.
    check : bool
        Run :func:`validate` before the stage is moved into place, and refuse (raise, writing
        nothing) while it reports an error (default True).

    Returns
    -------
    Path
        The stage written.

    Raises
    ------
    VrechoError
        On bad input (non-finite vertices, faces out of range, a missing WAV, an unwritable
        path, ...) or a stage with validation errors. Nothing is written then, and nothing that
        was there is touched.

    Examples
    --------
    >>> import tempfile
    >>> from pathlib import Path
    >>> import numpy as np
    >>> from usd_export import validate, write_scene
    >>> vertices = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0]])
    >>> faces = np.array([[0, 1, 2]])
    >>> tmp = tempfile.TemporaryDirectory()
    >>> stage = write_scene(Path(tmp.name) / "room.usda", (vertices, faces))
    >>> stage.name, validate(stage)
    ('room.usda', [])
    >>> tmp.cleanup()
    """
    path = check_target(path)
    vertices, faces, colours = _mesh_arrays(mesh)
    surfaces, sources = list(surfaces), list(sources)
    for i, s in enumerate(surfaces):
        _check_surface(s, i)
    audio = check_sources(sources)
    parent = path.parent
    try:
        tmp = Path(tempfile.mkdtemp(dir=parent, prefix=f".{path.name}."))
    except OSError as e:
        raise VrechoError(f"export: cannot write in {parent} ({e.strerror or e})") from None
    try:
        package = path.suffix.lower() == ".usdz"
        stage_path = tmp / (f"{path.stem}.usdc" if package else path.name)
        audio_dir = tmp / f"{path.stem}_audio"
        if sources:
            audio_dir.mkdir()
        _write_stage(stage_path, audio_dir, vertices, faces, colours, surfaces, sources, audio)
        if package:
            from pxr import Sdf, UsdUtils  # OpenUSD: only when a stage is written or read

            built = tmp / path.name
            if not UsdUtils.CreateNewUsdzPackage(Sdf.AssetPath(str(stage_path)), str(built)):
                raise VrechoError(f"export: OpenUSD could not package {path.name}")
            stage_path = built
        if check:
            errors = [p for p in validate(stage_path) if p.severity == "error"]
            if errors:
                raise VrechoError(f"export: {len(errors)} validation error(s), nothing written; first: {errors[0]}")
        mask = os.umask(0)
        os.umask(mask)
        os.chmod(stage_path, 0o666 & ~mask)
        if sources and not package:  # the WAVs first, the stage last: it is what readers open
            final_audio = parent / audio_dir.name
            old = tmp / "previous_audio"
            if final_audio.exists():
                os.replace(final_audio, old)
            os.replace(audio_dir, final_audio)
        os.replace(stage_path, path)
    except OSError as e:
        raise VrechoError(f"export: writing {path} failed ({e.strerror or e}); nothing written") from None
    except Exception as e:  # OpenUSD's own Tf.ErrorException: how its writer reports a full disk
        from pxr import Tf  # OpenUSD: already loaded by the write that failed

        if not isinstance(e, Tf.ErrorException):
            raise
        found = re.search(r"writing file: ([^'\n]+)", str(e))
        why = found.group(1).strip() if found else "OpenUSD could not write it"
        raise VrechoError(f"export: writing {path} failed ({why}); nothing written") from None
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return path


# -- Checking --------------------------------------------------------------------------------------

def validate(path: str | Path) -> list[Problem]:
    """OpenUSD's own validators over the stage at ``path``, and vrecho's check of its audio.

    The validators are every one UsdValidation registers (stage metadata, material bindings,
    shader compliance, usdz packaging, ...); vrecho's check is that every audio file a
    ``SpatialAudio`` prim names resolves.

    Parameters
    ----------
    path : str or pathlib.Path
        The stage (a layer or a ``.usdz`` package).

    Returns
    -------
    list of Problem
        The problems (empty when the stage is clean).

    Raises
    ------
    VrechoError
        When ``path`` does not exist or OpenUSD cannot open it.
    """
    from pxr import Usd, UsdMedia, UsdValidation  # OpenUSD: only when a stage is written or read

    path = Path(path)
    if not path.is_file():
        raise VrechoError(f"validate: {path} does not exist")
    try:
        stage = Usd.Stage.Open(str(path))
    except Exception as e:  # pxr raises Tf.ErrorException
        raise VrechoError(f"validate: OpenUSD cannot open {path} ({str(e).strip().splitlines()[-1]})") from None
    validators = UsdValidation.ValidationRegistry().GetOrLoadAllValidators()
    severity = {UsdValidation.ValidationErrorType.Error: "error", UsdValidation.ValidationErrorType.Warn: "warning",
                UsdValidation.ValidationErrorType.Info: "info"}
    problems = []
    for e in UsdValidation.ValidationContext(validators).Validate(stage):
        if e.HasNoError():
            continue
        sites = [str(s.GetPrim().GetPath()) for s in e.GetSites() if s.IsPrim()]
        name = e.GetValidator().GetMetadata().name if e.GetValidator() else e.GetName()
        problems.append(Problem(severity.get(e.GetType(), "error"), str(name), e.GetMessage(), sites))
    for prim in stage.Traverse():
        if prim.IsA(UsdMedia.SpatialAudio):
            asset = UsdMedia.SpatialAudio(prim).GetFilePathAttr().Get()
            if asset is None or not asset.resolvedPath:
                problems.append(Problem("error", "vrecho:AudioResolves",
                                        f"audio file {asset.path if asset else None!r} does not resolve",
                                        [str(prim.GetPath())]))
    return problems
