"""The meshcat walkthrough of a run: the scan before and after its repair, the camera's path,
the sources heard, and the headset's alerts, in one self-contained page.

Scene tree (each entry a checkbox in meshcat's "Scene" panel, top right):

- ``scan/initial`` (hidden at first) and ``scan/repaired``: the camera's mesh and the repaired
  one, the ceiling cut away so the room is seen from above;
- ``surfaces/<name>``: each discontinuity as vrecho decided it: glass translucent blue, mirrors
  silver and shiny, openings an outline;
- ``camera/path`` and ``camera/device``: the walkthrough's path and the device moving along it
  (meshcat's "Animations" panel replays it);
- ``sources/heard_<k>`` and ``sources/truth_<k>``: placed sources as labelled orange spheres, the
  scene's own (where known) as small grey ones;
- ``boundary/<surface>``: each walk toward a surface, a dot per 10 ms block coloured by the
  headset call's alert (green clear, amber caution, red stop).
"""

from __future__ import annotations

import contextlib
import html
import io
import time
from dataclasses import dataclass, field

import meshcat
import meshcat.geometry as g
import numpy as np

LEVEL_COLOURS = {"clear": (0.15, 0.75, 0.25), "caution": (1.0, 0.65, 0.0), "stop": (0.9, 0.05, 0.05)}
GLASS = 0x7fc8ff
MIRROR = 0xd8dde6
HEARD = 0xff7f0e
TRUTH = 0x606060
OPENING = 0x2ca02c
UNKNOWN = 0x888888
PATH = 0x1f3fbf
ROOT = "/vrecho"  # everything drawn lies under it


@dataclass
class Marker:
    """A labelled point: ``position`` (3,) metres.

    Attributes
    ----------
    position : numpy.ndarray, shape (3,)
        In metres, in the scene's frame (z up).
    label : str
        The text shown beside it.
    """

    position: np.ndarray
    label: str


@dataclass
class Track:
    """A walk's positions (N, 3) and the alert level at each (N,), and its name in the scene tree.

    Attributes
    ----------
    positions : numpy.ndarray, shape (N, 3)
        In metres.
    levels : list of {"clear", "caution", "stop"}
        N alert levels.
    label : str
        Its name in the scene tree.
    """

    positions: np.ndarray
    levels: list[str]
    label: str


@dataclass
class Walkthrough:
    """What the page shows. Meshes are (vertices (N, 3), faces (F, 3), colours (N, 3) or None);
    ``surfaces`` are :class:`usd_export.LabeledSurface`; ``camera`` the path's positions (N, 3)
    and viewing directions (N, 3).

    Attributes
    ----------
    initial, repaired : tuple
        The scan's mesh and the repaired one: vertices (N, 3) in metres, faces (F, 3) int,
        colours (N, 3) in [0, 1] or None.
    surfaces : list of usd_export.LabeledSurface
        Each discontinuity as vrecho decided it.
    camera : tuple of numpy.ndarray
        The path's positions (N, 3) in metres and viewing directions (N, 3).
    heard : list of Marker
        The sources placed from what was heard.
    truth : list of Marker
        The scene's own sources, where known.
    tracks : list of Track
        The headset's walks.
    title : str
        The page's title (default ``vrecho``).
    room : tuple of numpy.ndarray, optional
        The room's box (lo, hi), (3,) each in metres, to frame; default: the path's, 1.5 m
        wider each way.
    """

    initial: tuple
    repaired: tuple
    surfaces: list
    camera: tuple[np.ndarray, np.ndarray]
    heard: list[Marker] = field(default_factory=list)
    truth: list[Marker] = field(default_factory=list)
    tracks: list[Track] = field(default_factory=list)
    title: str = "vrecho"
    room: tuple[np.ndarray, np.ndarray] | None = None  # the room's box (lo, hi) to frame; default: the path's


class _SpriteMaterial(g.GenericMaterial):
    _type = "SpriteMaterial"


class _Sprite(g.Object):
    _type = "Sprite"  # always faces the viewer; three.js' ObjectLoader ignores its geometry


def _label(text: str, colour: str = "black"):
    """A sprite (always facing the viewer) showing ``text``, 1 x 1 before scaling (the picture is
    8 : 1: scale it so)."""
    import matplotlib  # heavy (0.8 s to import): only figures need it

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # once the Agg backend is chosen: no display needed

    fig = plt.figure(figsize=(4, 0.5), dpi=100)
    fig.text(0.5, 0.5, text, ha="center", va="center", fontsize=15, color=colour,
             bbox=dict(boxstyle="round,pad=0.25", fc="white", ec=colour, alpha=0.85))
    buf = io.BytesIO()
    fig.savefig(buf, format="png", transparent=True)
    plt.close(fig)
    material = _SpriteMaterial(map=g.ImageTexture(g.PngImage(buf.getvalue())), transparent=True, depthTest=False)
    return _Sprite(g.Box([1, 1, 1]), material)


