"""localization: separation of the room's sound sources and their placement in 3D (issue 5).

:class:`PlacedSource` is what placement hands to :mod:`usd_export`.
"""

from .sources import PlacedSource

__all__ = ["PlacedSource"]
