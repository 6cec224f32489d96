"""Real captures: a phone's video (or sound file) of vrecho's pulse train, its pulses, frames and
EchoCNN's answers, and with COLMAP's poses and the user's mesh, the mesh repaired.

- onsets.py: the pulses of a recording (:func:`find_onsets`) and PROTOCOL.md's frames cut from
  them (:func:`cut_frames`), flagged where the recording is clipped or its rate too low
  (:func:`frame_flags`); :data:`PULSE_TRAIN_WAV` is the train for the second phone to play;
- media.py: videos and sound files read (PyAV, soundfile) and written;
- posing.py: COLMAP's poses of the pictures on the recording's clock (:func:`read_poses`), and the
  scan of the user's mesh seen from each pulse (:func:`posed_scan`);
- pipeline.py: a capture from files to answers (:func:`open_capture`, :func:`analyse`).

``vrecho capture`` is :func:`vrecho.app.capture`; the simulator makes captures in
:mod:`vrecho.sim.captures`.
"""

from .media import read_audio, read_video, video_images, write_video
from .onsets import PULSE_TRAIN_WAV, Onsets, cut_frames, find_onsets, frame_flags, matched_envelope
from .pipeline import Analysis, Recording, analyse, answers, open_capture
from .posing import Poses, interpolate_poses, posed_scan, read_poses

__all__ = ["PULSE_TRAIN_WAV", "Analysis", "Onsets", "Poses", "Recording", "analyse", "answers", "cut_frames",
           "find_onsets", "frame_flags", "interpolate_poses", "matched_envelope", "open_capture", "posed_scan",
           "read_audio", "read_poses", "read_video", "video_images", "write_video"]
