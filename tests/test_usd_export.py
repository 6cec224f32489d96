"""usd_export: stages read back with pxr, validated by OpenUSD's own validators, written atomically."""

import io
import os
from pathlib import Path

import numpy as np
import pytest
import soundfile as sf
from pxr import Sdf, Usd, UsdGeom, UsdMedia, UsdShade

import usd_export
from localization import PlacedSource
from vrecho.errors import VrechoError


def _room():
    """A 4 x 3 x 2.5 m box (12 triangles, Z up), coloured."""
    v = np.array([[x, y, z] for z in (0.0, 2.5) for y in (0.0, 3.0) for x in (0.0, 4.0)])
    q = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    f = np.array([t for a, b, c, d in q for t in ((a, b, c), (a, c, d))])
    return v, f, np.linspace(0.2, 0.8, 24).reshape(8, 3)


SURFACES = [
    usd_export.LabeledSurface("window", np.array([[1.0, 0, 1], [2, 0, 1], [2, 0, 2], [1, 0, 2]]), "closed", "glass", 1.6, 0.93),
    usd_export.LabeledSurface("mirror", np.array([[4.0, 1, 0.5], [4, 2, 0.5], [4, 2, 1.8], [4, 1, 1.8]]), "closed", "mirror",
                              2.1, 0.88),
    usd_export.LabeledSurface("door", np.array([[0.0, 2, 0], [0, 1, 0], [0, 1, 2], [0, 2, 2]]), "open", None, None, 0.7),
]


def _sources(tmp_path):
    wav = tmp_path / "given.wav"
    sf.write(wav, 0.2 * np.sin(np.arange(8000) / 3.0), 16000)
    return [PlacedSource(np.array([1.0, 2.0, 1.2]), 0.5 * np.sin(np.arange(22050) / 7.0), 22050, 0.8, "tv", 0.12),
            PlacedSource(np.array([3.0, 0.5, 0.4]), wav, 0, 0.6, "radio")]


