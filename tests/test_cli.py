import json

from conftest import run_cli

from vrecho.scene import builtin_scene


def _one_error_line(result):
    lines = result.stderr.strip().splitlines()
    assert result.returncode == 2 and len(lines) == 1 and lines[0].startswith("vrecho: error: "), result.stderr
    return lines[0]


def test_help_lists_commands():
    r = run_cli("--help")
    assert r.returncode == 0 and "generate" in r.stdout and "demo" in r.stdout
    assert run_cli("generate", "--help").returncode == 0


def test_demo_on_a_bad_scene_says_one_line_and_writes_nothing(tmp_path):
    d = json.loads(builtin_scene().to_json())
    d["room"]["height_m"] = -1
    scene = tmp_path / "bad.json"
    scene.write_text(json.dumps(d))
    out = tmp_path / "out"
    line = _one_error_line(run_cli("demo", "--scene", scene, "--out", out))
    assert "room.height_m" in line and not out.exists()


def test_generate_into_an_unwritable_folder(tmp_path):
    line = _one_error_line(run_cli("generate", "--out", "/proc/vrecho-data", "--preset", "tiny"))
    assert "not writable" in line
    blocker = tmp_path / "file"
    blocker.write_text("x")
    line = _one_error_line(run_cli("generate", "--out", blocker / "ds"))
    assert "not writable" in line


def test_generate_bad_arguments():
    r = run_cli("generate", "--out", "/tmp/x-vrecho", "--seed", "-3")
    assert r.returncode == 2 and "--seed: expected 0 to" in r.stderr
    r = run_cli("generate", "--out", "/tmp/x-vrecho", "--preset", "huge")
    assert r.returncode == 2 and "invalid choice" in r.stderr
