"""The headset call: warn before the wearer walks into glass, a mirror or a wall.

- :class:`BoundaryMonitor` (boundary.py): the echo ranging of a full-duplex audio callback, its
  alerts (:class:`Alert`, alert.py) and their hysteresis; the surfaces it follows are
  :class:`~.tracks.Track` (tracks.py); its probe, when it plays it, and the microphone's envelope
  are ranging.py's, the echoes in it echoes.py's (and those too faint for one pulse, summed
  along the wearer's approach over eight, faint.py's), the lock on its own round trip
  roundtrip.py's, the per-pulse work compiled (numba) kernels.py's.
- :func:`look` (view.py): what the headset's camera says of a surface an echo found (wall, glass
  or mirror), shown to the monitor with :meth:`BoundaryMonitor.see`.

Nothing here imports torch until a camera frame is classified: the audio path starts fast.
"""

from .alert import Alert
from .boundary import BoundaryMonitor
from .ranging import ProbeSchedule, probe_codes, ranging_probe
from .view import SurfaceView, load_model, look, look_all, pane_crop

__all__ = ["Alert", "BoundaryMonitor", "ProbeSchedule", "probe_codes", "SurfaceView", "load_model", "look", "look_all", "pane_crop", "ranging_probe"]
