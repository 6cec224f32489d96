"""``vrecho reconstruct`` and ``vrecho export``: a scan (a user's, or a scene's simulated one)
repaired, and written as meshes and a report, or as an OpenUSD stage."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np

import localization
import usd_export

from ..errors import VrechoError, check_count
from ..io import OutputFolder, atomic_write_text, write_mesh
from ..reconstruct import LABELS, VARIANTS, Reconstruction
from ..reconstruct import reconstruct as repair_scan
from .figures import before_after
from .sources import Source, open_source, resolve

LABEL_CHOICES = (*LABELS, "oracle")
"""Who decides what each hole is: a decider of :data:`vrecho.reconstruct.LABELS`, or ``oracle``,
the truth of a simulated scene."""
SOURCE_CHOICES = ("none", "truth", "heard")


def _repaired(source: Source, labels: str, variant: str) -> Reconstruction:
    """A source's scan reconstructed and repaired, its holes decided by ``labels`` (checked by the
    command: ``oracle`` only where the source has a scene's truth)."""
    decide = source.truth.oracle() if labels == "oracle" else labels
    return repair_scan(source.scan, hear=source.hear, decide=decide, variant=variant)


def _check(labels: str, variant: str, n_frames: int, seed: int) -> None:
    if labels not in LABEL_CHOICES:
        raise VrechoError(f"labels: expected one of {LABEL_CHOICES}, got {labels!r}")
    if variant not in VARIANTS:
        raise VrechoError(f"variant: expected one of {VARIANTS}, got {variant!r}")
    check_count(n_frames, "frames", 1000, 2)
    check_count(seed, "seed", 2**32 - 1, 0)


def reconstruct(source: str | Path, out: str | Path, *, labels: str = "echocnn", variant: str = "simplified",
                n_frames: int = 60, seed: int = 0, save_scan: bool = False, force: bool = False,
                progress: bool = True) -> Reconstruction:
    """``vrecho reconstruct``: scan (or load) a source, repair it, write the results, print a summary.

    Parameters
    ----------
    source : str or path
        ``builtin`` (the living room), a scene JSON file, or a scan folder
        (:func:`vrecho.reconstruct.load_scan`); checked before anything is written, but for a
        scan folder's contents, read (and checked) once ``out`` is made.
    out : path
        Output folder: ``initial.ply``, ``repaired.ply``, ``report.json`` (surfaces, holes,
        decisions with their confidences and per-frame inferences, times; for a scene also the
        metrics against its truth), ``before_after.png`` and, with ``save_scan``, ``scan/`` (the
        scan-folder format). New, empty, or an earlier run's of this command
        (:class:`vrecho.io.OutputFolder`); all files appear at once, when all are written.
    labels : {"echocnn", "echocnn-only", "oracle"}
        Who decides what each hole is (:data:`LABEL_CHOICES`).
    variant : {"simplified", "per_vertex"}
        Algorithm 1's fill.
    n_frames : int
        Walkthrough frames of a scene's simulated scan.
    seed : int
        Seed of a scene's simulated recordings.
    force : bool
        Write into a folder that holds files this command did not write.
    progress : bool
        Progress bars.

    Returns
    -------
    Reconstruction
        The scan, its holes, the decisions and the repaired mesh.

    Raises
    ------
    VrechoError
        For unknown ``labels`` or ``variant``, frames outside 2 to 1000, a source that is none of the
        above or cannot be read, ``labels="oracle"`` on a scan folder, an ``out`` that cannot
        be written (a full disk: nothing is written) or holds files this command did not write
        (without ``force``).

    Examples
    --------
    A source that is none of the three is refused before anything is written:

    >>> try:
    ...     reconstruct("no-such-scene.json", "out")
    ... except VrechoError as e:
    ...     print(e)
    scene: no-such-scene.json is neither 'builtin', a scene JSON file nor a scan folder
    """
    _check(labels, variant, n_frames, seed)
    spec = resolve(source)  # bad input answered before anything is written
    if labels == "oracle" and isinstance(spec, Path):
        raise VrechoError("labels='oracle' needs the scene's truth")
    with OutputFolder(out, "reconstruct", force=force) as folder:
        src = open_source(spec, n_frames=n_frames, seed=seed, progress=progress)
        result = _repaired(src, labels, variant)
        metrics = None if src.truth is None else src.truth.score(result.scan.mesh, result.repaired)
        with folder.writing() as stage:
            write(result, stage, metrics=metrics, save_scan=save_scan)
    out = folder.path
    print(summary(result))
    print(f"{len(result.surfaces)} surfaces added; discontinuities and repair "
          f"{result.seconds['total_without_hearing']:.1f} s")
    print(f"written to {out}: initial.ply, repaired.ply, report.json, before_after.png" + (", scan/" if save_scan else ""))
    return result


