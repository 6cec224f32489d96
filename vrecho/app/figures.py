"""The commands' figures: the repair before and after (``before_after.png``), a capture's
pulses and answers (``capture.png``), and a mesh drawn by ray casting (headless: no OpenGL).
"""

from __future__ import annotations

import copy
from pathlib import Path

import numpy as np

from ..camera import Camera, camera_pose
from ..capture.onsets import Onsets
from ..reconstruct import Reconstruction


def render_mesh(mesh, pose: np.ndarray, *, camera: Camera = Camera()) -> np.ndarray:
    """An RGB picture (H, W, 3) in [0, 1] of an open3d triangle mesh from a camera-to-world
    ``pose``: vertex colours, lit from the camera (headless: ray casting, no OpenGL).

    Parameters
    ----------
    mesh : open3d.geometry.TriangleMesh
        Grey (0.7) where it has no vertex colours.
    pose : numpy.ndarray, shape (4, 4)
        Camera-to-world, OpenCV axes, metres (:func:`vrecho.camera.camera_pose`).
    camera : Camera
        Image size and field of view (default 320 x 240 pixels, 65 degrees).

    Returns
    -------
    numpy.ndarray, shape (H, W, 3), float
        White where no triangle is hit.
    """
    import open3d as o3d  # heavy (1.2 s to import): only where meshes are made or ray-cast

    rc = o3d.t.geometry.RaycastingScene()
    rc.add_triangles(o3d.t.geometry.TriangleMesh.from_legacy(mesh))
    rays = rc.create_rays_pinhole(o3d.core.Tensor(camera.intrinsics), o3d.core.Tensor(np.linalg.inv(pose)),
                                  camera.width, camera.height)
    ans = rc.cast_rays(rays)
    hit = np.isfinite(ans["t_hit"].numpy())
    prim = ans["primitive_ids"].numpy()
    normals = ans["primitive_normals"].numpy()
    dirs = rays.numpy()[..., 3:]
    dirs /= np.linalg.norm(dirs, axis=-1, keepdims=True)
    tris = np.asarray(mesh.triangles)
    colours = np.asarray(mesh.vertex_colors) if mesh.has_vertex_colors() else np.full((len(mesh.vertices), 3), 0.7)
    img = np.ones((camera.height, camera.width, 3))
    p = prim[hit]
    light = 0.35 + 0.65 * np.abs(np.sum(normals[hit] * dirs[hit], axis=-1))
    img[hit] = colours[tris[p]].mean(axis=1) * light[:, None]
    return np.clip(img, 0, 1)


def before_after(result: Reconstruction, path: str | Path) -> Path:
    """A figure of the initial and the repaired mesh from two viewpoints (over the shoulder of
    the walkthrough, and from above), side by side.

    Parameters
    ----------
    result : Reconstruction
        A repair (:func:`vrecho.reconstruct.reconstruct`).
    path : str or path
        The PNG to write.

    Returns
    -------
    pathlib.Path
        ``path``.
    """
    import matplotlib  # heavy (0.8 s to import): only figures need it

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # once the Agg backend is chosen: no display needed

    cams = result.scan.cameras
    centre = cams.mean(axis=0)
    v = np.asarray(result.scan.mesh.vertices)
    hi = np.percentile(v, 98, axis=0)
    corner = np.array([hi[0], hi[1], 0.0])
    views = [camera_pose(np.r_[(corner + 0.25 * (centre - corner))[:2], hi[2] - 0.1],
                         np.r_[(centre - corner)[:2], -0.35 * np.linalg.norm((centre - corner)[:2])]),
             camera_pose(np.r_[centre[:2], hi[2] + 9.0], [0, 0, -1.0], up=(0, 1.0, 0))]
    fig, axes = plt.subplots(2, 2, figsize=(12, 9))
    for row, pose in enumerate(views):
        for col, (mesh, title) in enumerate(((result.scan.mesh, "initial scan"), (result.repaired, "repaired"))):
            if row == 1:
                mesh = below(mesh, hi[2] - 0.3)
            ax = axes[row, col]
            ax.imshow(render_mesh(mesh, pose, camera=Camera(480, 360, 80 if row == 0 else 60)))
            ax.set_title(title if row == 0 else f"{title}, from above (ceiling cut away)")
            ax.axis("off")
    fig.tight_layout()
    path = Path(path)
    fig.savefig(path, dpi=80)
    plt.close(fig)
    return path


