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
    """Frames rendered along the scene's camera path, evenly spaced in time."""
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
    """The simulated phone scan of a scene: its walkthrough (the scene's camera path, or
    :func:`~vrecho.sim.scenes.walkthrough_path`) fused into a mesh. No echoes yet: the
    reconstruction asks :func:`hear_echoes`'s ``hear`` for them where frames look at a hole."""
    if scene.camera_path is None:
        scene = dataclasses.replace(scene, camera_path=walkthrough_path(scene))
    views = walkthrough(scene, n_frames=n_frames, camera=camera, progress=progress)
    return Scan(views, fuse(views, voxel_m=voxel_m, progress=progress))


def simulate_echoes(scene: Scene, views: list[View], frames, *, seed: int = 0, progress: bool = False) -> Echoes:
    """What the device hears at the given walkthrough frames while it plays vrecho's probe
    (pyroomacoustics, the recording conditions of PROTOCOL.md drawn per frame)."""
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
    """What the device hears in ``scene``, as :func:`vrecho.reconstruct.reconstruct` asks for it:
    ``hear(views, frames)`` is :func:`simulate_echoes` at those frames."""
    return functools.partial(simulate_echoes, scene, seed=seed, progress=progress)


def simulate_scene(scene: Scene, *, n_frames: int = 60, seed: int = 0,
                   progress: bool = False) -> tuple[Scan, Callable[[list[View], object], Echoes], SceneTruth]:
    """What the ``vrecho`` commands run on for a scene (the simulator's entry point, group
    ``vrecho.simulators``): its scan (:func:`scan_scene` with ``n_frames`` walkthrough frames),
    what the device hears at a frame (:func:`hear_echoes`) and the truth (:class:`SceneTruth`)."""
    return scan_scene(scene, n_frames=n_frames, progress=progress), hear_echoes(scene, seed=seed, progress=progress), \
        SceneTruth(scene)