def write(result: Reconstruction, out: Path, *, metrics: dict | None = None, save_scan: bool = False) -> None:
    """A run's files in ``out``: ``initial.ply``, ``repaired.ply``, ``report.json`` (with
    ``metrics``, a repair's against the truth, where given), ``before_after.png`` and, with
    ``save_scan``, ``scan/``.

    Parameters
    ----------
    result : Reconstruction
        The repair.
    out : pathlib.Path
        An existing, writable folder (an :class:`~vrecho.io.OutputFolder`'s staging folder).
    metrics : dict, optional
        The repair's metrics against a scene's truth.
    save_scan : bool
        Also write the scan (the scan-folder format).
    """
    scan = result.scan
    write_mesh(out / "initial.ply", scan.mesh)
    write_mesh(out / "repaired.ply", result.repaired)
    report = result.report()
    if metrics is not None:
        report["metrics"] = metrics
    atomic_write_text(out / "report.json", json.dumps(report, indent=1, default=float) + "\n")
    before_after(result, out / "before_after.png")
    if save_scan:
        scan.save(out / "scan")


def summary(result: Reconstruction) -> str:
    """A table of the holes and what was done, for people.

    Parameters
    ----------
    result : Reconstruction

    Returns
    -------
    str
        A Markdown table, a row per hole: its wall, area in m2, decision, material, p(closed),
        frames heard and the action taken.
    """
    lines = ["| hole | wall | area m2 | decision | material | p(closed) | frames | action |", "|---|---|---|---|---|---|---|---|"]
    for h in result.report()["holes"]:
        d, a = h["decision"], h["action"]
        act = ("filled" if a["filled"] else "left open") + (f", {a['phantom_triangles_removed']} phantom triangles removed"
                                                           if a["phantom_triangles_removed"] else "")
        lines.append(f"| {h['id']} | {h['wall']} | {h['area_m2']:.2f} | {d['state']} | {d['material'] or '-'} | "
                     f"{d['p_closed']:.3f} | {len(d['frames'])} | {act} |")
    return "\n".join(lines)


