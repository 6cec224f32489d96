"""The headset call's name as ARCHITECTURE.md gives it (``vrecho.boundary.BoundaryMonitor``): the
code lives in :mod:`vrecho.headset`."""

from .headset import Alert, BoundaryMonitor, ranging_probe

__all__ = ["Alert", "BoundaryMonitor", "ranging_probe"]
