"""The demo (issue 8): the whole run on the built-in living room, and its meshcat walkthrough
opened by a real headless Chromium (Debian's package, installed by ``install.sh --test``)."""

import json

import numpy as np
import pytest
from conftest import run_cli

from vrecho.scene import builtin_scene


def _png(path):
    import matplotlib.image as mpimg

    return (mpimg.imread(path)[..., :3] * 255).astype(int)


def _alert_red(img) -> int:
    return int(((img[..., 0] > 200) & (img[..., 1] < 60) & (img[..., 2] < 60)).sum())


def _source_orange(img) -> int:
    return int(((img[..., 0] > 220) & (img[..., 1] > 90) & (img[..., 1] < 170) & (img[..., 2] < 70)).sum())


def _box_room():
    """A 5 x 4 x 2.5 m box, its faces toward the inside (as a scan's are)."""
    import open3d as o3d

    box = o3d.geometry.TriangleMesh.create_box(5.0, 4.0, 2.5)
    return np.asarray(box.vertices), np.asarray(box.triangles)[:, ::-1], None


def test_walkthrough_page_shows_the_scene_in_headless_chromium(tmp_path):
    from demo.browser import screenshot
    from demo.walkthrough import Marker, Track, Walkthrough, static_page
    from usd_export import LabeledSurface

    room = _box_room()
    rect = lambda x0, x1, y, z0, z1: np.array([[x0, y, z0], [x1, y, z0], [x1, y, z1], [x0, y, z1]], float)  # noqa: E731
    surfaces = [LabeledSurface("glass_0", rect(1, 2.5, 0.0, 1, 2), "closed", "glass", 1.0, 0.9),
                LabeledSurface("opening_1", rect(3, 4, 0.0, 1, 2), "open", None, 1.0, 0.9)]
    n = 40
    track = Track(np.c_[np.full(n, 1.7), np.linspace(2.5, 0.2, n), np.full(n, 1.6)],
                  ["clear"] * 20 + ["caution"] * 10 + ["stop"] * 10, "walk into the glass")
    camera = (np.array([[1.0, 2.0, 1.5], [3.0, 2.0, 1.5], [4.0, 3.0, 1.5]]), np.array([[0, -1.0, 0], [1, 0, 0], [0, 1, 0]]))
    w = Walkthrough(room, room, surfaces, camera, [Marker(np.array([3.0, 3.5, 1.0]), "source_0")],
                    [Marker(np.array([3.2, 3.5, 1.0]), "voice (truth)")], [track], "test room",
                    (np.zeros(3), np.array([5.0, 4.0, 2.5])))
    page = tmp_path / "page.html"
    page.write_text(static_page(w))
    assert 0.5e6 < page.stat().st_size < 5e6 and "https://" not in page.read_text()[:2000]
    img = _png(screenshot(page, tmp_path / "page.png", size=(900, 600)))
    assert img.shape == (600, 900, 3)
    # WebGL drew the geometry: the stop dots and the placed source's sphere are there.
    assert _alert_red(img) > 20 and _source_orange(img) > 50
    # Not a blank page: well over a tenth of the picture differs from the background gradient
    # (each row's median colour) outside the legend's corner.
    top = img[:380]
    assert np.mean(np.abs(top - np.median(top, axis=1, keepdims=True)).sum(axis=2) > 40) > 0.1


@pytest.mark.slow
def test_the_demo_runs_the_whole_pipeline_on_the_living_room(tmp_path):
    out = tmp_path / "out"
    r = run_cli("demo", "--out", out, "--no-browser", "--quiet", timeout=900)
    assert r.returncode == 0, r.stderr[-2000:]
    rows = [[c.strip() for c in line.split("|")[1:-1]] for line in r.stdout.splitlines()
            if line.startswith("| ") and "---" not in line][1:]
    holes = [row for row in rows if row[0].startswith("hole")]
    walks = [row for row in rows if row[0].startswith("walk into")]
    sources = [row for row in rows if row[0].startswith("source ")]
    assert len(holes) == 4 and all(row[3] == "yes" for row in holes)  # each discontinuity decided right
    assert {row[2].split()[0] for row in holes} == {"glass", "open", "mirror"}
    assert len(walks) == 4 and all(row[3] == "yes" for row in walks)  # warned before glass and mirrors only
    assert len(sources) == 3 and sum(row[3] == "yes" for row in sources) >= 2
    assert [row[3] for row in rows if row[0].startswith("scene.usd")] == ["yes", "yes"]
    for name in ("initial.ply", "repaired.ply", "report.json", "before_after.png", "surfaces.png", "boundary.png",
                 "scene.usda", "scene.usdz", "summary.md", "walkthrough.html", "walkthrough.png", "echoes.md"):
        assert (out / name).stat().st_size > 0, name
    assert json.loads((out / "report.json").read_text())["metrics"]
    # The exported package read back: the repaired surfaces and the placed sources are in it.
    from pxr import Usd, UsdMedia

    import usd_export

    assert not [p for p in usd_export.validate(out / "scene.usdz") if p.severity == "error"]
    stage = Usd.Stage.Open(str(out / "scene.usdz"))
    placed = next(row[1] for row in rows if row[0] == "scene.usdz").split(", ")[1]  # "N spatial-audio sources"
    assert sum(p.IsA(UsdMedia.SpatialAudio) for p in stage.Traverse()) == int(placed.split()[0]) >= 2
    # The walkthrough as the browser shows it: the room, the alerts, the sources.
    img = _png(out / "walkthrough.png")
    assert _alert_red(img) > 20 and _source_orange(img) > 50


