"""localization: separation of the room's sound sources and their placement in 3D (issue 5)."""
