"""The phone's scan of a scene: frames rendered along a walkthrough, fused into a mesh, and
what the device hears at the frames that face a hole (vrecho's probe through the scene's room).
"""

from __future__ import annotations

import dataclasses
import functools
from typing import Callable

import numpy as np
from tqdm import tqdm

from ..camera import Camera, View, camera_pose, device_pose
from ..errors import VrechoError
from ..reconstruct.scan import Echoes, Scan, fuse
from ..scene import Scene
from ..signals import FS, probe
from .acoustics import device_direct_amplitude, device_impulse_response, record_pulse, recording_conditions
from .render import World, render_view
from .scenes import walkthrough_path
from .scoring import SceneTruth


def walkthrough(scene: Scene, *, n_frames: int = 60, camera: Camera = Camera(), progress: bool = False) -> list[View]:
    """Frames rendered along the scene's camera path, evenly spaced in time.

    Parameters
    ----------
    scene : Scene
        The scene, with a ``camera_path``.
    n_frames : int
        Number of frames, at least 2 (default 60).
    camera : vrecho.camera.Camera
        Image size and field of view (default ``Camera()``).
    progress : bool
        Whether to show a progress bar.

    Returns
    -------
    list of vrecho.camera.View
        The frames, in the path's order.

    Raises
    ------
    VrechoError
        If the scene has no camera path or ``n_frames`` is less than 2.
    """
    if scene.camera_path is None:
        raise VrechoError(f"scene {scene.name!r}: no camera_path to walk")
    if n_frames < 2:
        raise VrechoError(f"n_frames: expected at least 2, got {n_frames}")
    world = World(scene)
    positions, forwards = scene.camera_path.sample(n_frames)
    return [render_view(world, camera_pose(p, f), camera=camera)
            for p, f in tqdm(list(zip(positions, forwards)), desc="render walkthrough", unit="frame",
                             disable=not progress)]


def scan_scene(scene: Scene, *, n_frames: int = 60, camera: Camera = Camera(), voxel_m: float = 0.03,
               progress: bool = False) -> Scan:
    """The simulated phone scan of a scene: its walkthrough fused into a mesh.

    The walkthrough follows the scene's camera path, or
    :func:`~vrecho.sim.scenes.walkthrough_path`. No echoes yet: the reconstruction asks
    :func:`hear_echoes`'s ``hear`` for them where frames look at a hole.

    Parameters
    ----------
    scene : Scene
        The scene to scan.
    n_frames : int
        Number of walkthrough frames, at least 2 (default 60).
    camera : vrecho.camera.Camera
        Image size and field of view (default ``Camera()``).
    voxel_m : float
        Voxel size of the fusion in metres (default 0.03).
    progress : bool
        Whether to show progress bars.

    Returns
    -------
    vrecho.reconstruct.scan.Scan
        The frames and the fused mesh, with no echoes.

    Raises
    ------
    VrechoError
        If ``n_frames`` is less than 2.
    """
    if scene.camera_path is None:
        scene = dataclasses.replace(scene, camera_path=walkthrough_path(scene))
    views = walkthrough(scene, n_frames=n_frames, camera=camera, progress=progress)
    return Scan(views, fuse(views, voxel_m=voxel_m, progress=progress))


def simulate_echoes(scene: Scene, views: list[View], frames, *, seed: int = 0, progress: bool = False) -> Echoes:
    """What the device hears at the given walkthrough frames while it plays vrecho's probe.

    Simulated with pyroomacoustics, the recording conditions of PROTOCOL.md drawn per frame
    (:func:`~vrecho.sim.acoustics.recording_conditions`) from ``seed`` and the frame's index, so
    a frame sounds the same whichever others are asked for with it.

    Parameters
    ----------
    scene : Scene
        The scene heard.
    views : list of vrecho.camera.View
        The walkthrough's frames; the device stands where each camera is.
    frames : iterable of int
        Indices into ``views`` (repeats are heard once, in increasing order).
    seed : int
        Seed of the recordings (default 0).
    progress : bool
        Whether to show a progress bar.

    Returns
    -------
    vrecho.reconstruct.scan.Echoes
        ``frame`` (K,) the sorted indices, ``audio`` (K, 44100) float32 1 s frames at 44 100 Hz,
        and the probe as ``emitted``.
    """
    frames = sorted(set(int(i) for i in frames))
    sound = probe()
    audio = np.zeros((len(frames), FS), np.float32)
    for k, i in enumerate(tqdm(frames, desc="simulate echoes", unit="frame", disable=not progress)):
        rng = np.random.default_rng([seed, i])
        pose = device_pose(views[i])
        ir = device_impulse_response(scene, pose)[0]
        audio[k] = record_pulse(ir, sound, device_direct_amplitude(scene, pose), rng, *recording_conditions(rng))
    return Echoes(np.array(frames, int), audio, FS, sound)


def hear_echoes(scene: Scene, *, seed: int = 0, progress: bool = False) -> Callable[[list[View], object], Echoes]:
    """What the device hears in ``scene``, as :func:`vrecho.reconstruct.reconstruct` asks for it.

    Parameters
    ----------
    scene : Scene
        The scene heard.
    seed : int
        Seed of the recordings (default 0).
    progress : bool
        Whether to show a progress bar.

    Returns
    -------
    callable
        ``hear(views, frames)``: :func:`simulate_echoes` at those frames.
    """
    return functools.partial(simulate_echoes, scene, seed=seed, progress=progress)


def simulate_scene(scene: Scene, *, n_frames: int = 60, seed: int = 0,
                   progress: bool = False) -> tuple[Scan, Callable[[list[View], object], Echoes], SceneTruth]:
    """What the ``vrecho`` commands run on for a scene.

    The simulator's entry point, group ``vrecho.simulators``.

    Parameters
    ----------
    scene : Scene
        The scene.
    n_frames : int
        Number of walkthrough frames, at least 2 (default 60).
    seed : int
        Seed of the recordings (default 0).
    progress : bool
        Whether to show progress bars.

    Returns
    -------
    scan : vrecho.reconstruct.scan.Scan
        Its scan (:func:`scan_scene` with ``n_frames`` walkthrough frames).
    hear : callable
        What the device hears at a frame (:func:`hear_echoes`).
    truth : SceneTruth
        The truth.

    Raises
    ------
    VrechoError
        If ``n_frames`` is less than 2.
    """
    return scan_scene(scene, n_frames=n_frames, progress=progress), hear_echoes(scene, seed=seed, progress=progress), \
        SceneTruth(scene)
