"""Bad JSON: scene files, ``--sources`` files and the learning code's manifests each get one
:class:`VrechoError` naming the file and the field (with the allowed range), never a traceback,
and quickly (no work on what they describe)."""

import copy
import json
import math
import time
from types import SimpleNamespace

import numpy as np
import pytest
import soundfile as sf
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from usd_export import sources_from_json
from vrecho.errors import VrechoError, read_json
from vrecho.materials import Material
from vrecho.scene import Scene, builtin_scene, load_scene

Material.from_database("brickwork")  # pyroomacoustics' import (1.4 s) here, not in a timed example

BUILTIN = builtin_scene().to_dict()


def fast(n: int):
    """Hypothesis settings: ``n`` examples, each within 1 s (the file runs in well under a minute)."""
    return settings(max_examples=n, deadline=1000,
                    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])


def _write(folder, name, data):
    path = folder / name
    path.write_bytes(data if isinstance(data, bytes) else json.dumps(data, allow_nan=True).encode())
    return path


def _scene_file(tmp_path, mutate):
    d = copy.deepcopy(BUILTIN)
    mutate(d)
    return _write(tmp_path, "scene.json", d)


def _refused(call, match):
    """``call()`` raises one VrechoError matching ``match``, within a second."""
    start = time.perf_counter()
    with pytest.raises(VrechoError, match=match):
        call()
    assert time.perf_counter() - start < 1.0


# -- The tracebacks, one test each --------------------------------------------------------

def test_scene_file_of_non_utf8_bytes(tmp_path):
    path = _write(tmp_path, "scene.json", b'{"name": "caf\xe9"}')
    _refused(lambda: load_scene(path), r"scene file .*scene.json: not UTF-8 text \(byte 13")


def test_deeply_nested_json(tmp_path):
    path = _write(tmp_path, "scene.json", b"[" * 100_000 + b"]" * 100_000)
    _refused(lambda: load_scene(path), "nested deeper than 32 levels")
    nested = 1
    for _ in range(40):
        nested = [nested]
    shallow = _write(tmp_path, "shallow.json", {"room": nested})
    _refused(lambda: load_scene(shallow), "nested deeper than 32 levels")  # under Python's own limit too


def test_huge_integer_json(tmp_path):
    path = _write(tmp_path, "scene.json", b'{"emitter_p": ' + b"9" * 5000 + b"}")
    _refused(lambda: load_scene(path), "an integer of 5000 digits")
    path = _write(tmp_path, "scene.json", b'{"emitter_p": ' + b"9" * 400 + b"}")  # under Python's int limit
    _refused(lambda: load_scene(path), "an integer of 400 digits")


@pytest.mark.parametrize("camera_path, match", [
    ({"positions": "abc", "look_at": [[0, 0, 0]] * 2}, r"camera_path.positions: expected a list"),
    ({"positions": [[1, 1, 1], [1, 2]], "look_at": [[0, 0, 0]] * 2}, r"camera_path.positions\[1\]: expected 3 numbers"),
    ({"positions": [[1, 1, 1], {"x": 1}], "look_at": [[0, 0, 0]] * 2}, r"camera_path.positions\[1\]: expected 3 numbers"),
    ({"positions": [[1, 1, 1], [1, "2", 1]], "look_at": [[0, 0, 0]] * 2},
     r"camera_path.positions\[1\]\[1\]: expected a finite number"),
    ({"positions": [[1, 1, 1], [3, 3, 1]], "look_at": [[3, 3, 1], [1, 1, 1]]}, "within 1 cm of itself at 50.0%"),
    ([1, 2], "camera_path: expected an object"),
])
def test_camera_path_entry_of_the_wrong_type(tmp_path, camera_path, match):
    path = _scene_file(tmp_path, lambda d: d.update(camera_path=camera_path))
    _refused(lambda: load_scene(path), match)


def _wav(folder):
    sf.write(folder / "tv.wav", np.zeros(4000), 16000)


