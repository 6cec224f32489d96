"""What the headset's camera says of the surface its echoes found: a wall, glass or a mirror.

The echo says *that* a surface lies ahead and how far (:class:`vrecho.headset.BoundaryMonitor`);
glass, a mirror and a wall return the monitor's 4-20 kHz probe alike (their absorption differs
by hundredths there, PROTOCOL.md), so the echo cannot say *what* it is. The headset's depth
camera can, because of how it fails (PROTOCOL.md, :mod:`vrecho.sim.render`):

1. **Wall.** Straight ahead (rays within ``CONE_DEG`` of the optical axis) the depth sensor
   reads the plane the echo comes from: at least half of its readings there lie within
   ``depth_window`` of the echo's distance.
2. **Glass or mirror.** Otherwise the sensor sees past the echo's plane (through glass to what
   lies beyond, in a mirror the phantom room behind it) or gets nothing back: those pixels are
   the pane. The region they form around the straight-ahead direction, widened by 15 % on
   each side as EchoCNN's crops of a discontinuity are (:func:`vrecho.sim.render.crop`), resampled to
   PROTOCOL.md's 64 x 25 grayscale crop, goes to EchoCNN's visual branch (the paper's
   image sub-network, ``EchoCNN(inputs=("image",))``), trained here on such crops from
   simulated headsets (:func:`train`, weights ``vrecho/assets/headset_view.pt``): glass shows
   what lies beyond, a mirror the room.

A pane that fills the frame (the region touches its edges) is still answered, from what is in
view. The straight-ahead cone stands for the echo's specular point, the foot of the
loudspeaker's perpendicular on the surface: the two part by ``d tan(yaw)`` when the wearer looks
askew, so a narrow pane looked at from its edge can read as the wall beside it (walking toward
a surface, the wearer faces it). Call :func:`look` from the camera's thread, not the audio
callback (a few milliseconds a frame).

Train the shipped weights again with ``python3 -m vrecho.learn.headset_view``.
"""

from __future__ import annotations

from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from scipy import ndimage

from ..camera import CROP_SHAPE
from ..errors import VrechoError

if TYPE_CHECKING:
    from ..models import EchoCNN


CONE_DEG = 5.0
"""Half-angle of the straight-ahead cone whose depth readings decide "wall"."""


MARGIN = 0.15
"""The pane's region is widened by this share of its size on each side, as EchoCNN's crops are."""


WEIGHTS = "headset_view.pt"


@dataclass
class SurfaceView:
    """What one camera frame says of the surface the echo found ``distance_m`` ahead.

    Parameters
    ----------
    surface : str
        "wall", "glass" or "mirror".
    confidence : float
        In [0.5, 1].
    agree : float
        The share, in [0, 1], of the straight-ahead depth readings at the echo's distance.
    crop : numpy.ndarray [shape=(64, 25), dtype=uint8] or None
        The crop of the pane that was classified (None for a wall).
    """

    surface: str
    confidence: float
    agree: float
    crop: np.ndarray | None = None


def depth_window(distance_m: float) -> tuple[float, float]:
    """The z-depths a depth camera beside the emitter reads, straight ahead, of the echo's plane.

    The plane lies ``distance_m`` from the emitter, and the camera faces it within 20 degrees (a
    ray within ``CONE_DEG`` of the axis meets it at most 25 degrees off its normal: 1 / cos 25 =
    1.10), with 10 cm of slack for the sensor's noise and the wearer's motion between the echo
    and the frame.

    Parameters
    ----------
    distance_m : float
        The echo's distance from the emitter in metres.

    Returns
    -------
    lo, hi : float
        The window in metres: ``distance_m - 0.1`` to ``1.12 * distance_m + 0.1``.
    """
    return distance_m - 0.1, 1.12 * distance_m + 0.1


