"""What each ``vrecho`` command does, one function per command (:mod:`vrecho.cli` parses the command
line and calls one of them), and the commands' figures:

- :func:`generate`, :func:`train`, :func:`evaluate` (learning.py): datasets and models
  (:mod:`vrecho.learn`);
- :func:`reconstruct`, :func:`export` (scans.py): a scan repaired, and written as meshes or
  OpenUSD; what they run on (a user's scan folder, or a scene the simulator scans) is sources.py;
- :func:`capture` (captures.py): a phone's capture;
- :func:`demo` (demos.py): the whole run on one scene (:mod:`demo`);
- :func:`watch` (watch.py): the headset call live on this computer's sound card;
- figures.py: the repair before and after, a capture's pulses.

Each prints what the command prints; bad input is one :class:`~vrecho.errors.VrechoError`.
"""

from .captures import capture
from .demos import demo
from .learning import evaluate, generate, train
from .scans import export, reconstruct
from .watch import list_devices, watch

__all__ = ["capture", "demo", "evaluate", "export", "generate", "list_devices", "reconstruct", "train", "watch"]
