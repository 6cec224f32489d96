"""Echo-reconstruction: the camera's scan of a room, its glass and mirror failures, and their repair.

1. **The scan** (scan.py): the camera's frames and the mesh fused from them (:func:`fuse`, open3d's
   TSDF), or a user's scan folder (:func:`load_scan`); what the device heard is its
   :class:`Echoes`.
2. **Discontinuities** (discontinuities.py): the walls (:func:`wall_planes`), the holes in them
   (:func:`holes`, free space carved by the depth frames), what lies behind them
   (:func:`beyond_walls`) and the frames that face a hole (:func:`facing`).
3. **What each hole is** (decide.py): :func:`infer` asks EchoCNN about the frames facing it and
   adds what the scan knows by physics (:func:`scan_distance`: the hole's plane's distance, where
   the echo is looked for); the ways to decide are the registry :data:`LABELS`.
4. **The repair**, the paper's Algorithm 1 (repair.py, :func:`repair`).

:func:`reconstruct` (pipeline.py) runs 2 to 4 on a scan. It takes what the device hears as an
argument (``hear``): the simulator (:mod:`vrecho.sim`) supplies it for a scene, a capture's
recordings for a real one. ``vrecho reconstruct`` is :func:`vrecho.app.reconstruct`.
"""

from .decide import LABELS, SCAN_TOLERANCE_M, Decision, EchoCNNOnly, EchoCNNWithScan, infer, mirror_evidence, scan_distance
from .discontinuities import Hole, Plane, beyond_walls, facing, holes, seen_through, wall_planes
from .pipeline import Reconstruction, reconstruct
from .repair import SURFACE_COLOURS, VARIANTS, Surface, repair
from .scan import Echoes, Scan, fuse, load_scan

__all__ = ["LABELS", "SCAN_TOLERANCE_M", "SURFACE_COLOURS", "VARIANTS", "Decision", "EchoCNNOnly", "EchoCNNWithScan", "Echoes", "Hole",
           "Plane", "Reconstruction", "Scan", "Surface", "beyond_walls", "facing", "fuse", "holes", "infer",
           "load_scan", "mirror_evidence", "reconstruct", "repair", "scan_distance", "seen_through", "wall_planes"]
