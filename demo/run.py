"""``vrecho demo``: the whole of vrecho on one scene, each decision against the scene's truth.

Steps, each with the library's own calls (nothing here decides anything itself):

1. the simulated phone scan along the scene's walkthrough and its fusion
   (:func:`vrecho.sim.scans.scan_scene`);
2. its discontinuities, EchoCNN's answers (shipped weights) on the echoes of the frames facing
   them, and the repair (:func:`vrecho.reconstruct.reconstruct`);
3. what the device hears in front of each surface (:func:`vrecho.sim.listening.listen`): the figure of
   the surfaces' echoes;
4. the room's sources heard by the headset's 4 microphones along the same walk, located,
   separated and placed (:func:`localization.place_sources`);
5. the headset call (:class:`vrecho.headset.BoundaryMonitor`) on a walk toward each
   discontinuity at 1 m/s (:func:`vrecho.sim.walks.simulate_walk`);
6. the OpenUSD export (.usda with its WAVs, and .usdz), checked by OpenUSD's validators;
7. the walkthrough page (:mod:`demo.walkthrough`), its screenshot where Chromium is installed.
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy.optimize import linear_sum_assignment
from tqdm import tqdm

import localization
import usd_export
from vrecho.app.figures import below
from vrecho.app.scans import write
from vrecho.errors import VrechoError
from vrecho.headset import BoundaryMonitor
from vrecho.io import OutputFolder, atomic_write_text, ensure_writable_dir
from vrecho.reconstruct import reconstruct
from vrecho.scene import Scene, builtin_scene, load_scene
from vrecho.signals import FS, probe
from vrecho.sim.listening import figure, listen, table
from vrecho.sim.render import World
from vrecho.sim.scans import hear_echoes, scan_scene
from vrecho.sim.scenes import walkthrough_path
from vrecho.sim.scoring import SceneTruth, match_truth
from vrecho.sim.walks import headset_frames, simulate_walk

from . import browser as chromium
from . import walkthrough
from .walkthrough import LEVEL_COLOURS, Marker, Track, Walkthrough

WALK_SPEED_MPS = 1.0
WALK_FROM_M = 2.5  # a boundary walk starts this far from the surface (less where the room is smaller)
HEAR_POSES = 12  # localization's captures along the walk (1.5 s each)
SOURCE_RIGHT_M = 0.5  # a source placed within this of a true one counts as found
DISPLAY_VOXEL_M = 0.05  # the page's meshes: vertices clustered at this size


@dataclass
class BoundaryWalk:
    """The headset call on a walk toward a discontinuity: per 10 ms block the device's position
    (K, 3), the true distance to the surface's plane and the alert level; the true distance when
    caution and stop were first raised (None: never); what the stop named the surface (the
    headset camera's answer, :meth:`~vrecho.headset.BoundaryMonitor.see`).

    Attributes
    ----------
    surface : int
        The discontinuity's index in the scene.
    kind : {"glass", "mirror", "open"}
    positions : numpy.ndarray, shape (K, 3)
        The device's position in metres, per block.
    distance_m : numpy.ndarray, shape (K,)
        The true distance to the surface's plane in metres, per block.
    levels : list of {"clear", "caution", "stop"}
        The alert, per block.
    caution_at_m, stop_at_m : float or None
        The true distance in metres when caution and stop were first raised.
    named : str, optional
        What the stop named the surface.
    """

    surface: int
    kind: str
    positions: np.ndarray
    distance_m: np.ndarray
    levels: list[str]
    caution_at_m: float | None
    stop_at_m: float | None
    named: str | None = None

    @property
    def right(self) -> bool:
        """A closed surface warned of before 0.5 m and named right; an opening walked through
        without alarm."""
        if self.kind == "open":
            return self.caution_at_m is None
        return self.caution_at_m is not None and self.caution_at_m >= 0.5 and self.named == self.kind


@dataclass
class DemoRun:
    """A demo's results: ``rows`` the decisions against the truth (what, vrecho says, truth,
    right), ``files`` what was written, ``seconds`` each step's time.

    Attributes
    ----------
    scene : Scene
    reconstruction : Reconstruction
        The scan and its repair.
    placed : list
        The sources placed (:func:`localization.place_sources`).
    walks : list of BoundaryWalk
    rows : list of tuple
        (what, vrecho says, truth, right): ``right`` True, False, or None where it is an account,
        not a decision.
    files : dict of str to pathlib.Path
    seconds : dict of str to float
        Each step's time in seconds, and ``total``.
    """

    scene: Scene
    reconstruction: object  # vrecho.reconstruct.Reconstruction
    placed: list
    walks: list[BoundaryWalk]
    rows: list[tuple[str, str, str, bool | None]]
    files: dict[str, Path] = field(default_factory=dict)
    seconds: dict[str, float] = field(default_factory=dict)

    def table(self) -> str:
        """The decisions as a Markdown table (a row per entry of ``rows``).

        Returns
        -------
        str
        """
        lines = ["| decision | vrecho says | truth | right |", "|:---|:---|:---|:---:|"]
        mark = {True: "yes", False: "**no**", None: "-"}
        lines += [f"| {a} | {b} | {c} | {mark[d]} |" for a, b, c, d in self.rows]
        return "\n".join(lines)


def _surface_name(scene: Scene, k: int) -> str:
    d = scene.discontinuities[k]
    return f"{d.kind} on wall {d.wall} (#{k})"


def _hole_rows(scene: Scene, result) -> list:

    rows, found = [], set()
    for k, (hole, d, action) in enumerate(zip(result.holes, result.decisions, result.actions)):
        truth = match_truth(scene, hole)
        said = {"open": "open", "closed": f"closed, {d.material}", "unknown": "unknown (not heard)"}[d.state]
        said += f" (p closed {d.p_closed:.2f})"
        if action.get("phantom_triangles_removed"):
            said += f", {action['phantom_triangles_removed']:,} phantom triangles removed"
        what = f"hole {k} ({hole.area_m2:.2f} m2)"
        if truth is None:
            rows.append((what, said, "no discontinuity there (a gap in the scan)", None))
            continue
        found.add(truth)
        t = scene.discontinuities[truth]
        right = d.state == "open" if t.is_open else (d.state == "closed" and d.material == t.kind)
        rows.append((what, said, _surface_name(scene, truth), right))
    for k in range(len(scene.discontinuities)):
        if k not in found:
            rows.append((f"{_surface_name(scene, k)}", "not found in the scan", _surface_name(scene, k), False))
    return rows


def _repair_row(m: dict) -> tuple:
    """The repaired scan against the scene's geometry (``m``: :func:`vrecho.sim.scoring.score`'s
    metrics, as report.json holds them): an account, not a decision."""
    said = []
    if m["closed_ious"]:
        errors = [e for e in m["depth_error_cm"] if e is not None and np.isfinite(e)]
        said.append(f"closed surfaces overlap the truth by IoU {m['closed_iou']:.2f}"
                    + (f", planes {min(errors):.1f}-{max(errors):.1f} cm off" if errors else ""))
    said.append(f"phantom area {m['phantom_m2_initial']:.1f} -> {m['phantom_m2']:.1f} m2")
    if m["n_openings"]:
        said.append(f"{m['openings_filled'] * m['n_openings']:.0f} of {m['n_openings']} openings filled")
    return ("repaired scan", "; ".join(said), "the scene's geometry", None)


def source_rows(scene: Scene, placed: list) -> list:
    """The summary's rows for the room's sound sources: one per true source and one per placed
    source that matches none. Each placed source answers for one true source at most (the pairs
    that lie nearest in all, as the benchmarks match them), so two true sources near one placed
    source are not both said to be found.

    Parameters
    ----------
    scene : Scene
        Its ``sources`` (each with ``sound`` and ``position``, metres) are the truth.
    placed : list
        What :func:`localization.place_sources` placed (each with ``name``, ``position`` and
        ``confidence``).

    Returns
    -------
    list of tuple
        (decision, what vrecho says, the truth, right: bool).
    """
    truths = [np.asarray(s.position, float) for s in scene.sources]
    d = np.array([[np.linalg.norm(p.position - t) for p in placed] for t in truths]).reshape(len(truths), len(placed))
    match = dict(zip(*linear_sum_assignment(d)))  # true source -> placed source
    rows = []
    for k, s in enumerate(scene.sources):
        where = f"at {np.round(truths[k], 2).tolist()} m"
        if k not in match:
            said = "not heard" if not placed else (f"not placed ({len(placed)} placed for {len(truths)}; nearest "
                                                   f"{d[k].min():.2f} m away)")
            rows.append((f"source {s.sound}", said, where, False))
            continue
        j = match[k]
        p = placed[j]
        rows.append((f"source {s.sound}", f"{p.name} at {np.round(p.position, 2).tolist()} m "
                     f"(confidence {p.confidence:.2f})", f"{where}: {d[k, j]:.2f} m away", bool(d[k, j] <= SOURCE_RIGHT_M)))
    for j, p in enumerate(placed):
        if j not in match.values():
            near = d[:, j].min() if len(truths) else np.inf
            rows.append((f"{p.name}", f"a source at {np.round(p.position, 2).tolist()} m", f"no source there "
                         f"(nearest {near:.2f} m)", False))
    return rows


def _walk_rows(scene: Scene, walks: list[BoundaryWalk]) -> list:
    rows = []
    for w in walks:
        at = lambda d: "never" if d is None else f"at {d:.2f} m"  # noqa: E731
        said = f"caution {at(w.caution_at_m)}, stop {at(w.stop_at_m)}" + (f": {w.named}" if w.named else "")
        truth = ("an opening: no alarm" if w.kind == "open"
                 else f"{w.kind}: caution before 0.5 m, named {w.kind}")
        rows.append((f"walk into {_surface_name(scene, w.surface)}", said, truth, w.right))
    return rows


def boundary_walks(scene: Scene, rng: np.random.Generator, *, progress: bool = False) -> list[BoundaryWalk]:
    """The headset call on a walk toward each discontinuity of ``scene`` (1.6 m high, straight
    at its centre, at 1 m/s, from up to 2.5 m away), in 10 ms blocks at 48 kHz, the headset's
    camera showing it a frame every 0.24 s (:func:`vrecho.sim.walks.headset_frames`).

    A walk starts as far as 2.5 m from the surface as the room allows (0.3 m from its walls),
    but no nearer than 1 m; a surface with no such room in front of it gets no walk.

    Parameters
    ----------
    scene : Scene
    rng : numpy.random.Generator
        Draws the walks' noise.
    progress : bool
        Show a progress bar (default False).

    Returns
    -------
    list of BoundaryWalk
        One per discontinuity walked toward, in the scene's order.
    """
    fs = 48000
    world = World(scene)
    out = []
    for k in tqdm(range(len(scene.discontinuities)), desc="headset walks", unit="walk", disable=not progress):
        d = scene.discontinuities[k]
        origin, u, normal = scene.room.wall_frame(d.wall)  # normal: out of the room
        target = origin + d.center_u_m * u + [0.0, 0.0, 1.6]
        start = next((target - normal * s for s in np.arange(WALK_FROM_M, 0.9, -0.1)
                      if scene.room.contains((target - normal * s)[None], margin_m=0.3)[0]), None)
        if start is None:
            continue  # no room to walk toward it
        mon = BoundaryMonitor(fs, seed=int(rng.integers(2 ** 32)))
        walk = simulate_walk(scene, start, start + normal, WALK_SPEED_MPS, mon.schedule, (origin, normal), rng)
        n10 = fs // 100
        frames = headset_frames(world, walk)
        positions, distances, levels = [], [], []
        caution = stop = named = None
        for i in range(0, len(walk.mic), n10):
            alert = mon.process(walk.mic[i:i + n10])
            level = alert.level
            while frames and frames[0][0] <= (i + n10) / fs:
                mon.see(*frames.pop(0)[1:])
            now = min(int(np.searchsorted(walk.pulse_times_s, (i + n10) / fs - walk.output_lag_s)),
                      len(walk.distance_m) - 1)  # the pulse being played
            positions.append(walk.position_m[now])
            distances.append(walk.distance_m[now])
            levels.append(level)
            if level != "clear" and caution is None:
                caution = float(walk.distance_m[now])
            if level == "stop" and stop is None:
                stop, named = float(walk.distance_m[now]), alert.surface
        out.append(BoundaryWalk(k, d.kind, np.array(positions), np.array(distances), levels, caution, stop, named))
    return out


def boundary_figure(walks: list[BoundaryWalk], path: Path) -> Path:
    """Each walk's true distance against time, coloured by the alert, with the thresholds.

    Parameters
    ----------
    walks : list of BoundaryWalk
        At least one.
    path : pathlib.Path
        The PNG to write.

    Returns
    -------
    pathlib.Path
        ``path``.
    """
    import matplotlib  # heavy (0.8 s to import): only figures need it

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # once the Agg backend is chosen: no display needed

    fig, axes = plt.subplots(1, len(walks), figsize=(3.2 * len(walks), 3.2), squeeze=False, sharey=True)
    for ax, w in zip(axes[0], walks):
        t = 0.01 * np.arange(1, len(w.levels) + 1)
        ax.scatter(t, w.distance_m, c=[LEVEL_COLOURS[v] for v in w.levels], s=6)
        for y, name in ((1.0, "caution 1.0 m"), (0.5, "stop 0.5 m")):
            ax.axhline(y, color="0.5", lw=0.7, ls="--")
            ax.text(t[-1], y, name, ha="right", va="bottom", fontsize=7, color="0.3")
        ax.set_title(f"into the {w.kind} (#{w.surface})" + (f": stop, '{w.named}'" if w.named else ""), fontsize=9)
        ax.set_xlabel("s")
    axes[0, 0].set_ylabel("true distance to the surface (m)")
    fig.suptitle("headset call on walks at 1 m/s: green clear, amber caution, red stop", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return path


def _walkthrough(scene: Scene, result, room: tuple, surfaces: list, placed: list, walks: list[BoundaryWalk]):
    """What the page shows: the scan and the repaired room (``room``: vertices, faces, colours
    without the added surfaces, drawn apart), the ceiling cut away."""
    import open3d as o3d  # heavy (1.2 s to import): only the page's meshes need it

    top = np.percentile(np.asarray(result.scan.mesh.vertices)[:, 2], 98) - 0.3

    def arrays(mesh):  # for the page: 5 cm vertex clusters (a 20 MB page becomes 7 MB)
        mesh = below(mesh, top).simplify_vertex_clustering(voxel_size=DISPLAY_VOXEL_M)
        colours = np.asarray(mesh.vertex_colors) if mesh.has_vertex_colors() else None
        return np.asarray(mesh.vertices), np.asarray(mesh.triangles), colours

    repaired = o3d.geometry.TriangleMesh(o3d.utility.Vector3dVector(room[0]), o3d.utility.Vector3iVector(room[1]))
    repaired.vertex_colors = o3d.utility.Vector3dVector(room[2])
    truths = [(np.asarray(s.position, float), s.sound) for s in scene.sources]
    heard = []
    for p in placed:
        label = p.name
        if truths:
            q, sound = min(truths, key=lambda t: np.linalg.norm(p.position - t[0]))
            label += f": {sound}, {np.linalg.norm(p.position - q):.2f} m off"
        heard.append(Marker(p.position, label))
    return Walkthrough(arrays(result.scan.mesh), arrays(repaired), surfaces,
                       (scene.camera_path or walkthrough_path(scene)).sample(120), heard,
                       [Marker(q, f"{sound} (truth)") for q, sound in truths],
                       [Track(w.positions, w.levels, f"walk into the {w.kind}") for w in walks],
                       f"vrecho: {scene.name}", scene.room.box)


def run(out: str | Path = "vrecho-out", *, scene: str | Path | Scene | None = None, html: str | Path | None = None,
        browser: bool = True, screenshot: bool = True, seed: int = 0, serve: bool = False, force: bool = False,
        progress: bool = True) -> DemoRun:
    """Run the demo on ``scene`` (the built-in living room when None; a scene JSON path, or a
    :class:`~vrecho.scene.Scene`), writing everything to ``out`` and the walkthrough page to
    ``html`` (default ``out/walkthrough.html``); open it in the browser when ``browser`` and
    a display is there; with ``serve``, also show it on a live meshcat server until Ctrl-C.
    ``screenshot``: write ``out/walkthrough.png`` where Chromium is installed. Prints each step
    and, at the end, the table of decisions (also ``out/summary.md``).

    Parameters
    ----------
    out : str or path
        Output folder (default ``vrecho-out``); created if missing. New, empty, or an earlier
        demo's (:class:`vrecho.io.OutputFolder`); its files appear at once, when all are written.
    scene : str, path or Scene, optional
        The scene (default: the built-in living room).
    html : str or path, optional
        The walkthrough page, a .html file (default ``out/walkthrough.html``).
    browser : bool
        Open the page in a browser.
    screenshot : bool
        Write ``out/walkthrough.png`` where Chromium is installed.
    seed : int
        Seed of the simulated recordings.
    serve : bool
        Also serve the walkthrough live until Ctrl-C.
    force : bool
        Write into a folder that holds files the demo did not write.
    progress : bool
        Progress bars and the step lines (the table is printed either way).

    Returns
    -------
    DemoRun
        The decisions against the truth, the files written and each step's time.

    Raises
    ------
    VrechoError
        For a bad scene file, a scene without glass, mirror or opening, an ``html`` path that is
        not a .html file, a folder that cannot be written (a full disk: nothing is written) or
        holds files the demo did not write (without ``force``).
    """
    from vrecho.classifier import load_classifier  # torch-bound (1.7 s): `vrecho --help` needs none of it

    if scene is None:
        scene = builtin_scene()
    elif not isinstance(scene, Scene):
        scene = load_scene(scene)  # a bad scene is answered before anything is written
    if not scene.discontinuities:
        raise VrechoError(f"scene {scene.name!r} has no glass, mirror or opening: nothing to repair")
    if html is not None and Path(html).suffix.lower() not in (".html", ".htm"):
        raise VrechoError(f"html: expected a .html file, got {html}")
    if html is not None:
        ensure_writable_dir(Path(html).parent)
    with OutputFolder(out, "demo", force=force) as folder, folder.writing() as stage:
        rng = np.random.default_rng(seed)
        seconds, files = {}, {}
        say = print if progress else (lambda *a, **k: None)

        def step(name):
            seconds[name] = time.perf_counter()

        def done(name, what):
            seconds[name] = time.perf_counter() - seconds[name]
            say(f"{name}: {what} ({seconds[name]:.1f} s)", flush=True)

        t_all = time.perf_counter()
        say(f"vrecho demo on {scene.name!r}: {len(scene.discontinuities)} glass, mirror or open surfaces, "
            f"{len(scene.sources)} sound sources; writing to {folder.path}")
        step("scan")
        scan = scan_scene(scene, progress=progress)
        done("scan", f"{len(scan.views)} frames fused into {len(scan.mesh.triangles):,} triangles")
        step("repair")
        result = reconstruct(scan, hear=hear_echoes(scene, seed=seed, progress=progress), decide="echocnn")
        write(result, stage, metrics=SceneTruth(scene).score(result.scan.mesh, result.repaired))
        files.update({k: folder.path / k for k in ("initial.ply", "repaired.ply", "report.json", "before_after.png")})
        done("repair", f"{len(result.holes)} holes, {len(result.surfaces)} surfaces added")
        rows = _hole_rows(scene, result) + [_repair_row(json.loads((stage / "report.json").read_text())["metrics"])]

        step("echoes")
        observations = listen(scene, rng, progress=progress)
        if observations:
            predictions = load_classifier().predict_batch(np.stack([o.frame for o in observations]), FS, emitted=probe())
            figure(scene, observations, stage / "surfaces.png")
            files["surfaces.png"] = folder.path / "surfaces.png"
            atomic_write_text(stage / "echoes.md", table(observations, predictions) + "\n")
            files["echoes.md"] = folder.path / "echoes.md"
        done("echoes", f"{len(observations)} poses facing a surface heard")

        placed = []
        if scene.sources:
            step("sources")
            sim = SceneTruth(scene).captures(rng, n_poses=HEAR_POSES)
            placed = localization.place_sources(sim.captures, bounds=scene.room.box, progress=progress)
            rows += source_rows(scene, placed)
            done("sources", f"{len(placed)} placed from {len(sim.captures)} captures")

        step("headset")
        walks = boundary_walks(scene, rng, progress=progress)
        rows += _walk_rows(scene, walks)
        if walks:
            boundary_figure(walks, stage / "boundary.png")
            files["boundary.png"] = folder.path / "boundary.png"
        done("headset", f"{len(walks)} walks")

        step("usd")
        mesh, surfaces = usd_export.from_reconstruction(result)
        for name in ("scene.usda", "scene.usdz"):
            path = usd_export.write_scene(stage / name, mesh, surfaces, placed)
            problems = usd_export.validate(path)
            errors = [p for p in problems if p.severity == "error"]
            rows.append((name, f"{len(surfaces)} surfaces, {len(placed)} spatial-audio source{'s' * (len(placed) != 1)}",
                         "OpenUSD's validators: no error", not errors))
            files[name] = folder.path / name
        done("usd", "scene.usda (+ WAVs) and scene.usdz")

        step("walkthrough")
        shown = _walkthrough(scene, result, mesh, surfaces, placed, walks)
        page = stage / "walkthrough.html" if html is None else Path(html)
        atomic_write_text(page, walkthrough.static_page(shown))
        files["walkthrough"] = folder.path / "walkthrough.html" if html is None else page
        shot = ""
        if screenshot and chromium.chromium():
            chromium.screenshot(page, stage / "walkthrough.png")
            files["walkthrough.png"] = folder.path / "walkthrough.png"
            shot = ", walkthrough.png"
        done("walkthrough", f"{files['walkthrough']}{shot}")

        run_ = DemoRun(scene, result, placed, walks, rows, files, seconds)
        seconds["total"] = time.perf_counter() - t_all
        right = [r[3] for r in rows if r[3] is not None]
        steps = ", ".join(f"{k} {v:.1f} s" for k, v in seconds.items() if k != "total")
        tail = f"{sum(right)} of {len(right)} decisions right; {seconds['total']:.0f} s in all ({steps})"
        atomic_write_text(stage / "summary.md", run_.table() + "\n\n" + tail + "\n")
        files["summary.md"] = folder.path / "summary.md"
    html = files["walkthrough"]
    print(run_.table())
    print(tail)
    print(f"written to {folder.path}: " + ", ".join(sorted(p.name for p in files.values())))
    if browser:
        if chromium.open_in_browser(html):
            print(f"the walkthrough is open in your browser: {html}")
        else:
            print(f"no display to open a browser on: open {html} in one")
    if serve:
        walkthrough.serve(shown)
    return run_
