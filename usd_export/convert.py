"""From vrecho's reconstruction to what :func:`usd_export.write_scene` takes."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import soundfile as sf

from localization import PlacedSource
from vrecho.device import REACH_M
from vrecho.errors import (VrechoError, check_field, check_keys, check_list, check_number, check_text, check_vector,
                           read_json)
from vrecho.signals import FS, emitted_sound, pulse_train

from .stage import LabeledSurface

MAX_SOURCES = 64
"""The most sources a sources file lists."""
WAV_MAX_S = 600
"""The longest WAV a source may play, in seconds (the stage reads it whole)."""


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
    """Placed sources listed in a JSON file, every field and WAV header checked (no WAV is read
    whole): call it before any long work.

    Parameters
    ----------
    path : str or pathlib.Path
        A JSON file holding up to :data:`MAX_SOURCES` sources: ``[{"name"?, "position": [x, y, z]
        (metres, Z up, each within :data:`REACH_M`), "wav": path (relative to the file),
        "confidence"? (0 to 1, default 1), "uncertainty_m"? (0 to :data:`REACH_M`, or null)},
        ...]``; no other fields.

    Returns
    -------
    list of localization.PlacedSource
        One per item, its signal the WAV's path (read when the stage is written) and ``fs`` the
        WAV's rate; unnamed items are ``source_<i>``.

    Raises
    ------
    VrechoError
        Naming the file and the item's field: a file :func:`vrecho.errors.read_json` refuses, no
        list, too many items, a missing, unknown or out-of-range field, or a WAV that does not
        exist, is not audio, has no samples, a rate outside 8000 to 192000 Hz or is longer than
        :data:`WAV_MAX_S`.
    """
    path = Path(path)
    items = read_json(path, "sources file", expect=list)
    try:
        check_list(items, "sources", hi=MAX_SOURCES)
        return [_placed(d, f"sources[{i}]", path.parent, f"source_{i}") for i, d in enumerate(items)]
    except VrechoError as e:
        raise VrechoError(f"sources file {path}: {e}") from None


def _placed(d, where: str, folder: Path, name: str) -> PlacedSource:
    check_keys(d, ("name", "position", "wav", "confidence", "uncertainty_m"), where)
    position = check_vector(check_field(d, "position", where), f"{where}.position", lo=-REACH_M, hi=REACH_M)
    wav = folder / check_text(check_field(d, "wav", where), f"{where}.wav", max_len=1000)
    if not wav.is_file():
        raise VrechoError(f"{where}.wav: {wav} is not a file")
    try:
        info = sf.info(str(wav))
    except (RuntimeError, sf.LibsndfileError) as e:
        raise VrechoError(f"{where}.wav: cannot read {wav} as audio ({e})") from None
    if not 8000 <= info.samplerate <= 192000 or not 0 < info.frames <= WAV_MAX_S * info.samplerate:
        raise VrechoError(f"{where}.wav: {wav} must have a rate from 8000 to 192000 Hz and 1 sample to {WAV_MAX_S} s, "
                          f"has {info.frames} samples at {info.samplerate} Hz")
    uncertainty = check_field(d, "uncertainty_m", where, None)
    return PlacedSource(position, wav, int(info.samplerate),
                        check_number(check_field(d, "confidence", where, 1.0), f"{where}.confidence", lo=0.0, hi=1.0),
                        check_text(check_field(d, "name", where, name), f"{where}.name"),
                        None if uncertainty is None else check_number(uncertainty, f"{where}.uncertainty_m", lo=0.0,
                                                                      hi=REACH_M))
