"""The simulator: from a scene's truth to what a device records, and the truth to judge by.

Everything that needs the truth lives here, and nothing of the method imports it (the method takes
what it hears as an argument; a test holds the rule):

- scenes.py: random scenes as PROTOCOL.md allows, device poses facing a discontinuity, the
  walkthrough a person scanning would follow, furniture for a room;
- acoustics.py: pyroomacoustics impulse responses (cached) and recordings through a microphone;
- render.py: what a camera sees, with the depth sensor's glass and mirror failures;
- scans.py: the phone's scan of a scene and the echoes heard at its frames
  (:func:`simulate_scene`, what the ``vrecho`` commands run on for a scene);
- walks.py: walks toward or past a surface for the headset call, on the monitor's own schedule,
  heard through an audio stream (its round trip, steps and drift), with other headsets and
  ambient sound, and its camera's frames along them;
- captures.py: recordings of the pulse train and whole captures for ``vrecho capture``;
- ambient.py, sounds.py: the room's sound sources and a microphone array's captures of them;
- listening.py: what the device hears in front of each surface;
- scoring.py: the truth as a decider (:class:`~.scoring.Oracle`) and a repair's metrics.
"""

from .acoustics import device_direct_amplitude, device_impulse_response, impulse_responses, record_pulse
from .ambient import AmbientSource, Shoebox, SimulatedCapture, hear_scene, random_walk, simulate_walk_capture
from .render import World, crop, render_view
from .scans import hear_echoes, scan_scene, simulate_echoes, simulate_scene, walkthrough
from .scenes import face, random_furniture, random_scene, walkthrough_path
from .scoring import Oracle, SceneTruth, match_truth, oracle, score
from .walks import (HEADSET_CAMERA, AudioLink, Headset, Walk, headset_frames, other_headsets, record_walk,
                    simulate_walk, walk_responses)

__all__ = ["HEADSET_CAMERA", "AmbientSource", "AudioLink", "Headset", "Oracle", "SceneTruth", "Shoebox",
           "SimulatedCapture", "Walk", "World", "other_headsets", "random_furniture", "record_walk", "walk_responses",
           "crop", "device_direct_amplitude", "device_impulse_response", "face", "headset_frames", "hear_echoes",
           "hear_scene", "impulse_responses", "match_truth", "oracle", "random_scene", "random_walk", "record_pulse",
           "render_view", "scan_scene", "score", "simulate_echoes", "simulate_scene", "simulate_walk",
           "simulate_walk_capture", "walkthrough", "walkthrough_path"]