@pytest.mark.slow
def test_the_demo_on_a_users_scene_with_the_page_elsewhere(tmp_path):
    from conftest import small_room

    scene = tmp_path / "room.json"
    scene.write_text(small_room(sources=True).to_json())
    out, page = tmp_path / "out", tmp_path / "pages" / "room.html"
    r = run_cli("demo", "--scene", scene, "--out", out, "--html", page, "--no-browser", "--quiet", timeout=900)
    assert r.returncode == 0, r.stderr[-2000:]
    assert page.stat().st_size > 1e6 and not (out / "walkthrough.html").exists()
    summary = (out / "summary.md").read_text()
    assert summary.count("| yes |") == 9 and "**no**" not in summary  # 3 holes, 1 source, 3 walks, 2 stages


def test_listen_hears_open_and_closed_surfaces():
    from vrecho.sim.listening import listen

    levels = {}
    for o in listen(builtin_scene(), progress=False):
        levels.setdefault(o.kind, []).append(o.echo_level_db)
    assert set(levels) == {"glass", "open", "mirror"}
    # an opening returns far less than glass or a mirror at the same distances
    assert max(levels["open"]) < min(levels["glass"] + levels["mirror"]) - 3


def test_a_placed_source_answers_for_one_true_source_at_most():
    from types import SimpleNamespace as S

    from demo.run import source_rows

    # The demo's living room as it came out: one placed source is the nearest to the voice and to the brown noise.
    scene = S(sources=[S(sound="voice", position=(3.0, 4.25, 1.1)), S(sound="brown_noise", position=(1.0, 3.6, 0.8)),
                       S(sound="whistle", position=(5.2, 3.4, 0.75))])
    placed = [S(name="source_0", position=np.array([5.15, 3.39, 0.75]), confidence=0.7),
              S(name="source_1", position=np.array([1.16, 3.57, 0.91]), confidence=0.2),
              S(name="source_2", position=np.array([3.0, 1.0, 2.0]), confidence=0.1)]
    rows = {row[0]: row for row in source_rows(scene, placed[:2])}
    assert rows["source voice"] == ("source voice", "not placed (2 placed for 3; nearest 1.97 m away)",
                                    "at [3.0, 4.25, 1.1] m", False)
    assert rows["source brown_noise"][1].startswith("source_1") and rows["source brown_noise"][3] is True
    assert rows["source whistle"][1].startswith("source_0") and rows["source whistle"][3] is True
    assert len(rows) == 3
    rows = {row[0]: row for row in source_rows(scene, placed)}  # a third one placed: the voice's, 3.4 m off
    assert rows["source voice"][1].startswith("source_2") and rows["source voice"][3] is False
    assert rows["source brown_noise"][1].startswith("source_1") and len(rows) == 3
    assert [row[1] for row in source_rows(scene, [])] == ["not heard"] * 3


def test_demo_refuses_a_page_that_is_not_html_before_any_work(tmp_path):
    r = run_cli("demo", "--out", tmp_path / "out", "--html", tmp_path / "page.png", "--no-browser")
    assert r.returncode == 2 and "html" in r.stderr and len(r.stderr.strip().splitlines()) == 1
    assert not (tmp_path / "out").exists()


def test_the_walkthrough_is_served_live(tmp_path, capsys):
    import urllib.request

    from demo.walkthrough import Walkthrough, serve

    room = _box_room()
    camera = (np.array([[1.0, 2.0, 1.5], [3.0, 2.0, 1.5]]), np.array([[0, -1.0, 0], [1, 0, 0]]))
    pages = []

    def visit():  # what a browser does while the server runs
        url = capsys.readouterr().out.split("served at ")[1].split()[0]
        with urllib.request.urlopen(url, timeout=30) as r:
            pages.append((r.status, r.read()))

    serve(Walkthrough(room, room, [], camera), wait=visit)
    assert pages[0][0] == 200 and b"MeshCat" in pages[0][1]