def _frame(image, depth, intrinsics) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The frame checked: gray (H, W) in [0, 1], depth (H, W) with 0 for no return, and the
    straight-ahead cone (H, W) bool."""
    g = np.asarray(image)
    z = np.asarray(depth, dtype=np.float64)
    K = np.asarray(intrinsics, dtype=np.float64)
    if g.ndim != 2 or g.shape != z.shape:
        raise VrechoError(f"image, depth: expected two (H, W) frames of one size, got {g.shape} and {z.shape}")
    if min(g.shape) < 16:
        raise VrechoError(f"image: a frame of at least 16 x 16 pixels is needed, got {g.shape}")
    if K.shape != (3, 3) or not np.all(np.isfinite(K)) or K[0, 0] <= 0 or K[1, 1] <= 0:
        raise VrechoError("intrinsics: expected a 3 x 3 pinhole matrix with positive focal lengths")
    if g.dtype == np.uint8:
        g = g.astype(np.float64) / 255
    elif g.dtype.kind != "f" or not np.all(np.isfinite(g)) or g.min() < 0 or g.max() > 1:
        raise VrechoError("image: expected uint8 grayscale, or finite floats in [0, 1]")
    z = np.where(np.isfinite(z) & (z > 0), z, 0.0)  # no return: 0, as the sensor says
    h, w = z.shape
    v, u = np.ogrid[0:h, 0:w]
    cone = np.hypot((u - K[0, 2]) / K[0, 0], (v - K[1, 2]) / K[1, 1]) < np.tan(np.radians(CONE_DEG))
    if not cone.any():
        raise VrechoError("intrinsics: the principal point lies outside the frame")
    return g.astype(np.float64), z, cone


def _pane(g: np.ndarray, z: np.ndarray, cone: np.ndarray, distance_m: float) -> tuple[float, np.ndarray | None]:
    lo, hi = depth_window(distance_m)
    agree = float(np.mean((z[cone] >= lo) & (z[cone] <= hi)))
    if agree >= 0.5:
        return agree, None

    beyond = (z == 0) | (z > hi)
    labels, _ = ndimage.label(beyond)
    ahead = labels[cone & beyond]
    if not len(ahead):  # nearer than the echo straight ahead (an object in front): the pane is not in view
        return agree, None
    rows, cols = np.nonzero(labels == np.bincount(ahead).argmax())
    r0, r1, c0, c1 = rows.min(), rows.max(), cols.min(), cols.max()
    rr = np.linspace(r0 - MARGIN * (r1 - r0), r1 + MARGIN * (r1 - r0), CROP_SHAPE[0])
    cc = np.linspace(c0 - MARGIN * (c1 - c0), c1 + MARGIN * (c1 - c0), CROP_SHAPE[1])
    R, C = np.meshgrid(rr, cc, indexing="ij")
    h, w = z.shape
    inside = (R >= 0) & (R <= h - 1) & (C >= 0) & (C <= w - 1)  # outside the frame: black, as render.crop_view
    crop = np.where(inside, ndimage.map_coordinates(g, [R, C], order=1, mode="nearest"), 0.0)
    return agree, np.round(255 * np.clip(crop, 0, 1)).astype(np.uint8)


def pane_crop(image, depth, intrinsics, distance_m: float) -> tuple[float, np.ndarray | None]:
    """The share of straight-ahead depth readings at the echo's distance, and the pane's crop.

    The crop, when the share is under half, is of the region the sensor reads past the echo's
    plane (see the module's notes).

    Parameters
    ----------
    image : numpy.ndarray [shape=(H, W)]
        Grayscale, uint8 or floats in [0, 1]; at least 16 x 16 pixels.
    depth : numpy.ndarray [shape=(H, W)]
        The depth sensor's z-depth in metres, registered to ``image``; 0 (or NaN) where it
        returns nothing.
    intrinsics : numpy.ndarray [shape=(3, 3)]
        The camera's pinhole matrix.
    distance_m : float
        The echo's distance in metres (not checked here: :func:`look` checks it).

    Returns
    -------
    agree : float
        The share, in [0, 1], of the straight-ahead readings within :func:`depth_window`.
    crop : numpy.ndarray [shape=(64, 25), dtype=uint8] or None
        The pane's crop; None when ``agree`` is at least 0.5, or when nothing straight ahead
        reads past the echo's plane.

    Raises
    ------
    VrechoError
        For frames of different shapes or under 16 x 16 pixels, an image that is neither uint8
        nor finite floats in [0, 1], or intrinsics that are not a 3 x 3 pinhole matrix with
        positive focal lengths and the principal point in the frame.

    Examples
    --------
    >>> import numpy as np
    >>> from vrecho.headset import pane_crop
    >>> K = np.array([[60.0, 0, 32], [0, 60.0, 24], [0, 0, 1]])
    >>> depth = np.full((48, 64), 2.0)
    >>> depth[10:40, 20:50] = 0.0  # a pane the sensor gets nothing back from
    >>> agree, crop = pane_crop(np.zeros((48, 64), np.uint8), depth, K, 2.0)
    >>> agree, crop.shape
    (0.0, (64, 25))
    """
    return _pane(*_frame(image, depth, intrinsics), distance_m)


def look(image, depth, intrinsics, distance_m: float, *, model: EchoCNN | None = None) -> SurfaceView | None:
    """What a camera frame says of the surface an echo found ``distance_m`` straight ahead.

    A wall needs no network; glass or a mirror is told by the visual branch (torch is imported
    then).

    Parameters
    ----------
    image : numpy.ndarray [shape=(H, W)]
        Grayscale, uint8 or floats in [0, 1], from a camera beside the loudspeaker looking along
        the wearer's forward axis; at least 16 x 16 pixels.
    depth : numpy.ndarray [shape=(H, W)]
        The depth sensor's z-depth in metres, registered to ``image``; 0 (or NaN) where it
        returns nothing.
    intrinsics : numpy.ndarray [shape=(3, 3)]
        The camera's pinhole matrix (pixels).
    distance_m : float
        The echo's distance in metres, from the loudspeaker.
    model : EchoCNN, optional
        The visual branch; :func:`load_model`'s by default.

    Returns
    -------
    SurfaceView or None
        None when the frame cannot tell: the depth sensor returned nothing anywhere (off, or
        blinded), or something nearer than the echo fills the view ahead.

    Raises
    ------
    VrechoError
        For a bad frame or intrinsics (as :func:`pane_crop`), or a distance that is not a
        positive finite number.

    Examples
    --------
    >>> import numpy as np
    >>> from vrecho.headset import look
    >>> K = np.array([[60.0, 0, 32], [0, 60.0, 24], [0, 0, 1]])
    >>> depth = np.full((48, 64), 2.0)  # a wall 2 m ahead fills the view
    >>> view = look(np.zeros((48, 64), np.uint8), depth, K, 2.0)
    >>> view.surface, view.confidence
    ('wall', 1.0)
    """
    return look_all(image, depth, intrinsics, [distance_m], model=model)[0]


def look_all(image, depth, intrinsics, distances_m, *, model: EchoCNN | None = None) -> list[SurfaceView | None]:
    """:func:`look` for several echoes' distances in one frame.

    The frame is read once, and the crops are classified in one batch.

    Parameters
    ----------
    image, depth, intrinsics
        The frame, as for :func:`look`.
    distances_m : sequence of float
        The echoes' distances in metres, from the loudspeaker.
    model : EchoCNN, optional
        The visual branch; :func:`load_model`'s by default.

    Returns
    -------
    list of SurfaceView or None
        One per distance, in order, as :func:`look` answers.

    Raises
    ------
    VrechoError
        As :func:`look`, for any of the distances.
    """
    g, z, cone = _frame(image, depth, intrinsics)
    for d in distances_m:
        if not np.isfinite(d) or d <= 0:
            raise VrechoError(f"distance_m: expected a positive distance, got {d!r}")
    panes = [_pane(g, z, cone, d) for d in distances_m]
    blind = not np.any(z > 0)  # a pane only where the sensor returns something somewhere
    crops = [] if blind else [crop for _, crop in panes if crop is not None]
    p_mirror = iter(material_probability(np.stack(crops), model=model) if crops else ())
    out = []
    for agree, crop in panes:
        if agree >= 0.5:
            out.append(SurfaceView("wall", min(1.0, 0.5 + agree / 2), agree))
        elif crop is None or blind:
            out.append(None)
        else:
            p = float(next(p_mirror))
            out.append(SurfaceView("mirror" if p > 0.5 else "glass", max(p, 1 - p), agree, crop))
    return out


def material_probability(crops: np.ndarray, *, model: EchoCNN | None = None) -> np.ndarray:
    """P(mirror) of each crop, from the visual branch.

    Parameters
    ----------
    crops : numpy.ndarray [shape=(N, 64, 25), dtype=uint8]
        Pane crops, as :func:`pane_crop` makes them.
    model : EchoCNN, optional
        The visual branch; :func:`load_model`'s by default.

    Returns
    -------
    numpy.ndarray [shape=(N,), dtype=float32]
        The probability that each crop shows a mirror (rather than glass).
    """
    import torch  # heavy (1.7 s): the audio path imports this module and never classifies

    model = model or load_model()
    x = torch.as_tensor(np.asarray(crops, np.float32) / 255)
    with torch.no_grad():
        return torch.softmax(model({"image": x})["material"], 1)[:, 1].numpy()


_MODEL: EchoCNN | None = None


def load_model(path: str | Path | None = None) -> EchoCNN:
    """The visual branch with the weights shipped in the package, or those of ``path``.

    Parameters
    ----------
    path : str or pathlib.Path, optional
        Weights written by :func:`save` (as :mod:`vrecho.learn.headset_view` does); None: the
        shipped ones, loaded once and kept.

    Returns
    -------
    EchoCNN
        The model, in evaluation mode.

    Raises
    ------
    VrechoError
        When ``path`` is no file, or not a headset-view model.
    """
    global _MODEL
    if path is None and _MODEL is not None:
        return _MODEL
    if path is None:
        with resources.as_file(resources.files("vrecho.assets") / WEIGHTS) as p:
            _MODEL = _load(Path(p))
        return _MODEL
    if not Path(path).is_file():
        raise VrechoError(f"model: no such file {path}")
    return _load(Path(path))


def _load(path: Path) -> EchoCNN:
    import torch  # heavy (1.7 s): the audio path imports this module and never classifies

    from ..models import build  # torch-bound, as above

    try:
        saved = torch.load(path, weights_only=True)
        model = build(saved["config"])
        model.load_state_dict({k: v.float() if v.is_floating_point() else v for k, v in saved["state"].items()})
    except Exception as e:  # a foreign or damaged file: say which
        raise VrechoError(f"model: {path} is not a headset-view model ({type(e).__name__})") from None
    return model.eval()


def save(model: EchoCNN, path: str | Path) -> None:
    """Write the weights in half precision (the crops' classes need no more), with the model's config.

    Parameters
    ----------
    model : EchoCNN
        The visual branch to save.
    path : str or pathlib.Path
        The file to write (torch's format), readable by :func:`load_model`.
    """
    import torch  # heavy (1.7 s): the audio path imports this module and never classifies

    torch.save({"config": model.config, "state": {k: v.half() if v.is_floating_point() else v
                                                  for k, v in model.state_dict().items()}}, path)