@pytest.mark.parametrize("position, match", [
    ([1, "a", 3], r"sources\[0\].position\[1\]: expected a finite number, got 'a'"),
    ([[1], 2, 3], r"sources\[0\].position\[0\]: expected a finite number"),
    ([1, 2], r"sources\[0\].position: expected 3 numbers"),
    ([1e9, 2, 3], r"sources\[0\].position\[0\]: must be from -1000.0 to 1000.0, got 1000000000.0"),
    ("here", r"sources\[0\].position: expected 3 numbers"),
])
def test_bad_sources_coordinate(tmp_path, position, match):
    _wav(tmp_path)
    path = _write(tmp_path, "sources.json", [{"name": "tv", "position": position, "wav": "tv.wav"}])
    _refused(lambda: sources_from_json(path), r"sources file .*sources.json: " + match)


def test_room_a_billion_metres_high_is_refused_before_any_allocation(tmp_path):
    path = _scene_file(tmp_path, lambda d: d["room"].update(height_m=1e9))
    _refused(lambda: load_scene(path), r"room.height_m: must be from 1.0 to 50.0, got 1000000000.0")


# -- Every field's range ----------------------------------------------------------------------------

@pytest.mark.parametrize("mutate, match", [
    (lambda d: d["room"].update(footprint=[[0, 0], [60, 0], [60, 4], [0, 4]]), r"spans 60 x 4 m.*from 1 to 50 m"),
    (lambda d: d["room"].update(footprint=[[0, 0], [1e6, 0], [1e6, 4], [0, 4]]),
     r"room.footprint\[1\]\[0\]: must be from -1000"),
    (lambda d: d["room"].update(footprint=[[0, 0]] * 10_000), r"room.footprint: expected 3 to 32 items, got 10000"),
    (lambda d: d["room"].update(height_m="2.7"), r"room.height_m: expected a finite number, got '2.7'"),
    (lambda d: d["room"].update(walls=d["room"]["walls"] * 1000), r"room.walls: expected exactly 4 items"),
    (lambda d: d["room"].update(floor="no_such_material"), r"room.floor: material: 'no_such_material' is not in"),
    (lambda d: d["room"]["ceiling"].update(scattering=1.5), r"room.ceiling.scattering: must be from 0.0 to 1.0"),
    (lambda d: d.update(mic_array=[]), r"scene.mic_array: expected a string"),
    (lambda d: d.update(mic_array="ear"), r"scene.mic_array: expected one of \('phone', 'headset4'\)"),
    (lambda d: d.update(name="\ud800"), r"scene.name: expected 1 to 100 printable characters"),
    (lambda d: d.update(name=[1]), r"scene.name: expected a string"),
    (lambda d: d.update(version=2), r"scene.version: must be exactly 1, got 2"),
    (lambda d: d.update(heigth_m=3), r"scene: unknown field 'heigth_m'"),
    (lambda d: d.update(poses=None), r"poses: expected a list, got None"),
    (lambda d: d.update(poses=d["poses"] * 100), r"poses: expected at most 1000 items, got 1200"),
    (lambda d: d["poses"][0].update(emitter=[1e308, 1, 1]), r"poses\[0\].emitter\[0\]: must be from -1000.0 to 1000.0"),
    (lambda d: d["poses"][0].update(target=10 ** 17),
     r"poses\[0\].target: no discontinuity 100000000000000000; there are 4"),
    (lambda d: d["poses"][0].update(colour="red"), r"poses\[0\]: unknown field 'colour'"),
    (lambda d: d["discontinuities"][0].update(wall=10 ** 17), r"discontinuities\[0\].wall: must be from 0 to 31"),
    (lambda d: d["discontinuities"][0].update(width_m=1e300),
     r"discontinuities\[0\].width_m: must be from 0.01 to 100.0"),
    (lambda d: d["discontinuities"][0].update(depth_sensor_sees_through="no"),
     r"depth_sensor_sees_through: expected true or false"),
    (lambda d: d["sources"][0].update(position=["1", "2", "1"]),
     r"sources\[0\].position\[0\]: expected a finite number, got '1'"),
    (lambda d: d["sources"][0].update(position=[3, 2, 9]),
     r"sources\[0\].position: .* outside the room \(the room spans x 0 to 6, y 0 to 4.5, z 0 to 2.7 m\)"),
    (lambda d: d["sources"][0].update(gain_db=1e6), r"sources\[0\].gain_db: must be from -60.0 to 40.0"),
    (lambda d: d.update(furniture=[{"center": [1, 1], "size": [1, 1, 1], "yaw_deg": 1e300}]),
     r"furniture\[0\].yaw_deg: must be from -360.0 to 360.0"),
    (lambda d: d.update(furniture=[{"center": [1, 1], "size": [1e308, 1, 1]}]),
     r"furniture\[0\].size\[0\]: must be from 0.01 to 50.0"),
    (lambda d: d["camera_path"].update(duration_s=1e300), r"camera_path.duration_s: must be from 0.1 to 3600.0"),
    (lambda d: d.update(emitter_p=float("nan")), r"NaN is not a number JSON allows"),
    (lambda d: d.update(emitter_p=float("inf")), r"Infinity is not a number JSON allows"),
])
def test_every_field_has_a_range(tmp_path, mutate, match):
    path = _scene_file(tmp_path, mutate)
    _refused(lambda: load_scene(path), match)


