"""vrecho: audio-augmented 3D scene reconstruction.

A phone or headset emits short pulses while it films; the echoes tell whether a hole in the scan
is an opening, a pane of glass or a mirror, and how far away it is. Modules, one idea each:
``scene`` (rooms, surfaces, the device; JSON), ``signals`` (the 16 emitted sounds, the probe),
``acoustics`` (pyroomacoustics impulse responses and recordings), ``render`` (the ray-cast camera),
``features`` (log-mel and echo features), ``data`` (datasets), ``listen`` (what the device hears),
``cli`` (the ``vrecho`` command).
"""

from .errors import VrechoError
from .scene import Scene, builtin_scene, load_scene, random_scene

__all__ = ["VrechoError", "Scene", "builtin_scene", "load_scene", "random_scene"]
__version__ = "0.1.0"
