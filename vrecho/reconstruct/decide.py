"""What each hole is: open, or closed glass or mirror, and at what depth.

:func:`infer` asks EchoCNN about the frames that look at a hole (:func:`~.discontinuities.facing`)
and, by default, adds what the scan knows by physics (the distance to the hole's plane, where
EchoCNN listens for its echo; the mirror test by reflection, :func:`mirror_evidence`). The ways
to decide are a registry, :data:`LABELS`, as pyroomacoustics' ``doa.algorithms`` is: a name maps
to a class whose instances are called with the holes, the frames and what the device heard. A decider of one's own (the
simulator's oracle, :class:`vrecho.sim.scoring.Oracle`) has the same call; its ``hears``
attribute says whether it needs the recordings.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.spatial import cKDTree

from ..camera import View, crop_view, device_pose
from ..planes import MAX_SURFACE_M, plane_open
from .discontinuities import Hole, Plane, facing, seen_through
from .scan import Echoes


@dataclass
class Decision:
    """What a hole is judged to be.

    Parameters
    ----------
    state : str
        ``"closed"``, ``"open"`` or ``"unknown"`` (no frame looked at it).
    material : str or None
        ``"glass"`` or ``"mirror"`` for closed holes, else None.
    offset_m : float or None
        The plane of the surface, in metres: points x with normal . x + offset = 0, normal into
        the room (the hole's wall's). None unless closed.
    p_closed, p_mirror : float
        Probabilities that the hole is closed, and that a closed surface is a mirror.
    confidence : float
        Probability of the answer given (open or closed).
    source : str
        Who decided: ``"echocnn+scan"``, ``"echocnn"`` (:func:`infer`) or ``"oracle"`` (the
        simulator's :class:`~vrecho.sim.scoring.Oracle`).
    frames : list of dict
        The per-frame inferences it was combined from (see :func:`infer`); empty by default.
    evidence : dict
        The scan's evidence (see :func:`infer`); empty by default.
    """

    state: str
    material: str | None
    offset_m: float | None
    p_closed: float
    p_mirror: float
    confidence: float
    source: str
    frames: list[dict] = field(default_factory=list)
    evidence: dict = field(default_factory=dict)


SCAN_TOLERANCE_M = 0.03
"""How far a scanned wall's plane may lie from the truth, where the echo of a closed surface in
its hole is looked for: the plane is fitted over thousands of a wall's points, 3 cm voxels (its
depth off by 0.3 cm in the median on the benchmark's rooms). The default 5 cm of
:meth:`~vrecho.classifier.Classifier.predict` took, on a tuning room (seed 1000, room 0), the
corner of an opening's wall with the floor, 2 to 9 cm beyond the plane, for glass."""


MIRROR_SHARE = 0.15
"""Share of seen-through geometry that, reflected, lands on the room: above it, a mirror (the
living room: mirror 0.27, window 0.006, opening 0.04)."""


def infer(holes_: list[Hole], views: list[View], echoes: Echoes, *, classifier=None, mesh=None, walls=(),
          use_scan: bool = True, min_crop_inside: float = 0.98, max_frames: int = 6) -> list[Decision]:
    """vrecho's answer for each hole, from the frames that look at it (:func:`facing`).

    Each frame's recording goes to EchoCNN with the known probe (EchoCNN-E), and with the
    camera's crop around the hole when the frame holds all of it (EchoCNN-EV). Up to
    ``max_frames`` frames per hole, the most frontal first, are combined; only frames with a
    recording count, and a hole no such frame faces is ``"unknown"``.

    With ``use_scan`` (vrecho's choice) the scan adds what it knows, by physics: the wall around
    the hole is scanned, so the distance to a closed surface's plane is known. A frame whose
    specular point, the foot of the loudspeaker's perpendicular to that plane, falls in the hole
    is asked with it (``surface_m``: open/closed by the echo there or none,
    :func:`~vrecho.planes.plane_echo`), and those frames together decide open or closed by
    the echo where one offset of the scan's plane puts it in all of them
    (:func:`~vrecho.planes.plane_open`: the plane's error is the scan's, the same from every
    pose); EchoCNN's answers alone decide where no frame's foot falls in the hole. A frame's depth is its echo's where it agrees with the scan
    within 10 cm, else the scan's. The geometry seen through the hole, reflected in its plane
    (:func:`mirror_evidence`), says mirror or not where it is clear (200 or more vertices seen
    through), and glass where almost nothing is seen through (fewer than 50: a mirror always
    shows its phantom); EchoCNN's material answers otherwise. Without ``use_scan``: EchoCNN
    alone (probabilities averaged, depth the median of the frames' EchoCNN depths weighted by
    their closed probability; with it, the frames' chosen depths are weighted so).

    Parameters
    ----------
    holes_ : list of :class:`~.discontinuities.Hole`
        The holes to decide.
    views : list of :class:`~vrecho.camera.View`
        The scan's frames.
    echoes : :class:`~.scan.Echoes`
        What the device heard, by frame.
    classifier : vrecho.classifier.Classifier, optional
        EchoCNN (the shipped weights by default, :func:`vrecho.classifier.load_classifier`).
    mesh : open3d.geometry.TriangleMesh, optional
        The scan's mesh, for the mirror test; without it the mirror test is left out.
    walls : list of :class:`~.discontinuities.Plane`
        The room's walls, for the mirror test.
    use_scan : bool
        Add the scan's evidence (default True, vrecho's choice).
    min_crop_inside : float
        Smallest share of the crop within the frame for it to go to EchoCNN (default 0.98).
    max_frames : int
        Most frames combined per hole (default 6).

    Returns
    -------
    list of :class:`Decision`
        One per hole, in order. Each frame's row in :attr:`Decision.frames` holds ``frame``,
        ``model``, ``p_closed``, ``p_mirror``, ``echo_depth_m`` (EchoCNN's), ``scan_depth_m``
        (emitter to the wall's plane), ``depth_m`` (the one used) and ``offset_m`` (metres);
        with ``use_scan`` also ``foot_in_hole``. :attr:`Decision.evidence` holds
        ``echo_frames``, ``p_echo_closed`` and ``plane_offset_m`` (the frames asked with the
        plane's distance, their answer together, and how far the echo puts the plane beyond the
        scan's; where a specular point fell in the hole) and ``mirrored_share`` and
        ``seen_through_vertices`` (with a mesh); empty without ``use_scan``.

    Raises
    ------
    VrechoError
        From EchoCNN, for a recording it cannot take (a silent frame, or one not 1 s long).
    """
    from ..classifier import load_classifier  # torch-bound (1.7 s): only when EchoCNN is asked

    if classifier is None:
        classifier = load_classifier()
    cameras = np.array([v.pose[:3, 3] for v in views])
    out = []
    for hole in holes_:
        n = hole.plane.normal
        frames = [i for i in facing(views, hole) if echoes.of(i) is not None]
        frames = sorted(frames, key=lambda i: float(n @ views[i].pose[:3, 2]))[:max_frames]
        if not frames:
            out.append(Decision("unknown", None, None, 0.5, 0.5, 0.0, "echocnn"))
            continue
        rows, heard = [], []
        for i in frames:
            image, inside = crop_view(views[i], hole.corners())
            audio = echoes.of(i)
            pose = device_pose(views[i])
            scan_depth, foot_in_hole, surface, toward = _scan_geometry(pose, hole)
            surface, toward = (surface, toward) if use_scan else (None, None)
            pred = classifier.predict(audio, echoes.fs, image=image if inside >= min_crop_inside else None,
                                      emitted=echoes.emitted, surface_m=surface, surface_tolerance_m=SCAN_TOLERANCE_M,
                                      mic_toward_surface_m=toward)
            row = {"frame": i, "model": pred.model, "p_closed": pred.probabilities["closed"],
                   "p_mirror": pred.probabilities["mirror"], "echo_depth_m": pred.depth_m, "scan_depth_m": scan_depth}
            if use_scan:
                row["foot_in_hole"] = foot_in_hole
                row["depth_m"] = pred.depth_m if abs(pred.depth_m - scan_depth) < 0.1 else scan_depth
                if surface is not None:
                    heard.append((audio, surface, toward))
            else:
                row["depth_m"] = pred.depth_m
            row["offset_m"] = row["depth_m"] - float(n @ pose.emitter)
            rows.append(row)
        p_closed = float(np.mean([r["p_closed"] for r in rows]))
        p_mirror = float(np.mean([r["p_mirror"] for r in rows]))
        evidence = {}
        if use_scan:
            if heard:
                audio, surface, toward = zip(*heard)
                walk = plane_open(np.stack(audio), echoes.fs, emitted=echoes.emitted, surface_m=surface,
                                  mic_toward_surface_m=toward, surface_tolerance_m=SCAN_TOLERANCE_M)
                p_closed = 1.0 - walk.p_open
                evidence.update(echo_frames=len(heard), p_echo_closed=p_closed, plane_offset_m=walk.offset_m)
            if mesh is not None:
                share, count = mirror_evidence(mesh, hole, walls, cameras)
                evidence.update(mirrored_share=share, seen_through_vertices=count)
                if count >= 200:  # enough seen through to judge
                    p_mirror = 0.97 if share >= MIRROR_SHARE else 0.03
                elif count < 50:  # nothing behind it: a mirror always shows its phantom; clear glass shows nothing
                    p_mirror = 0.1
        offsets = np.array([r["offset_m"] for r in rows])
        weights = np.array([r["p_closed"] for r in rows]) + 1e-6
        order = np.argsort(offsets)
        cum = np.cumsum(weights[order])
        offset = float(offsets[order][np.searchsorted(cum, cum[-1] / 2)])
        closed = p_closed >= 0.5
        out.append(Decision("closed" if closed else "open", ("mirror" if p_mirror >= 0.5 else "glass") if closed else None,
                            offset if closed else None, p_closed, p_mirror, max(p_closed, 1 - p_closed),
                            "echocnn+scan" if use_scan else "echocnn", rows, evidence))
    return out


def scan_distance(view: View, hole: Hole) -> tuple[float | None, float | None]:
    """What the scan tells EchoCNN of a hole in one frame: the distance from the device's
    loudspeaker to the hole's plane (``surface_m``) and its microphone's offset toward it
    (``mic_toward_surface_m``), where the specular point, the foot of the loudspeaker's
    perpendicular to the plane, falls in the hole (5 cm inside its edge); else (None, None):
    the echo at the wall's delay then speaks of the wall beside the hole.

    Parameters
    ----------
    view : :class:`~vrecho.camera.View`
        The frame (its pose places the device: :func:`~vrecho.camera.device_pose`).
    hole : :class:`~.discontinuities.Hole`

    Returns
    -------
    surface_m, mic_toward_surface_m : float or None
        Metres; both None where the foot falls outside the hole or the plane is not 0 to
        :data:`~vrecho.planes.MAX_SURFACE_M` ahead.
    """
    _, _, surface, toward = _scan_geometry(device_pose(view), hole)
    return surface, toward


def _scan_geometry(pose, hole: Hole) -> tuple[float, bool, float | None, float | None]:
    """:func:`scan_distance` of the device at ``pose``, with the signed distance to the plane and
    whether the foot falls in the hole."""
    n = hole.plane.normal  # into the room
    depth = float(n @ pose.emitter + hole.plane.offset)
    foot_in_hole = bool(hole.contains((pose.emitter - depth * n)[None], margin_m=-0.05)[0])
    if not (foot_in_hole and 0 < depth <= MAX_SURFACE_M):
        return depth, foot_in_hole, None, None
    return depth, foot_in_hole, depth, float(n @ (pose.emitter - pose.microphone))


def mirror_evidence(mesh, hole: Hole, walls: list[Plane], cameras: np.ndarray, *, tolerance_m: float = 0.06,
                    shifts_m: np.ndarray = np.arange(-0.06, 0.061, 0.02)) -> tuple[float, int]:
    """How much of what the camera saw through a hole is the room itself, mirrored.

    A mirror's phantom is the room reflected in the mirror's plane: reflected back, it lands on
    the scanned room. What lies beyond glass or an opening does not. Returns the share of the
    seen-through vertices that, reflected, fall within ``tolerance_m`` of the scan's own
    surfaces (in front of every wall), and how many vertices were seen through. A mirror hangs a
    few centimetres off its wall, and a scanned surface lies within a voxel of the truth (the
    reflection is off by twice the plane's error): the mirror's plane is tried at the wall's
    plane moved by each of ``shifts_m`` (positive: away from the room), and the best share counts
    (on the tuning rooms of seeds 1000 and 3000: openings 0.09 at most, glass 0.06, mirrors 0.19
    and above).

    Parameters
    ----------
    mesh : open3d.geometry.TriangleMesh
        The scan's mesh (its vertices are used).
    hole : :class:`~.discontinuities.Hole`
        The hole.
    walls : list of :class:`~.discontinuities.Plane`
        The room's walls; the room's own surfaces are the vertices less than 5 cm behind every
        wall.
    cameras : numpy.ndarray [shape=(M, 3)], float
        Camera positions in metres (what was seen through, :func:`seen_through`).
    tolerance_m : float
        How near, in metres, a reflected vertex must land to the room's (default 0.06).
    shifts_m : numpy.ndarray [shape=(S,)], float
        Shifts of the mirror's plane from the wall's, in metres (default -0.06 to 0.06 in 2 cm
        steps).

    Returns
    -------
    share : float
        The best share in [0, 1]; 0 when fewer than 50 vertices were seen through.
    count : int
        How many vertices were seen through the hole.
    """
    v = np.asarray(mesh.vertices)
    through = v[seen_through(v, hole, cameras)]
    if len(through) < 50:
        return 0.0, int(len(through))
    room = np.ones(len(v), bool)
    for w in walls:
        room &= v @ w.normal + w.offset > -0.05
    n = hole.plane.normal
    tree = cKDTree(v[room])
    shares = []
    for offset in hole.plane.offset + np.asarray(shifts_m):
        dist, _ = tree.query(through - 2 * (through @ n + offset)[:, None] * n, distance_upper_bound=tolerance_m)
        shares.append(float(np.mean(np.isfinite(dist))))
    return max(shares), int(len(through))


class EchoCNNOnly:
    """EchoCNN alone (``labels="echocnn-only"``): its answers averaged over the frames facing
    each hole (:func:`infer` without the scan's evidence). Called as every decider is:
    ``decider(holes, views, echoes, mesh=..., walls=...)``.

    Parameters
    ----------
    classifier : vrecho.classifier.Classifier, optional
        EchoCNN; the shipped one by default (loaded by :func:`infer` at each call).

    Attributes
    ----------
    label : str
        Its name in :data:`LABELS`.
    use_scan : bool
        Whether :func:`infer` adds the scan's evidence.
    hears : bool
        Deciders that read the recordings say so: the pipeline hears the frames for them.
    """

    label = "echocnn-only"
    use_scan = False
    hears = True
    """Deciders that read the recordings say so: the pipeline hears the frames for them."""

    def __init__(self, classifier=None):
        self.classifier = classifier

    def __call__(self, holes: list[Hole], views: list[View], echoes: Echoes, *, mesh=None,
                 walls: list[Plane] = ()) -> list[Decision]:
        """Decide each hole (:func:`infer`).

        Parameters
        ----------
        holes : list of :class:`~.discontinuities.Hole`
            The holes to decide.
        views : list of :class:`~vrecho.camera.View`
            The scan's frames.
        echoes : :class:`~.scan.Echoes`
            What the device heard, by frame.
        mesh : open3d.geometry.TriangleMesh, optional
            The scan's mesh, for the mirror test (used with the scan's evidence).
        walls : list of :class:`~.discontinuities.Plane`
            The room's walls.

        Returns
        -------
        list of :class:`Decision`
            One per hole, in order.
        """
        return infer(holes, views, echoes, classifier=self.classifier, mesh=mesh, walls=walls, use_scan=self.use_scan)


class EchoCNNWithScan(EchoCNNOnly):
    """vrecho's choice (``labels="echocnn"``): EchoCNN with what the scan adds by physics (see
    :func:`infer`). Built and called as :class:`EchoCNNOnly`.

    Parameters
    ----------
    classifier : vrecho.classifier.Classifier, optional
        EchoCNN; the shipped one by default (loaded by :func:`infer` at each call).
    """

    label = "echocnn"
    use_scan = True


LABELS: dict[str, type[EchoCNNOnly]] = {cls.label: cls for cls in (EchoCNNWithScan, EchoCNNOnly)}
"""Who decides what each hole is, by name: ``echocnn`` (EchoCNN with the scan's evidence, vrecho's
choice) and ``echocnn-only``. The truth (``oracle``) is the simulator's
(:class:`vrecho.sim.scoring.Oracle`): it is passed as a decider, not named here."""