def test_read_json_refuses_what_is_not_a_small_json_file(tmp_path):
    _refused(lambda: read_json(tmp_path, "scene file"), r"^scene file \S+: not a regular file$")
    _refused(lambda: read_json(tmp_path / "gone.json", "scene file"), "cannot read")
    _refused(lambda: read_json(_write(tmp_path, "a.json", b"{\n  \"a\": 1,\n}"), "scene file"),
             r"not valid JSON \(line 3, column 1")
    _refused(lambda: read_json(_write(tmp_path, "a.json", b"[1e999]"), "scene file"), "too large for a float")
    _refused(lambda: read_json(_write(tmp_path, "a.json", b" " * 200), "x", max_bytes=100), "larger than the 100")
    _refused(lambda: read_json(_write(tmp_path, "a.json", b"[]"), "x", expect=dict), "expected a JSON object at the top")
    assert read_json(_write(tmp_path, "a.json", b"\xef\xbb\xbf{\"a\": [1, 2.5]}"), "x") == {"a": [1, 2.5]}  # a BOM is fine


def test_sources_file_fields_and_wav(tmp_path):
    _wav(tmp_path)
    (tmp_path / "text.wav").write_text("not audio")
    good = {"name": "tv", "position": [1, 2, 1], "wav": "tv.wav", "confidence": 0.5, "uncertainty_m": 0.2}
    [s] = sources_from_json(_write(tmp_path, "s.json", [good]))
    assert (s.name, s.fs, s.confidence, s.uncertainty_m) == ("tv", 16000, 0.5, 0.2)
    assert s.position.tolist() == [1.0, 2.0, 1.0]
    for change, match in [({"wav": "gone.wav"}, r"sources\[0\].wav: .*gone.wav is not a file"),
                          ({"wav": "text.wav"}, r"sources\[0\].wav: cannot read .* as audio"),
                          ({"wav": 5}, r"sources\[0\].wav: expected a string"),
                          ({"confidence": 2}, r"sources\[0\].confidence: must be from 0.0 to 1.0"),
                          ({"uncertainty_m": -1}, r"sources\[0\].uncertainty_m: must be from 0.0 to 1000.0"),
                          ({"name": {}}, r"sources\[0\].name: expected a string"),
                          ({"gain": 1}, r"sources\[0\]: unknown field 'gain'")]:
        path = _write(tmp_path, "s.json", [{**good, **change}])
        _refused(lambda: sources_from_json(path), match)
    _refused(lambda: sources_from_json(_write(tmp_path, "s.json", [good] * 65)), "sources: expected at most 64 items")
    _refused(lambda: sources_from_json(_write(tmp_path, "s.json", {"tv": good})), "expected a JSON array at the top")