def export(source: str | Path, out: str | Path, *, labels: str = "echocnn", variant: str = "simplified",
           sources: str = "none", n_frames: int = 60, seed: int = 0, force: bool = False, progress: bool = True) -> Path:
    """``vrecho export``: reconstruct and repair a source as :func:`reconstruct` does, and write it
    as an OpenUSD stage (:func:`usd_export.write_scene`; refused while OpenUSD's validators report
    an error, and nothing is written then).

    Parameters
    ----------
    source : str or path
        As for :func:`reconstruct`.
    out : path
        The stage: a ``.usda``, ``.usdc``, ``.usd`` or ``.usdz`` path. A file there, or a layer's
        ``<stem>_audio/`` folder, is replaced only where an earlier export wrote it (or with
        ``force``): the output-folder policy of :class:`vrecho.io.OutputFolder`, for one file.
    force : bool
        Replace a file (and audio folder) at ``out`` that vrecho did not write.
    labels, variant, n_frames, seed, progress
        As for :func:`reconstruct`.
    sources : str
        The sound sources: ``none``; ``truth`` (a scene's own sources where they are); ``heard``
        (a scene's sources recorded by the headset's 4 microphones along the walkthrough, then
        located and separated by :func:`localization.place_sources`; each one's error against
        the truth is printed); or a JSON file of placed sources (:func:`usd_export.sources_from_json`).

    Returns
    -------
    pathlib.Path
        The stage written.

    Raises
    ------
    VrechoError
        For an ``out`` of another suffix or in a folder that does not exist, ``sources`` that is
        none of the above or a sources file that cannot be read, a bad ``labels``, ``variant`` or
        frame count, a bad source, ``truth``, ``heard`` or ``oracle`` on a scan folder, a file at
        ``out`` that vrecho did not write (without ``force``), or a stage with validation errors.
    """
    out = usd_export.check_target(out)  # every check before the work, not after
    audio_dir = out.with_name(f"{out.stem}_audio")
    ours = usd_export.is_vrecho_stage(out)  # read once: a stage can be large
    theirs = [p for p in (out, audio_dir) if p.exists() and not ours]
    if theirs and not force:
        raise VrechoError(f"out: {', '.join(map(str, theirs))} not written by vrecho export; choose another path, "
                          "or pass --force to replace it")
    from_file = None
    if sources not in SOURCE_CHOICES:
        if not Path(sources).is_file():
            raise VrechoError(f"sources: expected 'none', 'truth', 'heard' or a JSON file, got {sources!r}")
        from_file = usd_export.sources_from_json(sources)
        # their WAVs read now, not after minutes of work, and once: the stage takes the samples
        from_file = [replace(s, signal=x, fs=fs) for s, (x, fs) in zip(from_file, usd_export.check_sources(from_file))]
    _check(labels, variant, n_frames, seed)
    spec = resolve(source)
    if sources in ("truth", "heard") and isinstance(spec, Path):
        raise VrechoError(f"sources: {sources!r} needs a scene (builtin or a scene JSON), not a scan folder")
    if labels == "oracle" and isinstance(spec, Path):
        raise VrechoError("labels='oracle' needs the scene's truth")
    src = open_source(spec, n_frames=n_frames, seed=seed, progress=progress)
    result = _repaired(src, labels, variant)
    room, surfaces = usd_export.from_reconstruction(result)
    if sources == "none":
        placed = []
    elif sources == "truth":
        placed = usd_export.sources_from_scene(src.scene)
    elif sources == "heard":
        placed = _heard(src, seed, progress)
    else:
        placed = from_file
    path = usd_export.write_scene(out, room, surfaces, placed)  # refuses a stage with validation errors
    problems = usd_export.validate(path)  # the warnings for the user (write_scene refused any error)
    for p in problems:
        print(f"  {p}")
    print(f"{path}: {len(room[1]):,} room triangles, {len(surfaces)} surfaces "
          f"({', '.join(f'{s.name} {s.state}' for s in surfaces) or 'none'}), {len(placed)} sound sources; "
          f"OpenUSD's validators: no errors, {len(problems)} other findings")
    return path


def _heard(source: Source, seed: int, progress: bool) -> list:
    """The scene's sources heard by the headset along its walkthrough, located and separated."""
    sim = source.truth.captures(np.random.default_rng(seed))
    placed = localization.place_sources(sim.captures, bounds=source.scene.room.box, progress=progress)
    if not placed:
        print("  no source heard: none stands clear of the microphones' own noise")
    for p in placed:
        err = min(np.linalg.norm(p.position - s.position) for s in sim.sources)
        print(f"  {p.name} at {np.round(p.position, 2).tolist()} m (+/- {p.uncertainty_m or float('nan'):.2f} m, "
              f"confidence {p.confidence:.2f}); nearest true source {err:.2f} m away")
    return placed