def _slug(text: str) -> str:
    return "".join(c if c.isalnum() else "_" for c in text).strip("_")


def _transform(position, scale=(1.0, 1.0, 1.0)) -> np.ndarray:
    t = np.diag([*scale, 1.0])
    t[:3, 3] = position
    return t


def _look(position: np.ndarray, forward: np.ndarray) -> np.ndarray:
    """A pose whose x axis points along ``forward`` (z up)."""
    x = forward / np.linalg.norm(forward)
    y = np.cross([0.0, 0.0, 1.0], x)
    y = y / np.linalg.norm(y) if np.linalg.norm(y) > 1e-6 else np.array([0.0, 1.0, 0.0])
    t = np.eye(4)
    t[:3, :3] = np.c_[x, y, np.cross(x, y)]
    t[:3, 3] = position
    return t


def _device(scale: float = 0.25):
    """A camera frustum (lines) looking along +x."""
    tip = np.zeros(3)
    c = np.array([[1, 0.6, 0.45], [1, -0.6, 0.45], [1, -0.6, -0.45], [1, 0.6, -0.45]]) * scale
    pts = []
    for i in range(4):
        pts += [tip, c[i], c[i], c[(i + 1) % 4]]
    return g.LineSegments(g.PointsGeometry(np.array(pts, np.float32).T), g.LineBasicMaterial(color=0x111111))


def _mesh(vis, path: str, mesh: tuple, visible: bool = True) -> None:
    vertices, faces, colours = mesh
    geometry = g.TriangularMeshGeometry(np.asarray(vertices, np.float32), np.asarray(faces, np.uint32),
                                        color=None if colours is None else np.asarray(colours, np.float32))
    # Front faces only: a wall seen from outside the room vanishes, as in a doll's house.
    vis[path].set_object(geometry, g.MeshLambertMaterial(color=0xffffff if colours is not None else 0xb0b0b0,
                                                         vertexColors=colours is not None, side=0))
    if not visible:
        vis[path].set_property("visible", False)


def _surface(vis, s) -> None:
    polygon = np.asarray(s.polygon, float)
    path = f"{ROOT}/surfaces/{s.name}"
    if s.state == "closed":
        faces = np.array([[0, i, i + 1] for i in range(1, len(polygon) - 1)], np.uint32)
        if s.material == "mirror":
            material = g.MeshPhongMaterial(color=MIRROR, reflectivity=1.0, shininess=200, specular=0xffffff,
                                           emissive=0x202830)
        else:
            material = g.MeshPhongMaterial(color=GLASS, opacity=0.35, shininess=120, specular=0xffffff,
                                           depthWrite=False)
        vis[path].set_object(g.TriangularMeshGeometry(polygon.astype(np.float32), faces), material)
    else:
        loop = np.vstack([polygon, polygon[:1]]).astype(np.float32).T
        vis[path].set_object(g.Line(g.PointsGeometry(loop), g.LineBasicMaterial(color=OPENING if s.state == "open"
                                                                                else UNKNOWN)))
    centre = polygon.mean(axis=0) + [0.0, 0.0, 0.25 + np.ptp(polygon[:, 2]) / 2]
    what = s.material if s.state == "closed" else s.state
    vis[f"{ROOT}/surfaces/{s.name}_label"].set_object(_label(what))
    vis[f"{ROOT}/surfaces/{s.name}_label"].set_transform(_transform(centre, (1.6, 0.2, 1.0)))