# -- The learning code's manifests ----------------------------------------------------------------

CORRUPT = {"latin-1": b"\xff\xfe{}", "cut short": b'{"preset": "tiny", ', "a list": b"[1, 2]", "deep": b"[" * 5000}


@pytest.mark.parametrize("data", CORRUPT.values(), ids=CORRUPT.keys())
def test_corrupt_dataset_manifest(tmp_path, data):
    from vrecho.learn.datasets import Dataset, generate

    _write(tmp_path, "manifest.json", data)
    _refused(lambda: Dataset(tmp_path), r"dataset manifest .*manifest.json: ")
    _refused(lambda: generate(tmp_path, preset="tiny", progress=False), r"dataset manifest .*manifest.json: ")


@pytest.mark.parametrize("name", ["run.json", "training.json"])
@pytest.mark.parametrize("data", CORRUPT.values(), ids=CORRUPT.keys())
def test_corrupt_run_records(tmp_path, monkeypatch, name, data):
    from vrecho.learn import evaluate

    manifest = {"preset": "tiny", "seed": 0, "n_frames": 16}
    monkeypatch.setattr(evaluate, "Harness", lambda *a, **k: SimpleNamespace(ds=SimpleNamespace(manifest=manifest)))
    identity = {"format": "vrecho-run", "dataset": manifest, "seed": 0}
    _write(tmp_path, "run.json", identity)
    _write(tmp_path, name, data)
    _refused(lambda: evaluate.train_methods(tmp_path / "data", tmp_path, progress=False), r"(run|training records) .*json: ")


# -- The command line -------------------------------------------------------------------------------

