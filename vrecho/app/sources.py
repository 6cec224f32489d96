"""What ``vrecho reconstruct`` and ``vrecho export`` run on: a user's scan folder, or a scene
(``builtin``, or a scene JSON file) that a simulator turns into a scan and recordings.

The simulator is a plugin: it is found by its entry point in the group :data:`SIMULATORS`
(vrecho's own is :func:`vrecho.sim.scans.simulate_scene`, declared in ``pyproject.toml``), and the
commands are written against what it gives (:class:`Source`), never against its modules.
"""

from __future__ import annotations

from dataclasses import dataclass
from importlib import metadata
from pathlib import Path
from typing import Callable

from ..errors import VrechoError
from ..reconstruct import Echoes, Scan, load_scan
from ..scene import Scene, builtin_scene, load_scene

SIMULATORS = "vrecho.simulators"
"""The entry-point group of simulators: ``simulate(scene, *, n_frames, seed, progress)`` returns
the scene's scan, ``hear(views, frames) -> Echoes`` and the truth (``scene``, ``oracle()``,
``score(initial, repaired)``, ``captures(rng)``)."""


@dataclass
class Source:
    """A scan to reconstruct.

    Attributes
    ----------
    scan : Scan
        The frames and the initial mesh.
    hear : callable, optional
        ``hear(views, frames) -> Echoes``: what the device hears at frames the scan holds no
        recordings of (a simulated scene's; None for a user's scan: its ``echoes.npz`` is all
        there is).
    truth : object, optional
        The simulator's truth of a scene (None for a user's scan): ``scene``, ``oracle()``,
        ``score(initial, repaired)``, ``captures(rng)``.
    """

    scan: Scan
    hear: Callable[[list, object], Echoes] | None = None
    truth: object = None

    @property
    def scene(self) -> Scene | None:
        """The simulated scene (None for a user's scan)."""
        return None if self.truth is None else self.truth.scene


def resolve(source: str | Path) -> Scene | Path:
    """What the command line names, checked before any work: ``builtin`` (the living room) or a
    scene JSON file gives its :class:`~vrecho.scene.Scene`; a folder is a user's scan
    (:func:`~vrecho.reconstruct.load_scan`), or a folder with one in ``scan/`` (what ``vrecho
    capture --poses`` writes). A folder's contents are not read here: :func:`open_source` reads
    them.

    Parameters
    ----------
    source : str or path
        ``builtin``, a scene JSON file or a folder.

    Returns
    -------
    Scene or pathlib.Path
        The scene, or the scan folder (``source``, or ``source/scan`` where only that holds a
        ``frames.npz``).

    Raises
    ------
    VrechoError
        When ``source`` is none of these, or its scene JSON is not valid.

    Examples
    --------
    >>> resolve("builtin").name
    'living_room'
    """
    source = Path(source)
    if str(source) == "builtin":
        return builtin_scene()
    if source.is_dir():  # a scan folder, or the output of `vrecho capture` or `reconstruct --save-scan` holding one
        return source / "scan" if not (source / "frames.npz").exists() and (source / "scan" / "frames.npz").exists() \
            else source
    if source.is_file():
        return load_scene(source)
    raise VrechoError(f"scene: {source} is neither 'builtin', a scene JSON file nor a scan folder")


def simulator() -> Callable:
    """The installed simulator's entry point (vrecho's own when there are several).

    Returns
    -------
    callable
        ``simulate(scene, *, n_frames, seed, progress) -> (scan, hear, truth)`` (see
        :data:`SIMULATORS`).

    Raises
    ------
    VrechoError
        When no simulator is installed.
    """
    found = sorted(metadata.entry_points(group=SIMULATORS), key=lambda e: e.name != "vrecho")
    if not found:
        raise VrechoError(f"scene: no simulator is installed (entry point group {SIMULATORS!r}); "
                          "install vrecho (./install.sh) or give a scan folder")
    return found[0].load()


def open_source(source: str | Path | Scene, *, n_frames: int = 60, seed: int = 0, progress: bool = False) -> Source:
    """The scan of a source (see :func:`resolve`; a scene is scanned by the simulator with
    ``n_frames`` walkthrough frames, its recordings drawn from ``seed``).

    Parameters
    ----------
    source : str, path or Scene
        As for :func:`resolve`, or what it returned.
    n_frames : int
        Walkthrough frames of a scene's simulated scan (default 60, at least 2: the simulator
        says so).
    seed : int
        Seed of a scene's simulated recordings.
    progress : bool
        Show progress bars (default False).

    Returns
    -------
    Source
        A scan folder's with ``hear`` and ``truth`` None; a scene's with both.

    Raises
    ------
    VrechoError
        For a source :func:`resolve` refuses, a scan folder that cannot be read, or, for a
        scene, no simulator installed or fewer than 2 frames.
    """
    if not isinstance(source, Scene):
        source = resolve(source)
    if isinstance(source, Path):
        return Source(load_scan(source, progress=progress))
    scan, hear, truth = simulator()(source, n_frames=n_frames, seed=seed, progress=progress)
    return Source(scan, hear, truth)