@pytest.mark.parametrize("suffix", [".usda", ".usdz"])
def test_stage_reads_back(tmp_path, suffix):
    v, f, c = _room()
    sources = _sources(tmp_path)
    out = tmp_path / "out"
    out.mkdir()
    path = usd_export.write_scene(out / f"room{suffix}", (v, f, c), SURFACES, sources)
    assert [p for p in usd_export.validate(path) if p.severity == "error"] == []

    stage = Usd.Stage.Open(str(path))
    assert UsdGeom.GetStageUpAxis(stage) == UsdGeom.Tokens.y
    assert UsdGeom.GetStageMetersPerUnit(stage) == 1.0
    assert stage.GetDefaultPrim().GetPath() == Sdf.Path("/World")
    to_y = lambda p: np.stack([p[:, 0], p[:, 2], -p[:, 1]], axis=1)

    room = UsdGeom.Mesh(stage.GetPrimAtPath("/World/Room"))
    assert np.abs(np.array(room.GetPointsAttr().Get()) - to_y(v)).max() < 1e-3
    assert np.array_equal(np.array(room.GetFaceVertexIndicesAttr().Get()).reshape(-1, 3), f)
    normals = np.array(room.GetNormalsAttr().Get())
    assert normals.shape == v.shape and np.allclose(np.linalg.norm(normals, axis=1), 1, atol=1e-5)
    assert np.abs(np.array(room.GetDisplayColorPrimvar().Get()) - c).max() < 1e-6
    bound = lambda prim: UsdShade.MaterialBindingAPI(prim).ComputeBoundMaterial()[0]
    assert bound(room.GetPrim()).GetPath() == Sdf.Path("/World/Looks/Wall")

    for s in SURFACES:
        prim = stage.GetPrimAtPath(f"/World/Surfaces/{s.name}")
        assert np.abs(np.array(UsdGeom.Mesh(prim).GetPointsAttr().Get()) - to_y(s.polygon)).max() < 1e-3
        assert prim.GetAttribute("vrecho:state").Get() == s.state
        assert prim.GetAttribute("vrecho:confidence").Get() == pytest.approx(s.confidence)
        if s.state == "closed":
            assert prim.GetAttribute("vrecho:material").Get() == s.material
            assert prim.GetAttribute("vrecho:depth_m").Get() == pytest.approx(s.depth_m)
            assert bound(prim).GetPath() == Sdf.Path(f"/World/Looks/{s.material.capitalize()}")
            assert prim.HasAPI(UsdShade.MaterialBindingAPI)
        else:
            assert UsdGeom.Imageable(prim).GetPurposeAttr().Get() == UsdGeom.Tokens.guide
            assert not bound(prim)
    glass = UsdShade.Shader(stage.GetPrimAtPath("/World/Looks/Glass/Surface"))
    assert glass.GetInput("ior").Get() == pytest.approx(1.5) and glass.GetInput("opacity").Get() < 0.5
    mirror = UsdShade.Shader(stage.GetPrimAtPath("/World/Looks/Mirror/Surface"))
    assert mirror.GetInput("metallic").Get() == 1.0 and mirror.GetInput("roughness").Get() < 0.1

    for s in sources:
        xf = UsdGeom.Xformable(stage.GetPrimAtPath(f"/World/Sources/{s.name}"))
        at = np.array(xf.ComputeLocalToWorldTransform(Usd.TimeCode.Default()).ExtractTranslation())
        assert np.abs(at - to_y(s.position[None])[0]).max() < 1e-3
        audio = UsdMedia.SpatialAudio(stage.GetPrimAtPath(f"/World/Sources/{s.name}/Audio"))
        assert audio.GetAuralModeAttr().Get() == UsdMedia.Tokens.spatial
        assert audio.GetPlaybackModeAttr().Get() == UsdMedia.Tokens.loopFromStage
        asset = audio.GetFilePathAttr().Get()
        assert asset.path.startswith("./") and asset.resolvedPath  # relative, and it resolves
    # The WAV holds the signal (normalised; gain restores the level relative to the loudest).
    tv = UsdMedia.SpatialAudio(stage.GetPrimAtPath("/World/Sources/tv/Audio"))
    if suffix == ".usda":
        x, fs = sf.read(out / "room_audio" / "tv.wav")
    else:
        z = Sdf.ZipFile.Open(str(path))
        assert sorted(z.GetFileNames()) == ["room.usdc", "room_audio/radio.wav", "room_audio/tv.wav"]
        x, fs = sf.read(io.BytesIO(bytes(z.GetFile("room_audio/tv.wav"))))
    assert fs == 22050 and np.corrcoef(x, sources[0].signal)[0, 1] > 0.999
    assert tv.GetGainAttr().Get() == pytest.approx(1.0)
    radio = UsdMedia.SpatialAudio(stage.GetPrimAtPath("/World/Sources/radio/Audio"))
    assert radio.GetGainAttr().Get() == pytest.approx(0.4, abs=1e-3)
    assert sorted(os.listdir(out)) == (["room.usda", "room_audio"] if suffix == ".usda" else ["room.usdz"])


def _bad(kind, tmp_path):
    v, f, c = _room()
    surfaces, sources = SURFACES, _sources(tmp_path)
    path = tmp_path / "out" / "room.usda"
    if kind == "nan vertex":
        v = v.copy()
        v[3, 1] = np.nan
    elif kind == "face out of range":
        f = f.copy()
        f[5, 2] = 8
    elif kind == "missing wav":
        sources = sources[:1] + [PlacedSource(np.zeros(3), tmp_path / "gone.wav", 0)]
    elif kind == "unwritable path":
        path = tmp_path / "out" / "no such folder" / "room.usda"
    elif kind == "bad suffix":
        path = tmp_path / "out" / "room.obj"
    elif kind == "nan source position":
        sources = [PlacedSource(np.array([0.0, np.nan, 1.0]), np.ones(100), 16000)]
    return path, (v, f, c), surfaces, sources


@pytest.mark.parametrize("kind", ["nan vertex", "face out of range", "missing wav", "unwritable path", "bad suffix",
                                  "nan source position"])
