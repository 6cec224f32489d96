"""What bad input gets: some 270 bad or edge-case inputs through every command and public call.

Each case runs in a process of its own (forked from one that has imported vrecho, so a native
crash or a hang is seen as such and costs one case), and gets one outcome:

- ``error``: one :class:`~vrecho.errors.VrechoError` (a command: exit 2 and one line on stderr);
- ``flagged``: an answer that says it is unsure (low confidence, a flag, no source found), or
  an answer where the input, odd as it is, is valid (a quad face, PCM samples);
- failures: ``traceback`` (any other exception, or more than one line from a command),
  ``crash`` (killed by a signal), ``hang`` (past the time limit), ``confident`` (a confident
  answer to input that carries none), ``nan`` (NaN in an answer), ``answered`` (a command or
  call that should have refused and did not), ``partial`` (files left by a failed command),
  ``overwritten`` (a user's file changed).

Usage: ``python3 benchmarks/probe_bad_input.py [--jobs 2] [--timeout 120] [--only AREA]`` prints
a table per area and every failure; exit status 1 when any case fails.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import multiprocessing as mp
import os
import resource
import signal
import subprocess
import sys
import tempfile
import time
from collections import Counter, defaultdict
from dataclasses import dataclass
from pathlib import Path

import numpy as np

GOOD = ("error", "flagged")


@dataclass
class Case:
    area: str
    name: str
    run: object  # () -> answer, or a list of argv for the command
    judge: object = None  # answer -> "flagged" | "confident" | "answered" | "nan"; None: the call must refuse
    out: Path | None = None  # a command's output, which a failure must leave as it was
    full_disk: bool = False


# -- Judging answers -------------------------------------------------------------------------------

def _finite(x) -> bool:
    a = np.asarray(x, dtype=float) if not isinstance(x, dict) else np.asarray(list(x.values()), float)
    return bool(np.all(np.isfinite(a)))


def unsure_prediction(p) -> str:
    if not (_finite(p.depth_m) and _finite(p.confidence) and _finite(p.probabilities)):
        return "nan"
    return "flagged" if (p.low_confidence or p.flags) else "confident"


def unsure_predictions(ps) -> str:
    judged = [unsure_prediction(p) for p in ps]
    return "nan" if "nan" in judged else ("flagged" if all(j == "flagged" for j in judged) else "confident")


def no_sources(placed) -> str:
    if any(not (_finite(p.position) and _finite(p.confidence)) for p in placed):
        return "nan"
    return "flagged" if not placed else "confident"


def unsure_sources(placed) -> str:
    """No source, or none placed with confidence above 0.5."""
    if any(not (_finite(p.position) and _finite(p.confidence)) for p in placed):
        return "nan"
    return "flagged" if all(p.confidence <= 0.5 for p in placed) else "confident"


def finite_signal(y) -> str:
    return "flagged" if _finite(y) else "nan"


def flagged_rows(out: Path, flag: str) -> str:
    """A capture's frames.csv: every row flagged ``flag`` and at most 0.5 confident."""
    import csv

    with open(out / "frames.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    ok = rows and all(flag in r["flags"] and float(r["confidence"]) <= 0.5 for r in rows)
    return "flagged" if ok else "confident"


def any_finite_prediction(p) -> str:
    """A valid input (PCM samples): any answer without NaN will do."""
    return "flagged" if unsure_prediction(p) != "nan" else "nan"


def probe_written(out) -> str:
    """The monitor's speaker buffer: the probe written (finite, not all silent), or the call refused."""
    a = np.asarray(out, dtype=float)
    return "flagged" if np.all(np.isfinite(a)) and np.any(a != 0) else "answered"


# -- Running one case ------------------------------------------------------------------------------

def _snapshot(path: Path | None):
    if path is None or not path.exists():
        return None
    if path.is_file():
        return {path.name: path.read_bytes()}
    return {str(p.relative_to(path)): (p.read_bytes() if p.is_file() else None) for p in sorted(path.rglob("*"))}


def _child(case: Case, conn) -> None:
    from vrecho.cli import main
    from vrecho.errors import VrechoError

    if case.full_disk:
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
        resource.setrlimit(resource.RLIMIT_FSIZE, (2_000_000, 2_000_000))
    err = tempfile.TemporaryFile()
    saved = os.dup(2)
    os.dup2(err.fileno(), 2)  # what C libraries print counts as much as Python's lines
    try:
        with contextlib.redirect_stdout(io.StringIO()):
            if isinstance(case.run, list):
                try:
                    rc = main(case.run)
                except SystemExit as e:  # argparse's own refusal: usage and one error line
                    rc = e.code
                except BaseException as e:  # noqa: BLE001 - what the command let escape
                    rc = f"{type(e).__name__}: {str(e)[:200]}"
                sys.stderr.flush()
                err.seek(0)
                lines = [l for l in err.read().decode(errors="replace").splitlines() if l.strip()]
                if rc == 2 and lines and (lines[-1].startswith("vrecho: error:") or ": error: argument" in lines[-1]
                                          or ": error: " in lines[-1]) and not any("Traceback" in l for l in lines) \
                        and (len(lines) == 1 or lines[0].startswith("usage:")):
                    outcome = ("error", lines[-1][:160])
                elif rc == 0:
                    outcome = (case.judge(), "exit 0") if case.judge else ("answered", "exit 0")
                else:
                    outcome = ("traceback", f"exit {rc}: " + " | ".join(lines[-3:])[:300])
            else:
                try:
                    answer = case.run()
                except VrechoError as e:
                    outcome = ("error", str(e)[:160])
                except BaseException as e:  # noqa: BLE001 - the probe's point
                    outcome = ("traceback", f"{type(e).__name__}: {str(e)[:200]}")
                else:
                    outcome = (case.judge(answer), "") if case.judge else ("answered", repr(answer)[:120])
    finally:
        os.dup2(saved, 2)
    conn.send(outcome)


def run_case(case: Case, timeout: float) -> tuple[str, str, float]:
    before = _snapshot(case.out)
    parent, child = mp.Pipe(duplex=False)
    proc = mp.get_context("fork").Process(target=_child, args=(case, child))
    start = time.perf_counter()
    proc.start()
    child.close()
    outcome = None
    if parent.poll(timeout):
        try:
            outcome = parent.recv()
        except EOFError:
            pass
    proc.join(5 if outcome else 0.1)
    if proc.is_alive():
        proc.kill()
        proc.join()
        if outcome is None:
            return "hang", f"no answer in {timeout:.0f} s", time.perf_counter() - start
    if outcome is None:  # killed by a signal (a native crash), or died without a word
        return "crash", f"exit code {proc.exitcode}", time.perf_counter() - start
    seconds = time.perf_counter() - start
    kind, detail = outcome
    if case.out is not None and kind not in ("answered", "flagged"):
        after = _snapshot(case.out)
        if after != before:
            if before is None:
                left = [k for k, v in (after or {}).items() if v is not None]
                if left or (after is not None and case.out.is_file()):
                    return "partial", f"left {left[:3]}", seconds
            else:
                return "overwritten", "the folder changed", seconds
    return kind, detail, seconds


# -- The cases -------------------------------------------------------------------------------------

def _setup(base: Path) -> dict:
    """Real material to break: a small room's scene, its scan folder and a simulated capture (a
    video with the pulse train, COLMAP poses, a mesh). Made in a child process (no library that
    starts threads runs in the parent, which forks)."""
    code = f"""
import json, sys
sys.path.insert(0, {str(Path(__file__).resolve().parent.parent / 'tests')!r})
from conftest import small_room
from vrecho.sim.captures import simulate_capture
from vrecho.capture import read_video
import soundfile as sf
base = __import__('pathlib').Path({str(base)!r})
scene = small_room(sources=True)
(base / 'scene.json').write_text(json.dumps(scene.to_dict()))
cap = simulate_capture(small_room(), base / 'capture', n_pulses=6)
x, fs, _ = read_video(cap['video'])
sf.write(base / 'pulses.wav', x, fs)
"""
    subprocess.run([sys.executable, "-c", code], check=True)
    subprocess.run([sys.executable, "-m", "vrecho", "reconstruct", str(base / "scene.json"), "--out", str(base / "rec"),
                    "--frames", "6", "--labels", "oracle", "--save-scan", "--quiet"], check=True, capture_output=True)
    return {"scene": base / "scene.json", "scan": base / "rec" / "scan", "capture": base / "capture",
            "wav": base / "pulses.wav"}


def _write(path: Path, data) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_bytes(data if isinstance(data, bytes) else data.encode())
    return path


def _leaves(d, path=()):
    if isinstance(d, dict):
        for k, v in d.items():
            yield from _leaves(v, (*path, k))
    elif isinstance(d, list) and d and not all(isinstance(x, (int, float)) for x in d):
        for i, v in enumerate(d):
            yield from _leaves(v, (*path, i))
    else:
        yield path, d


def _set(d, path, value):
    d = json.loads(json.dumps(d))
    cur = d
    for k in path[:-1]:
        cur = cur[k]
    cur[path[-1]] = value
    return d


def scene_cases(base: Path, m: dict) -> list[Case]:
    from vrecho.scene import load_scene

    good = json.loads(m["scene"].read_text())
    cases = []
    raw = {"non-UTF-8 bytes": b"\xff\xfe\x00{\x93", "empty file": b"", "null": b"null", "a list": b"[]",
           "a string": b'"scene"', "a number": b"1", "truncated": m["scene"].read_bytes()[:200],
           "deep nesting": b"[" * 200_000 + b"]" * 200_000, "huge integer": json.dumps(good).replace(
               '"height_m": 2.5', '"height_m": ' + "9" * 5000).encode(),
           "NaN literal": json.dumps(good).replace('"height_m": 2.5', '"height_m": NaN').encode(),
           "Infinity literal": json.dumps(good).replace('"height_m": 2.5', '"height_m": Infinity').encode(),
           "UTF-16": json.dumps(good).encode("utf-16"), "binary zeros": bytes(4096),
           "room 1e9 m high": json.dumps(good).replace('"height_m": 2.5', '"height_m": 1e9').encode(),
           "room 1e6 m wide": json.dumps(_set(good, ("room", "footprint"),
                                              [[0, 0], [1e6, 0], [1e6, 3.6], [0, 3.6]])).encode()}
    for name, data in raw.items():
        path = _write(base / "scenes" / f"{len(cases)}.json", data)
        cases.append(Case("scene JSON", name, lambda p=path: load_scene(p)))
    bad_values = {float: [None, "x", 1e308, -1e308, True, [1, 2]], int: [None, "x", -7, 10**12, 2.5, True],
                  str: [None, 17, [], {"a": 1}], list: ["x", None, {"a": 1}, 5]}
    leaves = [(p, v) for p, v in _leaves(good) if p and p[-1] not in ("name", "format", "version")]
    for i, (path, v) in enumerate(leaves):
        kind = bool if isinstance(v, bool) else type(v)
        options = bad_values.get(kind)
        if not options:
            continue
        value = options[i % len(options)]
        mutated = _write(base / "scenes" / f"m{i}.json", json.dumps(_set(good, path, value)))
        cases.append(Case("scene JSON", f"{'.'.join(map(str, path))} = {value!r}"[:70], lambda p=mutated: load_scene(p)))
    # Through the commands: one line, nothing written.
    for i, name in enumerate(("non-UTF-8 bytes", "deep nesting", "room 1e9 m high", "NaN literal")):
        path = base / "scenes" / f"{list(raw).index(name)}.json"
        for cmd in ("reconstruct", "export", "demo"):
            out = base / "outs" / f"scene{i}{cmd}"
            argv = {"reconstruct": ["reconstruct", str(path), "--out", str(out)],
                    "export": ["export", str(path), "--out", str(out) + ".usda"],
                    "demo": ["demo", "--scene", str(path), "--out", str(out), "--no-browser"]}[cmd]
            cases.append(Case("scene JSON", f"vrecho {cmd}: {name}", argv + ["--quiet"],
                              out=Path(argv[argv.index("--out") + 1])))
    bad_sources = {"not JSON": "{", "a dict": '{"a": 1}', "2-D position": '[{"position": [1, 2], "wav": "x.wav"}]',
                   "NaN position": '[{"position": [NaN, 1, 1], "wav": "x.wav"}]',
                   "string position": '[{"position": "here", "wav": "x.wav"}]',
                   "missing WAV": '[{"position": [1, 1, 1], "wav": "nowhere.wav"}]',
                   "WAV a text file": '[{"position": [1, 1, 1], "wav": "scene.json"}]',
                   "confidence a string": '[{"position": [1, 1, 1], "wav": "../pulses.wav", "confidence": "high"}]',
                   "name a list": '[{"position": [1, 1, 1], "wav": "../pulses.wav", "name": [1]}]'}
    for i, (name, text) in enumerate(bad_sources.items()):
        src = _write(base / "sources" / f"{i}.json", text)
        out = base / "outs" / f"sources{i}.usda"
        cases.append(Case("sources JSON", f"export --sources: {name}", ["export", str(m["scene"]), "--out", str(out),
                                                                          "--sources", str(src), "--quiet"], out=out))
    return cases


PLY_HEAD = "ply\nformat ascii 1.0\nelement vertex {nv}\nproperty float x\nproperty float y\nproperty float z\n" \
           "element face {nf}\nproperty list uchar int vertex_indices\nend_header\n"


def _ply(vertices, faces) -> str:
    return PLY_HEAD.format(nv=len(vertices), nf=len(faces)) + "".join(
        " ".join(map(str, v)) + "\n" for v in vertices) + "".join(f"{len(f)} " + " ".join(map(str, f)) + "\n"
                                                                   for f in faces)


def mesh_cases(base: Path, m: dict) -> list[Case]:
    from vrecho.io import read_mesh

    tri = [[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]]
    meshes = {
        "negative index": _ply(tri, [[0, 1, -5]]), "index out of range": _ply(tri, [[0, 1, 99]]),
        "NaN vertex": _ply([[float("nan"), 0, 0], *tri[1:]], [[0, 1, 2]]),
        "inf vertex": _ply([[float("inf"), 0, 0], *tri[1:]], [[0, 1, 2]]),
        "1e30 vertex": _ply([[1e30, 0, 0], *tri[1:]], [[0, 1, 2]]), "no faces": _ply(tri, []),
        "no vertices": _ply([], [[0, 1, 2]]), "empty file": "", "garbage": "\x00\x01garbage" * 50,
        "header only": PLY_HEAD.format(nv=4, nf=1),
        "claims 1e9 vertices": PLY_HEAD.format(nv=10**9, nf=1) + "0 0 0\n",
        "a quad face": _ply(tri, [[0, 1, 2, 3]]), "a two-index face": _ply(tri, [[0, 1]]),
        "text in a vertex": _ply(tri, [[0, 1, 2]]).replace("1 0 0\n", "a b c\n", 1),
        "huge index": _ply(tri, [[0, 1, 2**31 - 1]]),
    }
    cases = []
    for name, text in meshes.items():
        path = _write(base / "meshes" / f"{len(cases)}.ply", text)
        valid = (lambda mesh: "flagged") if name == "a quad face" else None  # a valid polygon, split in two
        cases.append(Case("meshes", f"read_mesh: {name}", lambda p=path: read_mesh(p), valid))
    objs = {"obj index out of range": "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 99\n",
            "obj negative beyond": "v 0 0 0\nv 1 0 0\nv 0 1 0\nf -1 -2 -9\n",
            "obj NaN vertex": "v nan 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n", "obj no faces": "v 0 0 0\n",
            "obj garbage": "\xff\xfe binary", "obj text": "hello world\n"}
    for name, text in objs.items():
        path = _write(base / "meshes" / f"{len(cases)}.obj", text.encode("latin-1"))
        cases.append(Case("meshes", f"read_mesh: {name}", lambda p=path: read_mesh(p)))
    binary = (base / "meshes" / "good.ply")
    good_ply = (m["scan"] / "mesh.ply").read_bytes()
    for name, data in {"binary truncated to half": good_ply[: len(good_ply) // 2],
                       "binary truncated in the header": good_ply[:40],
                       "binary with a flipped byte every 1000": bytes(b ^ 0xFF if i % 1000 == 999 else b
                                                                       for i, b in enumerate(good_ply))}.items():
        path = _write(base / "meshes" / f"{len(cases)}.ply", data)
        cases.append(Case("meshes", f"read_mesh: {name}", lambda p=path: read_mesh(p)))
    for name in ("a folder", "missing", "an .stl"):
        path = base / "meshes" / {"a folder": "dir.ply", "missing": "none.ply", "an .stl": "x.stl"}[name]
        if name == "a folder":
            path.mkdir(parents=True, exist_ok=True)
        elif name == "an .stl":
            _write(path, "solid x\nendsolid x\n")
        cases.append(Case("meshes", f"read_mesh: {name}", lambda p=path: read_mesh(p)))
    # Through the commands: a scan folder's mesh.ply, and capture's --mesh.
    for i, name in enumerate(("negative index", "index out of range", "NaN vertex", "no faces", "garbage")):
        scan = base / "scans" / str(i)
        scan.mkdir(parents=True, exist_ok=True)
        for f in m["scan"].iterdir():
            (scan / f.name).write_bytes(f.read_bytes())
        _write(scan / "mesh.ply", meshes[name])
        out = base / "outs" / f"meshscan{i}"
        cases.append(Case("meshes", f"vrecho reconstruct FOLDER: {name}",
                          ["reconstruct", str(scan), "--out", str(out), "--labels", "echocnn-only", "--quiet"], out=out))
        out = base / "outs" / f"meshcap{i}"
        mesh = base / "meshes" / f"cap{i}.ply"
        _write(mesh, meshes[name])
        cases.append(Case("meshes", f"vrecho capture --mesh: {name}",
                          ["capture", str(m["capture"] / "capture.mkv"), "--poses", str(m["capture"] / "poses"),
                           "--mesh", str(mesh), "--image-fps", "4", "--out", str(out), "--quiet"], out=out))
    return cases


def colmap_cases(base: Path, m: dict) -> list[Case]:
    from vrecho.capture import read_poses

    poses = m["capture"] / "poses"
    cams, imgs = (poses / "cameras.txt").read_text(), (poses / "images.txt").read_text()
    lines = imgs.splitlines()
    head = [i for i, l in enumerate(lines) if l and not l.startswith("#")][0]
    first = lines[head].split()
    variants = {
        "binary images.txt": (cams, os.urandom(3000)), "non-UTF-8 images.txt": (cams, b"\xff\xfe" + imgs.encode()),
        "empty images.txt": (cams, ""), "images.txt truncated mid-line": (cams, imgs[: len(imgs) // 2 + 7]),
        "NaN quaternion": (cams, imgs.replace(lines[head], " ".join([first[0], "nan", *first[2:]]))),
        "zero quaternion": (cams, imgs.replace(lines[head], " ".join([first[0], "0", "0", "0", "0", *first[5:]]))),
        "text translation": (cams, imgs.replace(lines[head], " ".join([*first[:5], "x", *first[6:]]))),
        "9 fields": (cams, imgs.replace(lines[head], " ".join(first[:9]))),
        "unknown camera id": (cams, imgs.replace(lines[head], " ".join([*first[:8], "7", first[9]]))),
        "duplicate image id": (cams, imgs + lines[head] + "\n\n"),
        "unnumbered picture": (cams, imgs.replace(lines[head], " ".join([*first[:9], "photo.png"]))),
        "1e300 translation": (cams, imgs.replace(lines[head], " ".join([*first[:5], "1e300", *first[6:]]))),
        "binary cameras.txt": (os.urandom(500), imgs), "empty cameras.txt": ("", imgs),
        "unknown camera model": (cams.replace("PINHOLE", "FISHEYE_MAGIC"), imgs),
        "negative focal length": (" ".join(cams.splitlines()[-1].split()[:4] + ["-500"] +
                                           cams.splitlines()[-1].split()[5:]), imgs),
        "zero image size": (cams.replace(cams.splitlines()[-1], " ".join(
            cams.splitlines()[-1].split()[:2] + ["0", "0"] + cams.splitlines()[-1].split()[4:])), imgs),
        "two cameras": (cams + "\n" + cams.splitlines()[-1].replace("1 ", "2 ", 1) + "\n", imgs),
        "no cameras.txt": (None, imgs), "no images.txt": (cams, None),
    }
    cases = []
    for i, (name, (c, im)) in enumerate(variants.items()):
        folder = base / "colmap" / str(i)
        folder.mkdir(parents=True, exist_ok=True)
        if c is not None:
            _write(folder / "cameras.txt", c)
        if im is not None:
            _write(folder / "images.txt", im)
        valid = (lambda poses: "flagged") if name == "two cameras" else None  # the second one is used by no picture
        cases.append(Case("COLMAP", f"read_poses: {name}", lambda f=folder: read_poses(f, 4.0, 6.5), valid))
        if i % 4 == 0:
            out = base / "outs" / f"colmap{i}"
            cases.append(Case("COLMAP", f"vrecho capture --poses: {name}",
                              ["capture", str(m["capture"] / "capture.mkv"), "--poses", str(folder),
                               "--mesh", str(m["capture"] / "mesh.ply"), "--image-fps", "4", "--out", str(out),
                               "--quiet"], out=out))
    return cases


def audio_cases(base: Path, m: dict) -> list[Case]:
    import soundfile as sf

    from vrecho import load_classifier
    from vrecho.capture import find_onsets, read_audio

    x, fs = read_audio(m["wav"])
    rng = np.random.default_rng(0)
    one = x[int(0.25 * fs): int(1.25 * fs)].astype(np.float64)
    noise = 0.1 * rng.standard_normal(fs)
    env = np.repeat(rng.random(40) > 0.5, fs // 40 + 1)[:fs]
    speech = noise * env * np.sin(2 * np.pi * 3 * np.arange(fs) / fs) ** 2

    def predict(a, r, **k):
        return lambda: load_classifier().predict(a, r, **k)

    arrays = {"empty": np.zeros(0), "NaN": np.full(fs, np.nan), "inf": np.full(fs, np.inf),
              "2-D (2, n)": np.stack([one, one]), "3-D": one.reshape(1, 1, -1), "a scalar": np.float64(0.3),
              "int16": (one * 20000).astype(np.int16), "bool": one > 0, "complex": one.astype(complex),
              "object": np.array([None] * 10, dtype=object), "strings": np.array(["a"] * 10),
              "a list of strings": ["a", "b"], "1e308 samples": np.full(fs, 1e308), "10 samples": one[:10],
              "an hour": np.zeros(3600 * 44100, dtype=np.float32)}
    cases = [Case("recordings", f"predict: {k}", predict(a, fs), any_finite_prediction if k == "int16" else
                  unsure_prediction) for k, a in arrays.items()]
    for r in (0, -44100, 44100.5, 1e9, 10**12, "44100", None, True, 8000, 11025):
        judge = unsure_prediction if r in (8000, 11025) else None
        audio = one[:: 44100 // int(r)] if r in (8000, 11025) else one
        cases.append(Case("recordings", f"predict: fs={r!r}", predict(audio, r), judge))
    content = {"silence": np.zeros(fs), "white noise": noise, "speech-like bursts": speech,
               "a DC offset": np.full(fs, 0.5), "a 1 kHz tone": 0.3 * np.sin(2 * np.pi * 1000 * np.arange(fs) / fs),
               "clipped on 10 %": np.clip(one * 20, -1, 1), "one click": np.eye(1, fs, 500)[0]}
    for k, a in content.items():
        cases.append(Case("recordings", f"predict: {k}", predict(a, fs), unsure_prediction))
        cases.append(Case("recordings", f"predict with the probe: {k}",
                          lambda a=a: load_classifier().predict(a, fs, emitted=__import__("vrecho").signals.probe()),
                          unsure_prediction))
    t = np.arange(fs) / fs
    for name, fade in {"speech fading out": np.clip(1 - t, 0, 1), "speech dying away": np.exp(-4 * t)}.items():
        talk = noise * env * np.cos(2 * np.pi * 3 * t) ** 2 * fade  # loud from the first sample
        cases.append(Case("recordings", f"predict: {name}", predict(talk, fs), unsure_prediction))
    cases.append(Case("recordings", "predict_batch: mixed lengths", lambda: load_classifier().predict_batch(
        [one, one[:100]], fs), unsure_predictions))
    cases.append(Case("recordings", "predict: emitted NaN", predict(one, fs, emitted=np.full(100, np.nan))))
    cases.append(Case("recordings", "predict: emitted empty", predict(one, fs, emitted=np.zeros(0))))
    cases.append(Case("recordings", "predict: image NaN", predict(one, fs, image=np.full((64, 25), np.nan))))
    cases.append(Case("recordings", "predict: image wrong shape", predict(one, fs, image=np.zeros((3, 3, 3, 3)))))
    probe_ = __import__("vrecho").signals.probe()
    for name, d in (("NaN", np.nan), ("0", 0.0), ("-1", -1.0), ("11 m", 11.0), ("inf", np.inf), ("a string", "far"),
                    ("two for one frame", [1.0, 2.0])):
        cases.append(Case("recordings", f"predict: surface_m {name}", predict(one, fs, emitted=probe_, surface_m=d)))
    cases.append(Case("recordings", "predict: surface_m without emitted", predict(one, fs, surface_m=1.0)))
    for name, v in (("0", 0.0), ("1 m", 1.0), ("NaN", np.nan), ("a string", "5 cm"), ("True", True)):
        cases.append(Case("recordings", f"predict: surface_tolerance_m {name}",
                          predict(one, fs, emitted=probe_, surface_m=1.0, surface_tolerance_m=v)))
    for name, v in (("NaN", np.nan), ("1 m", 1.0), ("-inf", -np.inf), ("a string", "up"), ("two for one frame", [0.0, 0.1])):
        cases.append(Case("recordings", f"predict: mic_toward_surface_m {name}",
                          predict(one, fs, emitted=probe_, surface_m=1.0, mic_toward_surface_m=v)))
    cases.append(Case("recordings", "predict: mic_toward_surface_m without surface_m",
                      predict(one, fs, emitted=probe_, mic_toward_surface_m=0.0)))
    # Recordings as files, through the capture command (no pulse train: one error; flagged rows otherwise).
    long_noise = 0.1 * rng.standard_normal(8 * fs)
    long_speech = long_noise * np.repeat(rng.random(320) > 0.5, fs // 40 + 1)[: 8 * fs]
    files = {"white noise": (long_noise, fs), "speech-like bursts": (long_speech, fs), "silence": (np.zeros(8 * fs), fs),
             "noise bursts": (long_noise * (np.arange(8 * fs) % fs < fs // 20) * (rng.random(8 * fs) > 0.3), fs),
             "a sine": (0.3 * np.sin(2 * np.pi * 440 * np.arange(8 * fs) / fs), fs),
             "the capture at 8 kHz": (x[::int(fs // 8000)], 8000),
             "the capture clipped on 10 %": (np.clip(x * 12, -1, 1), fs), "0.3 s of the capture": (x[: int(0.3 * fs)], fs)}
    for i, (name, (a, r)) in enumerate(files.items()):
        wav = base / "wavs" / f"{i}.wav"
        wav.parent.mkdir(parents=True, exist_ok=True)
        sf.write(wav, a, r)
        if name in ("white noise", "speech-like bursts", "silence", "noise bursts", "a sine"):
            cases.append(Case("recordings", f"find_onsets: {name}", lambda a=a, r=r: find_onsets(a, r)))
        out = base / "outs" / f"wav{i}"
        flag = {"the capture at 8 kHz": "low_rate", "the capture clipped on 10 %": "clipped"}.get(name)
        cases.append(Case("recordings", f"vrecho capture --audio: {name}", ["capture", "--audio", str(wav), "--out",
                                                                          str(out), "--quiet"],
                          judge=(lambda out=out, flag=flag: flagged_rows(out, flag)) if flag else None,
                          out=None if flag else out))
    stereo = base / "wavs" / "stereo.wav"
    sf.write(stereo, np.stack([0.3 * x, np.clip(x * 12, -1, 1)], 1), fs)
    out = base / "outs" / "stereo"
    cases.append(Case("recordings", "vrecho capture --audio: stereo, one channel clipped",
                      ["capture", "--audio", str(stereo), "--out", str(out), "--quiet"],
                      judge=lambda out=out: flagged_rows(out, "clipped")))
    for name, data in {"text as WAV": b"hello", "WAV header only": open(m["wav"], "rb").read()[:44],
                       "truncated WAV": open(m["wav"], "rb").read()[:5000],
                       "truncated video": (m["capture"] / "capture.mkv").read_bytes()[:20000],
                       "video of zeros": bytes(100000)}.items():
        path = _write(base / "wavs" / (name.replace(" ", "_") + (".mkv" if "video" in name else ".wav")), data)
        out = base / "outs" / ("f" + path.stem)
        argv = ["capture", str(path)] if "video" in name else ["capture", "--audio", str(path)]
        cases.append(Case("recordings", f"vrecho capture: {name}", argv + ["--out", str(out), "--quiet"], out=out))
    return cases


def monitor_cases() -> list[Case]:
    from vrecho.headset import BoundaryMonitor

    def block(indata, outdata, frames=None, fs=48000, **kw):
        def go():
            mon = BoundaryMonitor(fs, **kw)
            n = frames if frames is not None else (len(outdata) if hasattr(outdata, "__len__") else 0)
            mon.callback(indata, outdata, n, None, None)
            return outdata
        return go

    ro = np.zeros((480, 1), np.float32)
    ro.flags.writeable = False
    z = lambda n=480, c=1, d=np.float32: np.zeros((n, c), d)  # noqa: E731
    cases = []
    for fs in (0, -48000, 8000, 16000, 22050, 96000, 48000.5, "48000", None):
        cases.append(Case("monitor", f"BoundaryMonitor(fs={fs!r})", lambda fs=fs: BoundaryMonitor(fs)))
    for k, v in {"mic_offset_m": [float("nan"), -1.0, 10.0, "7 cm"], "period_s": [0.0, -1.0, float("inf")],
                 "max_latency_s": [-0.1, 1e9], "threshold": [float("nan")]}.items():
        for x in v:
            cases.append(Case("monitor", f"BoundaryMonitor({k}={x!r})", lambda k=k, x=x: BoundaryMonitor(48000, **{k: x})))
    blocks = {
        "read-only speaker buffer": (z(), ro, None), "int16 speaker buffer": (z(d=np.int16), z(d=np.int16), "probe"),
        "int32 speaker buffer": (z(d=np.int32), z(d=np.int32), "probe"), "float64 buffers": (z(d=np.float64),
                                                                                             z(d=np.float64), "probe"),
        "frames disagree": (z(), z(), None, 999), "1-D buffers": (np.zeros(480, np.float32), np.zeros(480, np.float32),
                                                                  "probe"),
        "3-D buffers": (np.zeros((480, 1, 1), np.float32), np.zeros((480, 1, 1), np.float32), None),
        "in and out of different lengths": (z(240), z(480), None), "object buffers": (z(d=object), z(d=object), None),
        "None buffers": (None, None, None, 480), "lists": ([[0.0]] * 480, [[0.0]] * 480, None),
        "a NaN microphone block": (np.full((480, 1), np.nan, np.float32), z(), "probe"),
        "an inf microphone block": (np.full((480, 1), np.inf, np.float32), z(), "probe"),
        "a 5000-sample block": (z(5000), z(5000), "probe"), "an empty block": (z(0), z(0), "nothing", 0),
        "8 microphone channels": (z(480, 8), z(480, 2), "probe"), "bool buffers": (z(d=bool), z(d=bool), None),
    }
    for name, spec in blocks.items():
        indata, outdata, judge = spec[:3]
        frames = spec[3] if len(spec) > 3 else None
        judge = {"probe": probe_written, "nothing": lambda out: "flagged", None: None}[judge]  # 0 frames: nothing to do
        cases.append(Case("monitor", f"callback: {name}", block(indata, outdata, frames), judge))
    return cases


def localization_cases() -> list[Case]:
    import localization
    from localization import Capture
    from vrecho.sim.arrays import envelope_walk

    rng = np.random.default_rng(1)
    mics = np.array([[0, 0, 1.5], [0.1, 0, 1.5], [0, 0.1, 1.5], [0, 0, 1.6]])
    box = ([0, 0, 0], [4, 4, 2.5])
    noise = lambda: Capture(0.01 * rng.standard_normal((4, 16000)), 16000, mics)  # noqa: E731
    t = np.arange(16000) / 16000
    src = np.sin(2 * np.pi * 440 * t) * (1 + 0.5 * np.sin(2 * np.pi * 3 * t))
    delays = [0, 3, 5, 2]
    coherent = lambda: Capture(np.stack([np.roll(src, d) for d in delays]) + 0.001 * rng.standard_normal((4, 16000)),  # noqa: E731
                               16000, mics)
    cases = [Case("localization", "place_sources: independent noise", lambda: localization.place_sources(
                  [noise() for _ in range(3)], bounds=box), no_sources),
             Case("localization", "locate: independent noise", lambda: localization.locate([noise(), noise()], bounds=box),
                  lambda r: "flagged" if len(r.positions) == 0 else "confident")]
    walk = [np.array([1.0 + 0.4 * k, 1.0 + 0.3 * k, 0.0]) + mics for k in range(4)]

    def diffuse(m):  # 200 noise plane waves from random directions
        f = np.fft.rfftfreq(16000, 1 / 16000)
        spec = np.zeros((len(m), len(f)), complex)
        for u in rng.standard_normal((200, 3)):
            spec += np.fft.rfft(rng.standard_normal(16000))[None] * np.exp(
                2j * np.pi * f[None] * (m @ (u / np.linalg.norm(u)))[:, None] / 343.0)
        return 0.01 * np.fft.irfft(spec, 16000) / 20

    common = 0.01 * rng.standard_normal(16000)
    cases += [Case("localization", "place_sources: diffuse noise", lambda: localization.place_sources(
                  [Capture(diffuse(m), 16000, m) for m in walk], bounds=box), unsure_sources),
              Case("localization", "place_sources: crosstalk (one signal on every channel)", lambda: localization.place_sources(
                  [Capture(common + 1e-4 * rng.standard_normal((4, 16000)), 16000, m) for m in walk], bounds=box),
                  unsure_sources)]
    for n in (0, -1, 100, 2.5, "2", True, 10**9):
        cases.append(Case("localization", f"place_sources(n_sources={n!r})",
                          lambda n=n: localization.place_sources([coherent()], n, bounds=box)))
    for name, pos in {"on microphone 0": mics[:1], "1 mm from microphone 1": mics[1:2] + 1e-3,
                      "NaN position": [[np.nan, 1, 1]], "2-D position": [[1, 1]], "positions for 2 of 1": [[1, 1, 1]] * 2}.items():
        cases.append(Case("localization", f"separate informed: {name}",
                          lambda pos=pos: localization.separate(coherent(), 1, positions=pos), finite_signal))
    captures = {"NaN samples": (np.full((4, 16000), np.nan), 16000, mics),
                "inf samples": (np.full((4, 16000), np.inf), 16000, mics), "silence": (np.zeros((4, 16000)), 16000, mics),
                "one silent microphone": (np.vstack([np.zeros(16000), rng.standard_normal((3, 16000))]), 16000, mics),
                "1 microphone": (rng.standard_normal((1, 16000)), 16000, mics[:1]),
                "coincident microphones": (rng.standard_normal((4, 16000)), 16000, np.zeros((4, 3))),
                "NaN microphone position": (rng.standard_normal((4, 16000)), 16000, np.full((4, 3), np.nan)),
                "mics for 3 of 4 channels": (rng.standard_normal((4, 16000)), 16000, mics[:3]),
                "0.01 s": (rng.standard_normal((4, 160)), 16000, mics), "fs 0": (rng.standard_normal((4, 16000)), 0, mics),
                "fs 1e9": (rng.standard_normal((4, 16000)), 10**9, mics), "int16 samples":
                    ((rng.standard_normal((4, 16000)) * 1000).astype(np.int16), 16000, mics),
                "complex samples": (rng.standard_normal((4, 16000)).astype(complex), 16000, mics),
                "channels as columns": (rng.standard_normal((16000, 4)), 16000, mics),
                "mics unknown": (rng.standard_normal((4, 16000)), 16000, None)}
    for name, (a, r, mm) in captures.items():
        cases.append(Case("localization", f"Capture: {name}", lambda a=a, r=r, mm=mm: localization.place_sources(
            [Capture(a, r, mm)], bounds=box), no_sources))
    for name, b in {"inverted box": ([4, 4, 2.5], [0, 0, 0]), "NaN box": ([np.nan] * 3, [1, 1, 1]),
                    "flat box": ([0, 0, 1], [4, 4, 1]), "a 1e6 m box": ([0, 0, 0], [1e6, 1e6, 1e6])}.items():
        cases.append(Case("localization", f"locate bounds: {name}",
                          lambda b=b: localization.locate([coherent()], 1, bounds=b)))
    cases.append(Case("localization", "place_sources: no captures", lambda: localization.place_sources([], bounds=box)))
    cases.append(Case("localization", "place_sources: not captures", lambda: localization.place_sources([1, 2], bounds=box)))
    cases.append(Case("localization", "separate: unknown method", lambda: localization.separate(coherent(), 1,
                                                                                                  method="magic")))
    for name, pos in {"NaN position": [[np.nan, 1, 1], [2, 2, 1]], "2-D positions": [[1, 1], [2, 2]],
                      "no positions": np.zeros((0, 3)), "9 positions": np.arange(27.0).reshape(9, 3),
                      "text": "the sofa", "None": None}.items():
        cases.append(Case("localization", f"informed: {name}", lambda pos=pos: localization.informed(coherent(), pos)))
    cases.append(Case("localization", "informed: not a capture", lambda: localization.informed(np.zeros((4, 16000)), [[1, 1, 1]])))
    cases.append(Case("localization", "envelope_walk: unknown condition",
                      lambda: envelope_walk(rng, "underwater")))
    return cases


def command_cases(base: Path, m: dict) -> list[Case]:
    user = base / "user"
    _write(user / "notes.txt", "the user's notes")
    _write(user / "report.json", "the user's own report")
    _write(base / "user.usda", "#usda 1.0\n")
    _write(base / "user_audio" / "x.wav", "x")
    big = ["--frames", "6", "--labels", "oracle", "--quiet"]
    cases = [
        Case("commands", "reconstruct into a folder of the user's files", ["reconstruct", str(m["scene"]), "--out",
                                                                          str(user), *big], out=user),
        Case("commands", "capture into a folder of the user's files", ["capture", "--audio", str(m["wav"]), "--out",
                                                                      str(user), "--quiet"], out=user),
        Case("commands", "demo into a folder of the user's files", ["demo", "--out", str(user), "--no-browser", "--quiet"],
             out=user),
        Case("commands", "export over the user's stage", ["export", str(m["scene"]), "--out", str(base / "user.usda"),
                                                          *big], out=base / "user.usda"),
        Case("commands", "reconstruct: missing scene", ["reconstruct", str(base / "none.json"), "--out", str(base / "o")]),
        Case("commands", "reconstruct: a folder that is no scan", ["reconstruct", str(user), "--out", str(base / "o")]),
        Case("commands", "reconstruct: out in /proc", ["reconstruct", str(m["scene"]), "--out", "/proc/vrecho", *big]),
        Case("commands", "reconstruct: out is a file", ["reconstruct", str(m["scene"]), "--out", str(m["wav"]), *big]),
        Case("commands", "reconstruct --frames 0", ["reconstruct", str(m["scene"]), "--out", str(base / "o"),
                                                    "--frames", "0"]),
        Case("commands", "reconstruct --frames 10**9", ["reconstruct", str(m["scene"]), "--out", str(base / "o"),
                                                        "--frames", str(10**9)]),
        Case("commands", "reconstruct --seed -1", ["reconstruct", "builtin", "--out", str(base / "o"), "--seed", "-1"]),
        Case("commands", "reconstruct --labels oracle on a scan", ["reconstruct", str(m["scan"]), "--out",
                                                                   str(base / "o"), "--labels", "oracle"]),
        Case("commands", "export --out x.obj", ["export", "builtin", "--out", str(base / "x.obj")]),
        Case("commands", "export --out in a missing folder", ["export", "builtin", "--out", str(base / "no" / "x.usda")]),
        Case("commands", "export --sources heard on a scan", ["export", str(m["scan"]), "--out", str(base / "y.usda"),
                                                              "--sources", "heard"]),
        Case("commands", "export --sources nonsense", ["export", "builtin", "--out", str(base / "y.usda"),
                                                       "--sources", "loud"]),
        Case("commands", "train --epochs -3", ["train", "--data", str(base / "none"), "--out", str(base / "run"),
                                               "--epochs", "-3"]),
        Case("commands", "train: no dataset", ["train", "--data", str(base / "none"), "--out", str(base / "run")]),
        Case("commands", "train: a dataset folder of junk", ["train", "--data", str(user), "--out", str(base / "run2")]),
        Case("commands", "train: a dataset manifest without its counts", ["train", "--data", str(
            _write(base / "bare" / "manifest.json", '{"format": "vrecho-dataset", "version": 1, "complete": true}').parent),
            "--out", str(base / "run3")]),
        Case("commands", "evaluate: no run", ["evaluate", "--data", str(base / "none"), "--run", str(base / "none")]),
        Case("commands", "generate --workers 0", ["generate", "--out", str(base / "ds"), "--workers", "0"]),
        Case("commands", "generate into the user's folder", ["generate", "--out", str(user)], out=user),
        Case("commands", "generate --preset huge", ["generate", "--out", str(base / "ds"), "--preset", "huge"]),
        Case("commands", "capture: a video and --audio", ["capture", str(m["capture"] / "capture.mkv"), "--audio",
                                                          str(m["wav"]), "--out", str(base / "o")]),
        Case("commands", "capture --emitter-distance nan", ["capture", "--audio", str(m["wav"]), "--out",
                                                            str(base / "o"), "--emitter-distance", "nan"]),
        Case("commands", "capture --emitter-distance 50", ["capture", "--audio", str(m["wav"]), "--out",
                                                           str(base / "o"), "--emitter-distance", "50"]),
        Case("commands", "capture --image-fps -4", ["capture", str(m["capture"] / "capture.mkv"), "--poses",
                                                    str(m["capture"] / "poses"), "--mesh", str(m["capture"] / "mesh.ply"),
                                                    "--image-fps", "-4", "--out", str(base / "o")]),
        Case("commands", "capture --images of text files", ["capture", "--audio", str(m["wav"]), "--images", str(user),
                                                            "--image-fps", "4", "--out", str(base / "o")]),
        Case("commands", "demo --html x.txt", ["demo", "--out", str(base / "o"), "--html", str(base / "x.txt")]),
        Case("commands", "watch --samplerate 8000", ["watch", "--samplerate", "8000", "--seconds", "1"]),
        Case("commands", "watch --blocksize 99999", ["watch", "--blocksize", "99999", "--seconds", "1"]),
        Case("commands", "watch --device 999", ["watch", "--device", "999", "--seconds", "1"]),
        Case("commands", "watch --seconds -1", ["watch", "--seconds", "-1"]),
        Case("commands", "watch --mic-offset nan", ["watch", "--mic-offset", "nan", "--seconds", "1"]),
    ]
    for name, argv in {"reconstruct": ["reconstruct", str(m["scene"]), "--out", str(base / "full1"), *big],
                       "export": ["export", str(m["scene"]), "--out", str(base / "full2.usda"), *big],
                       "capture": ["capture", str(m["capture"] / "capture.mkv"), "--poses", str(m["capture"] / "poses"),
                                   "--mesh", str(m["capture"] / "mesh.ply"), "--image-fps", "4", "--out",
                                   str(base / "full3"), "--quiet"]}.items():
        out = Path(argv[argv.index("--out") + 1])
        cases.append(Case("commands", f"{name} on a full disk", argv, out=out, full_disk=True))
    return cases


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--jobs", type=int, default=2, help="cases at once (default 2)")
    parser.add_argument("--timeout", type=float, default=120.0, help="seconds a case may take (default 120)")
    parser.add_argument("--only", default=None, help="only this area (e.g. 'meshes')")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory(prefix="vrecho-probe-") as tmp:
        base = Path(tmp)
        print("setting up: a small room's scene, scan and simulated capture ...", flush=True)
        m = _setup(base)
        import localization  # noqa: F401 - everything imported once, before the forks
        import vrecho.cli  # noqa: F401
        from vrecho.headset import BoundaryMonitor  # noqa: F401

        cases = (scene_cases(base, m) + mesh_cases(base, m) + colmap_cases(base, m) + audio_cases(base, m)
                 + monitor_cases() + localization_cases() + command_cases(base, m))
        if args.only:
            cases = [c for c in cases if c.area == args.only]
        print(f"{len(cases)} cases, {args.jobs} at a time, {args.timeout:.0f} s each at most", flush=True)
        results = []
        start = time.perf_counter()
        from concurrent.futures import ThreadPoolExecutor

        with ThreadPoolExecutor(args.jobs) as pool:
            for case, (kind, detail, s) in zip(cases, pool.map(lambda c: run_case(c, args.timeout), cases)):
                results.append((case, kind, detail, s))
                if kind not in GOOD:
                    print(f"  FAIL {case.area} / {case.name}: {kind} ({detail})", flush=True)
        by_area = defaultdict(Counter)
        for case, kind, _, _ in results:
            by_area[case.area][kind] += 1
        kinds = ["error", "flagged", "traceback", "crash", "hang", "confident", "nan", "answered", "partial",
                 "overwritten"]
        print(f"\n| area | cases | {' | '.join(kinds)} |\n|---|---|{'---|' * len(kinds)}")
        for area, c in [*by_area.items(), ("all", sum(by_area.values(), Counter()))]:
            print(f"| {area} | {sum(c.values())} | " + " | ".join(str(c[k]) for k in kinds) + " |")
        slow = sorted(results, key=lambda r: -r[3])[:5]
        print(f"\n{len(results)} cases in {time.perf_counter() - start:.0f} s; slowest: "
              + ", ".join(f"{r[0].name} {r[3]:.1f} s" for r in slow))
        failed = [r for r in results if r[1] not in GOOD]
        print(f"{len(failed)} failures" + ("" if not failed else ":"))
        for case, kind, detail, _ in failed:
            print(f"- {case.area} / {case.name}: {kind} ({detail})")
        return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
