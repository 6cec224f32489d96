"""From vrecho's reconstruction to what :func:`usd_export.write_scene` takes."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from localization import PlacedSource
from vrecho.errors import VrechoError
from vrecho.signals import FS, emitted_sound, pulse_train

from .stage import LabeledSurface


def from_reconstruction(result) -> tuple[tuple[np.ndarray, np.ndarray, np.ndarray], list[LabeledSurface]]:
    """The room mesh without the surfaces the repair added, and every discontinuity as a
    :class:`LabeledSurface`.

    Parameters
    ----------
    result : vrecho.reconstruct.Reconstruction
        A reconstruction with its repaired mesh, holes, decisions and added surfaces.

    Returns
    -------
    room : tuple of numpy.ndarray
        (vertices (N, 3) metres, faces (F, 3) int, colours (N, 3) in [0, 1]; 0.6 grey where the
        mesh has none), as :func:`usd_export.write_scene` takes it.
    surfaces : list of LabeledSurface
        One per hole, in order: added surfaces with their polygon (named
        ``<material>_<k>``), openings (``opening_<k>``) and holes no frame listened to
        (``hole_<k>``, state "unknown") with the hole's outline, facing the room. ``depth_m`` is
        the median distance the listening frames gave (None for oracle labels).
    """
    mesh = result.repaired
    vertices = np.asarray(mesh.vertices)
    faces = np.asarray(mesh.triangles)
    colours = np.asarray(mesh.vertex_colors) if mesh.has_vertex_colors() else np.full((len(vertices), 3), 0.6)
    keep = np.ones(len(faces), bool)
    if result.surfaces:
        rows = lambda a: np.ascontiguousarray(a, dtype=np.int64).view(np.dtype((np.void, 24))).ravel()  # noqa: E731
        keep = ~np.isin(rows(faces), rows(np.vstack([s.triangles for s in result.surfaces])))
    used = np.unique(faces[keep])
    index = np.full(len(vertices), -1)
    index[used] = np.arange(len(used))
    room = (vertices[used], index[faces[keep]], colours[used])

    filled = {s.hole: s for s in result.surfaces}
    surfaces = []
    for k, (hole, d) in enumerate(zip(result.holes, result.decisions)):
        depths = [r["depth_m"] for r in d.frames if r.get("depth_m") is not None]
        depth = float(np.median(depths)) if depths else None
        if d.state == "closed":  # the repair fills every closed hole
            s = filled[k]
            surfaces.append(LabeledSurface(f"{s.material}_{k}", s.polygon, "closed", s.material, depth, d.confidence))
        else:
            polygon = hole.polygon()
            n = np.cross(polygon[1] - polygon[0], polygon[2] - polygon[0])
            if n @ hole.plane.normal < 0:  # face the room
                polygon = polygon[::-1]
            name = "opening" if d.state == "open" else "hole"  # unknown: no frame listened to it
            surfaces.append(LabeledSurface(f"{name}_{k}", polygon, d.state, None, depth, d.confidence))
    return room, surfaces


def sources_from_scene(scene, *, seconds: int = 10) -> list:
    """The scene's own sound sources at their true positions, each playing its sound.

    The truth, standing in where no localization ran (``vrecho export --sources truth``).

    Parameters
    ----------
    scene : vrecho.scene.Scene
        The scene whose sources are taken.
    seconds : int
        The signals' length in seconds (default 10): PROTOCOL's 100 ms sound once a second, at
        the source's gain.

    Returns
    -------
    list of localization.PlacedSource
        One per source, named ``<sound>_<k>``, at :data:`vrecho.signals.FS` (44.1 kHz),
        confidence 1.
    """
    out = []
    for k, s in enumerate(scene.sources):
        signal = pulse_train(emitted_sound(s.sound, FS, np.random.default_rng(k)), seconds) * 10 ** (s.gain_db / 20)
        out.append(PlacedSource(np.asarray(s.position, float), signal, FS, 1.0, f"{s.sound}_{k}"))
    return out


def sources_from_json(path) -> list:
    """Placed sources listed in a JSON file.

    Parameters
    ----------
    path : str or pathlib.Path
        A JSON file holding ``[{"name", "position": [x, y, z] (metres, Z up), "wav": path
        (relative to the file), "confidence"?, "uncertainty_m"?}, ...]``.

    Returns
    -------
    list of localization.PlacedSource
        One per item, its signal the WAV's path (read, and its rate with it, when the stage is
        written; ``fs`` is 0 until then); unnamed items are ``source_<i>``.

    Raises
    ------
    VrechoError
        For a file that cannot be read as JSON, that holds no list, or an item without
        "position" and "wav".
    """
    path = Path(path)
    try:
        items = json.loads(path.read_text())
    except (OSError, ValueError) as e:
        raise VrechoError(f"sources: cannot read {path} as JSON ({e})") from None
    if not isinstance(items, list):
        raise VrechoError(f"sources: {path} must hold a list of sources")
    out = []
    for i, d in enumerate(items):
        if not isinstance(d, dict) or "position" not in d or "wav" not in d:
            raise VrechoError(f"sources: {path} item {i} needs 'position' and 'wav'")
        out.append(PlacedSource(np.asarray(d["position"], float), path.parent / d["wav"], 0,
                                float(d.get("confidence", 1.0)), str(d.get("name", f"source_{i}")),
                                d.get("uncertainty_m")))
    return out
