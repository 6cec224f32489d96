"""usd_export: OpenUSD scenes with repaired glass and mirror geometry and spatial audio.

- :func:`write_scene` writes a stage (``.usda``/``.usdc``/``.usd``, WAVs beside it) or a
  ``.usdz`` package (WAVs inside), atomically, and refuses a stage OpenUSD's validators reject;
- :func:`validate` runs OpenUSD's validators (UsdValidation) and returns the problems;
- :func:`from_reconstruction` turns a :class:`vrecho.reconstruct.Reconstruction` into the room
  mesh and :class:`LabeledSurface` list ``write_scene`` takes; sound sources are
  :class:`localization.PlacedSource`.
"""

from .convert import from_reconstruction, sources_from_json, sources_from_scene
from .stage import LabeledSurface, Problem, check_sources, check_target, is_vrecho_stage, validate, write_scene, y_up

__all__ = ["LabeledSurface", "Problem", "check_sources", "check_target", "from_reconstruction", "is_vrecho_stage",
           "sources_from_json", "sources_from_scene", "validate", "write_scene", "y_up"]