def test_bad_input_writes_nothing(tmp_path, kind):
    (tmp_path / "out").mkdir()
    (tmp_path / "out" / "room.usda").write_text("previous")
    path, mesh, surfaces, sources = _bad(kind, tmp_path)
    with pytest.raises(VrechoError) as e:
        usd_export.write_scene(path, mesh, surfaces, sources)
    assert "\n" not in str(e.value)
    assert sorted(os.listdir(tmp_path / "out")) == ["room.usda"]  # no temporary folder, no audio
    assert (tmp_path / "out" / "room.usda").read_text() == "previous"


def test_read_only_folder_is_refused(tmp_path):
    """A folder nothing can be written in (Linux's /proc refuses even root)."""
    if not Path("/proc/self").is_dir():
        pytest.skip("needs Linux's /proc")
    with pytest.raises(VrechoError, match="cannot write"):
        usd_export.write_scene("/proc/room.usda", _room())


def test_validation_errors_refuse_the_stage(tmp_path, monkeypatch):
    """A stage OpenUSD's validators reject is not moved into place; the old one stays."""
    from usd_export import stage as stage_module

    (tmp_path / "room.usda").write_text("previous")
    fake = [usd_export.Problem("error", "usdGeomValidators:StageMetadataChecker", "no upAxis", ["/"])]
    monkeypatch.setattr(stage_module, "validate", lambda path: fake)
    with pytest.raises(VrechoError, match="validation error"):
        usd_export.write_scene(tmp_path / "room.usda", _room(), SURFACES, _sources(tmp_path))
    assert sorted(os.listdir(tmp_path)) == ["given.wav", "room.usda"]
    assert (tmp_path / "room.usda").read_text() == "previous"


def test_validate_finds_what_is_wrong(tmp_path):
    """OpenUSD's validators run for real: a stage with no metadata, an unapplied binding API and
    an audio file that is not there has each flagged."""
    stage = Usd.Stage.CreateNew(str(tmp_path / "bad.usda"))
    mesh = UsdGeom.Mesh.Define(stage, "/World/Mesh")
    material = UsdShade.Material.Define(stage, "/World/Material")
    mesh.GetPrim().CreateRelationship("material:binding").SetTargets([material.GetPath()])
    UsdMedia.SpatialAudio.Define(stage, "/World/Audio").CreateFilePathAttr(Sdf.AssetPath("./nowhere.wav"))
    stage.GetRootLayer().Save()
    found = {p.validator for p in usd_export.validate(tmp_path / "bad.usda") if p.severity == "error"}
    assert {"usdGeomValidators:StageMetadataChecker", "usdShadeValidators:MaterialBindingApiAppliedValidator",
            "vrecho:AudioResolves"} <= found
    with pytest.raises(VrechoError, match="does not exist"):
        usd_export.validate(tmp_path / "none.usda")
    (tmp_path / "garbage.usda").write_text("#usda 1.0\n(\n def oops")
    with pytest.raises(VrechoError, match="cannot open"):
        usd_export.validate(tmp_path / "garbage.usda")


def test_export_command(tmp_path, capsys):
    from vrecho.cli import main

    assert main(["export", "builtin", "--out", str(tmp_path / "room.obj"), "--quiet"]) == 2
    assert "must end in" in capsys.readouterr().err
    assert main(["export", "builtin", "--out", str(tmp_path / "r.usda"), "--sources", "nope.json", "--quiet"]) == 2
    assert "sources" in capsys.readouterr().err
    assert not any(Path(tmp_path).iterdir())


@pytest.mark.slow
def test_export_command_writes_a_clean_package(tmp_path, capsys):
    from conftest import export_small_room

    out = tmp_path / "small.usdz"
    assert export_small_room(tmp_path, out.name, "truth") == 0
    assert "no errors" in capsys.readouterr().out
    assert usd_export.validate(out) == []
    stage = Usd.Stage.Open(str(out))
    states = [p.GetAttribute("vrecho:state").Get() for p in stage.GetPrimAtPath("/World/Surfaces").GetChildren()]
    assert "closed" in states and "open" in states
    (source,) = stage.GetPrimAtPath("/World/Sources").GetChildren()
    at = UsdGeom.Xformable(source).ComputeLocalToWorldTransform(Usd.TimeCode.Default()).ExtractTranslation()
    assert np.allclose(at, [1.5, 1.1, -2.0], atol=1e-3)  # (x, z, -y) of the scene's source