def below(mesh, z_max: float):
    """A copy of a mesh without the triangles above ``z_max`` (the ceiling, for a view from above).

    Parameters
    ----------
    mesh : open3d.geometry.TriangleMesh
        Left as it is.
    z_max : float
        Height in metres; a triangle with a vertex above it goes.

    Returns
    -------
    open3d.geometry.TriangleMesh
    """
    out = copy.deepcopy(mesh)
    out.remove_triangles_by_mask(np.asarray(mesh.vertices)[np.asarray(mesh.triangles)][:, :, 2].max(axis=1) > z_max)
    return out


def capture_figure(x, fs, onsets: Onsets, rows: list[dict], path, decisions=None) -> None:
    """``capture.png``: a capture's recording with the pulses found (and those missing), and
    EchoCNN's answer for each frame against time.

    Parameters
    ----------
    x : numpy.ndarray, shape (n,)
        The recording.
    fs : int
        Its sample rate in Hz.
    onsets : Onsets
        The pulses found (:func:`vrecho.capture.onsets.find_onsets`).
    rows : list of dict
        One per frame, ``frames.csv``'s columns (``time_s``, ``open``, ``p_open``, ``depth_m``;
        ``hole`` for a posed capture).
    path : str or path
        The PNG to write.
    decisions : list of Decision, optional
        A posed capture's decisions, one per hole: the frames are then coloured by the hole they
        face.
    """
    import matplotlib  # heavy (0.8 s to import): only figures need it

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # once the Agg backend is chosen: no display needed

    t = np.arange(len(x)) / fs
    fig, (a, b) = plt.subplots(2, 1, figsize=(13, 5), sharex=True)
    step = max(len(x) // 200_000, 1)
    a.plot(t[::step], x[::step], lw=0.4, color="0.3")
    for s in onsets.seconds:
        a.axvline(s, color="tab:green", lw=0.8)
    for m in onsets.missing / fs:
        a.axvline(m, color="tab:red", lw=1.2, ls="--")
    a.set_ylabel("recording")
    a.set_title(f"{len(onsets.samples)} pulses found (green), {len(onsets.missing)} missing (red); "
                f"period {onsets.period_s:.5f} s")
    times = np.array([r["time_s"] for r in rows])
    p_closed = np.array([1 - r["p_open"] for r in rows])
    b.plot(times, [r["depth_m"] / 3 for r in rows], color="tab:gray", lw=0.8, label="depth / 3 m")
    if decisions is None:
        b.scatter(times, p_closed, c=["tab:orange" if r["open"] else "tab:blue" for r in rows], s=14,
                  label="p(closed): blue closed, orange open")
    else:  # a posed capture: the frames coloured by the hole they face, and what the hole was judged
        hole = np.array([r.get("hole", -1) if r.get("hole", "") != "" else -1 for r in rows])
        b.scatter(times[hole < 0], p_closed[hole < 0], color="0.7", s=10, label="p(closed), facing no hole")
        for h in sorted(set(hole[hole >= 0])):
            d = decisions[h]
            b.scatter(times[hole == h], p_closed[hole == h], color=plt.cm.tab10(h % 10), s=16,
                      label=f"hole {h}: {d.state}{' ' + d.material if d.material else ''} (p {d.p_closed:.2f})")
    b.set_ylim(-0.05, 1.05)
    b.set_xlabel("time (s)")
    b.set_ylabel("EchoCNN")
    b.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=7, frameon=False)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
