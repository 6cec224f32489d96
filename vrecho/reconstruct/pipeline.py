"""The reconstruction's whole run: a scan in, its discontinuities decided and repaired out.

:func:`reconstruct` finds the walls and holes (:mod:`.discontinuities`), asks a decider what each
hole is (:mod:`.decide`; it hears the frames facing them with ``hear`` when the scan holds no
recordings) and repairs the scan (:mod:`.repair`). It never changes the scan it is given.
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass
from typing import Callable

import numpy as np

from ..errors import VrechoError
from .decide import LABELS, Decision
from .discontinuities import Hole, Plane, facing, holes, wall_planes
from .repair import VARIANTS, Surface, repair
from .scan import Scan


@dataclass
class Reconstruction:
    """Everything a run of :func:`reconstruct` found and did; :meth:`report` is its JSON.

    Parameters
    ----------
    scan : :class:`~.scan.Scan`
        The scan worked on, with the recordings the decision heard.
    walls : list of :class:`~.discontinuities.Plane`
        The room's walls.
    holes : list of :class:`~.discontinuities.Hole`
        The holes found in them.
    decisions : list of :class:`~.decide.Decision`
        What each hole is, one per hole.
    repaired : open3d.geometry.TriangleMesh
        The repaired mesh.
    surfaces : list of :class:`~.repair.Surface`
        The surfaces the repair added.
    actions : list of dict
        What the repair did to each hole (see :func:`~.repair.repair`).
    variant : str
        The repair's fill, ``"simplified"`` or ``"per_vertex"``.
    seconds : dict
        Time taken per step, in seconds: ``discontinuities``, ``hear`` (where the device was
        heard), ``decide``, ``repair`` and ``total_without_hearing``.
    """

    scan: Scan
    walls: list[Plane]
    holes: list[Hole]
    decisions: list[Decision]
    repaired: object  # open3d.geometry.TriangleMesh
    surfaces: list[Surface]
    actions: list[dict]
    variant: str
    seconds: dict

    def report(self) -> dict:
        """The run as JSON-ready data (format ``"vrecho-reconstruction"``, version 1).

        Returns
        -------
        dict
            The variant, who decided (``labels``, the first decision's source), the initial and
            repaired meshes' vertex and triangle counts, the walls, each hole (its wall, area in
            square metres, world outline in metres, decision with its frames and evidence, and
            action), the added surfaces and the seconds per step. Numbers are rounded to 4
            decimals (areas and seconds to 3).
        """
        return {
            "format": "vrecho-reconstruction", "version": 1, "variant": self.variant,
            "labels": self.decisions[0].source if self.decisions else None,
            "initial": {"vertices": len(self.scan.mesh.vertices), "triangles": len(self.scan.mesh.triangles)},
            "repaired": {"vertices": len(self.repaired.vertices), "triangles": len(self.repaired.triangles)},
            "walls": [{"normal": w.normal.round(4).tolist(), "offset_m": round(w.offset, 4), "inliers": len(w.inliers)}
                      for w in self.walls],
            "holes": [{"id": k, "wall": next(i for i, w in enumerate(self.walls) if w is h.plane),
                       "area_m2": round(h.area_m2, 3), "outline": h.polygon().round(4).tolist(),
                       "decision": {"state": d.state, "material": d.material,
                                    "offset_m": None if d.offset_m is None else round(d.offset_m, 4),
                                    "p_closed": round(d.p_closed, 4), "p_mirror": round(d.p_mirror, 4),
                                    "confidence": round(d.confidence, 4), "source": d.source,
                                    "frames": [_rounded(r) for r in d.frames], "evidence": _rounded(d.evidence)},
                       "action": a}
                      for k, (h, d, a) in enumerate(zip(self.holes, self.decisions, self.actions))],
            "surfaces": [{"hole": s.hole, "material": s.material, "area_m2": round(s.area_m2, 3),
                          "normal": s.normal.round(4).tolist(), "polygon": s.polygon.round(4).tolist(),
                          "confidence": round(s.confidence, 4)} for s in self.surfaces],
            "seconds": {k: round(v, 3) for k, v in self.seconds.items()},
        }


def _rounded(d: dict) -> dict:
    return {k: round(v, 4) if isinstance(v, float) else v for k, v in d.items()}


def reconstruct(scan: Scan, *, hear: Callable | None = None, decide="echocnn", variant: str = "simplified",
                classifier=None) -> Reconstruction:
    """Find the scan's discontinuities, decide what each is, and repair it (Algorithm 1).

    Parameters
    ----------
    scan : :class:`~.scan.Scan`
        The camera's frames and mesh (:func:`~.scan.load_scan`, a capture, or the simulator's);
        not changed.
    hear : callable, optional
        ``hear(views, frames) -> Echoes``: what the device hears at the given frame indices (a
        set of int), for a scan without recordings (the simulator's, or a live device's). Asked
        only for the frames that face a hole, and only when the decider reads recordings.
    decide : str or decider
        A name of :data:`~.decide.LABELS` (``"echocnn"``, vrecho's choice and the default, or
        ``"echocnn-only"``), or a decider of one's own called as they are (the simulator's
        :class:`~vrecho.sim.scoring.Oracle`).
    variant : {"simplified", "per_vertex"}
        Algorithm 1's fill (see :func:`~.repair.repair`).
    classifier : vrecho.classifier.Classifier, optional
        EchoCNN for a named decider (the shipped weights by default).

    Returns
    -------
    Reconstruction
        Its ``scan`` holds the recordings the decision heard.

    Raises
    ------
    VrechoError
        For an unknown decider name or ``variant``; when the scan's mesh has fewer than 100
        vertices; and when the decider reads recordings, the scan has none and no ``hear`` is
        given.
    """
    if isinstance(decide, str):
        if decide not in LABELS:
            raise VrechoError(f"labels: expected one of {tuple(LABELS)} or a decider, got {decide!r}")
        decide = LABELS[decide](classifier)
    if variant not in VARIANTS:
        raise VrechoError(f"variant: expected one of {VARIANTS}, got {variant!r}")
    seconds = {}
    t0 = time.perf_counter()
    vertices = np.asarray(scan.mesh.vertices)
    if len(vertices) < 100:
        raise VrechoError(f"scan: the mesh has {len(vertices)} vertices; nothing to reconstruct")
    walls = wall_planes(vertices, scan.cameras)
    found = [h for w in walls for h in holes(w, scan.views, walls)]
    seconds["discontinuities"] = time.perf_counter() - t0
    echoes = scan.echoes
    if getattr(decide, "hears", True) and echoes is None:
        if hear is None:
            raise VrechoError("scan: no echoes.npz, so EchoCNN has nothing to hear; give echoes or use oracle labels")
        t = time.perf_counter()
        echoes = hear(scan.views, {i for h in found for i in facing(scan.views, h)})
        seconds["hear"] = time.perf_counter() - t
        scan = dataclasses.replace(scan, echoes=echoes)
    t = time.perf_counter()
    decisions = decide(found, scan.views, echoes, mesh=scan.mesh, walls=walls)
    seconds["decide"] = time.perf_counter() - t
    t = time.perf_counter()
    repaired, surfaces, actions = repair(scan.mesh, found, decisions, scan.cameras, variant=variant)
    seconds["repair"] = time.perf_counter() - t
    seconds["total_without_hearing"] = sum(v for k, v in seconds.items() if k != "hear")
    return Reconstruction(scan, walls, found, decisions, repaired, surfaces, actions, variant, seconds)