@pytest.mark.parametrize("mutate", [lambda d: d["room"].update(height_m=1e9), lambda d: d.update(camera_path=[1, 2])])
def test_reconstruct_of_a_bad_scene_exits_2_and_writes_nothing(tmp_path, capsys, mutate):
    from vrecho.cli import main

    scene = _scene_file(tmp_path, mutate)
    out = tmp_path / "out"
    assert main(["reconstruct", str(scene), "--out", str(out), "--quiet"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith(f"vrecho: error: scene file {scene}: ")
    assert not out.exists()


def test_export_refuses_a_bad_sources_file_before_any_long_work(tmp_path, monkeypatch, capsys):
    from vrecho.app import scans
    from vrecho.cli import main

    def long_work(*args, **kwargs):
        raise AssertionError("the scan was simulated before the sources file was checked")

    monkeypatch.setattr(scans, "open_source", long_work)
    _wav(tmp_path)
    bad = _write(tmp_path, "sources.json", [{"position": [1, "a", 3], "wav": "tv.wav"}])
    out = tmp_path / "room.usda"
    assert main(["export", "builtin", "--out", str(out), "--sources", str(bad), "--quiet"]) == 2
    assert r"sources[0].position[1]" in capsys.readouterr().err
    assert not out.exists()


# -- Properties: nothing but VrechoError, no NaN, bounded time --------------------------------------

SCALARS = (st.none() | st.booleans() | st.integers(-10 ** 20, 10 ** 20) | st.floats() | st.text(max_size=12)
           | st.sampled_from([0, -1, 1e9, -1e9, 1e-300, 1e308, 2.7, "glass", "phone", "voice", "brickwork"]))
JSON = st.recursive(SCALARS, lambda c: st.lists(c, max_size=5) | st.dictionaries(st.text(max_size=8), c, max_size=5),
                    max_leaves=25)


def _paths(value, path=()):
    """Every place in a JSON value: its key path."""
    yield path
    items = value.items() if isinstance(value, dict) else enumerate(value) if isinstance(value, list) else ()
    for k, v in items:
        yield from _paths(v, (*path, k))


PATHS = list(_paths(BUILTIN))


def _check_scene(scene: Scene) -> None:
    """An accepted scene is whole: finite JSON, finite patches, its own round trip."""
    text = json.dumps(scene.to_dict(), allow_nan=False)
    assert Scene.from_dict(json.loads(text)).to_dict() == scene.to_dict()
    assert all(np.all(np.isfinite(p.corners)) and np.all(np.isfinite(p.normal)) for p in scene.patches())
    if scene.camera_path is not None:
        assert np.all(np.isfinite(np.concatenate(scene.camera_path.sample(50))))


def _load(path):
    try:
        scene = load_scene(path)
    except VrechoError as e:
        assert str(e).startswith(f"scene file {path}: ") and "\n" not in str(e) and len(str(e)) < 600
        return
    _check_scene(scene)


@fast(120)
@given(value=JSON)
def test_random_json_is_one_error(tmp_path, value):
    _load(_write(tmp_path, "scene.json", value))
    try:
        _check_scene(Scene.from_dict(value))
    except VrechoError:
        pass


@fast(250)
@given(data=st.data())
def test_mutated_builtin_scene_is_loaded_whole_or_refused(tmp_path, data):
    d = copy.deepcopy(BUILTIN)
    for _ in range(data.draw(st.integers(1, 3))):
        path = data.draw(st.sampled_from(PATHS[1:]))
        parent = d
        try:
            for k in path[:-1]:
                parent = parent[k]
            parent[path[-1]]
        except (KeyError, IndexError, TypeError):
            continue  # an earlier mutation took the place away
        action = data.draw(st.sampled_from(["replace", "delete", "unknown", "scale"]))
        if action == "replace":
            parent[path[-1]] = data.draw(JSON)
        elif action == "delete":
            del parent[path[-1]]
        elif action == "unknown" and isinstance(parent[path[-1]], dict):
            parent[path[-1]][data.draw(st.text(min_size=1, max_size=8))] = data.draw(SCALARS)
        elif isinstance(parent[path[-1]], (int, float)) and not isinstance(parent[path[-1]], bool):
            parent[path[-1]] *= data.draw(st.sampled_from([-1, 0, 1e-9, 1.001, 1e3, 1e9, 1e300]))
    _load(_write(tmp_path, "scene.json", d))


@fast(100)
@given(data=st.binary(max_size=600) | st.builds(lambda a, b: a + b, st.just(json.dumps(BUILTIN)[:300].encode()),
                                                   st.binary(max_size=50)))
def test_random_bytes_are_one_error(tmp_path, data):
    path = _write(tmp_path, "file.json", data)
    _load(path)
    try:
        sources_from_json(path)
    except VrechoError:
        pass


FIELD = st.one_of(JSON, st.lists(st.floats(-2000, 2000), min_size=3, max_size=3))


@fast(150)
@given(items=st.lists(st.dictionaries(st.sampled_from(["name", "position", "wav", "confidence", "uncertainty_m", "gain"]),
                                      st.one_of(FIELD, st.sampled_from(["tv.wav", "gone.wav", "text.wav", ".", "tv"])),
                                      max_size=6), max_size=4) | JSON)
def test_random_sources_files_are_one_error(tmp_path, items):
    _wav(tmp_path)
    (tmp_path / "text.wav").write_text("not audio")
    path = _write(tmp_path, "sources.json", items)
    try:
        placed = sources_from_json(path)
    except VrechoError as e:
        assert str(e).startswith(f"sources file {path}: ")
        return
    for s in placed:
        assert s.position.shape == (3,) and np.all(np.abs(s.position) <= 1000)
        assert 0 <= s.confidence <= 1 and s.fs == 16000 and s.signal.name == "tv.wav"
        assert s.uncertainty_m is None or 0 <= s.uncertainty_m <= 1000 and math.isfinite(s.uncertainty_m)