def build(vis, w: Walkthrough, *, frames_per_pose: int = 6) -> None:
    """Draw ``w`` into the meshcat visualizer ``vis`` (its scene is replaced).

    Parameters
    ----------
    vis : meshcat.Visualizer
        Its scene, animation and camera are replaced.
    w : Walkthrough
    frames_per_pose : int
        Animation frames (at 30 per second) between two of the camera path's positions
        (default 6).
    """
    import meshcat.animation as anim  # heavy (0.6 s to import): only the walkthrough page needs it

    vis.delete()
    _mesh(vis, f"{ROOT}/scan/initial", w.initial, visible=False)
    _mesh(vis, f"{ROOT}/scan/repaired", w.repaired)
    for s in w.surfaces:
        _surface(vis, s)
    positions, forwards = w.camera
    vis[f"{ROOT}/camera/path"].set_object(g.Line(g.PointsGeometry(np.asarray(positions, np.float32).T),
                                          g.LineBasicMaterial(color=PATH, linewidth=2)))
    vis[f"{ROOT}/camera/device"].set_object(_device())
    vis[f"{ROOT}/camera/device"].set_transform(_look(positions[0], forwards[0]))
    a = anim.Animation(default_framerate=30)
    for i, (p, f) in enumerate(zip(positions, forwards)):
        with a.at_frame(vis, i * frames_per_pose) as frame:
            frame[f"{ROOT}/camera/device"].set_transform(_look(p, f))
    vis.set_animation(a, play=True, repetitions=1000)
    for group, markers, colour, radius in (("heard", w.heard, HEARD, 0.14), ("truth", w.truth, TRUTH, 0.07)):
        for k, m in enumerate(markers):
            path = f"{ROOT}/sources/{group}_{k}"
            vis[path].set_object(g.Sphere(radius), g.MeshPhongMaterial(color=colour))
            vis[path].set_transform(_transform(m.position))
            vis[path + "_label"].set_object(_label(m.label, "#b35900" if group == "heard" else "#404040"))
            vis[path + "_label"].set_transform(_transform(np.asarray(m.position) + [0, 0, 0.35 if group == "heard"
                                                                                     else -0.3], (2.0, 0.25, 1.0)))
    for k, t in enumerate(w.tracks):
        colours = np.array([LEVEL_COLOURS[level] for level in t.levels], np.float32).T
        path = f"{ROOT}/boundary/{k}_{_slug(t.label)}"
        vis[path].set_object(g.Points(g.PointsGeometry(np.asarray(t.positions, np.float32).T, color=colours),
                                      g.PointsMaterial(size=0.06)))
    # meshcat's orbit camera looks at the world's origin: the room is drawn centred on it, and
    # seen from above one side.
    lo, hi = w.room if w.room is not None else (positions.min(axis=0) - 1.5, positions.max(axis=0) + 1.5)
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    vis[ROOT].set_transform(_transform(-np.r_[(lo + hi)[:2] / 2, 0.5]))
    span = (hi - lo)[:2]
    offset = np.array([0.1 * span[0], -0.75 * span[1], 0.95 * max(span)])
    vis["/Cameras/default/rotated/<object>"].set_property("position", [offset[0], offset[2], -offset[1]])
    vis["/Grid"].set_property("visible", False)
    vis["/Axes"].set_property("visible", False)


LEGEND = """<div id="vrecho-legend" style="position:absolute;left:12px;bottom:12px;padding:8px 12px;
background:rgba(255,255,255,0.88);font:13px/1.5 sans-serif;border-radius:6px;max-width:360px">
<b>{title}</b><br>
<span style="color:#{clear}">&#9679;</span> <span style="color:#{caution}">&#9679;</span>
<span style="color:#{stop}">&#9679;</span> headset alert on each walk: clear, caution, stop<br>
<span style="color:#{heard:06x}">&#9679;</span> source placed from what the headset heard,
<span style="color:#{truth:06x}">&#9679;</span> true source<br>
<span style="color:#{glass:06x}">&#9632;</span> glass, <span style="color:#aab">&#9632;</span> mirror (repaired),
<span style="color:#{opening:06x}">&#9633;</span> opening; <span style="color:#{path:06x}">&#8212;</span> camera path<br>
Open Controls &#8594; Scene &#8594; vrecho &#8594; scan: toggle the initial and repaired scan;
Animations: replay the walk.</div>"""


def static_page(w: Walkthrough) -> str:
    """The walkthrough as one self-contained HTML page (meshcat's viewer and the scene inlined,
    a legend; no server, no network).

    Parameters
    ----------
    w : Walkthrough

    Returns
    -------
    str
        The page's HTML, titled ``w.title``.
    """
    with _server() as vis:
        build(vis, w)
        page = vis.static_html()
    page = page.replace("<title>MeshCat</title>", f"<title>{html.escape(w.title)}</title>", 1)
    return page.replace("</body>", LEGEND.format(
        title=html.escape(w.title), heard=HEARD, truth=TRUTH, glass=GLASS, opening=OPENING, path=PATH,
        **{k: "".join(f"{round(255 * c):02x}" for c in rgb) for k, rgb in LEVEL_COLOURS.items()}) + "</body>", 1)


@contextlib.contextmanager
def _server():
    with contextlib.redirect_stdout(io.StringIO()):  # meshcat prints its server's address
        vis = meshcat.Visualizer()
    try:
        yield vis
    finally:
        vis.window.server_proc.kill()  # vis.close() raises in meshcat 0.3.2 (NOTES.md)
        vis.window.server_proc.wait()


def serve(w: Walkthrough, *, wait=None) -> None:
    """Show ``w`` on a live meshcat server (its address printed) until interrupted (Ctrl-C) or,
    with ``wait``, until ``wait()`` returns.

    Parameters
    ----------
    w : Walkthrough
    wait : callable, optional
        Called with no argument; the server stops when it returns.
    """
    with _server() as vis:
        build(vis, w)
        print(f"the walkthrough is served at {vis.url()} (Ctrl-C to stop)", flush=True)
        try:
            if wait is not None:
                wait()
            else:
                while True:
                    time.sleep(3600)
        except KeyboardInterrupt:
            pass
