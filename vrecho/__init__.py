"""vrecho: audio-augmented 3D scene reconstruction.

A phone or headset emits short pulses while it films; the echoes tell whether a hole in the scan
is an opening, a pane of glass or a mirror, and how far away it is. The method, one idea a module:

- ``scene`` (rooms, discontinuities, sources; the data model and its JSON), ``device`` (the
  capture device and its microphone arrays), ``materials`` (acoustic absorption per band),
  ``geometry`` (polygons), ``camera`` (poses, intrinsics, projection, crops, walkthrough
  paths), ``signals`` (the 16 emitted sounds, the probe, matched filters), ``features`` (log-mel
  and echo features), ``planes`` (the echo of a plane whose distance a scan gives: open or
  closed by physics), ``models`` (EchoCNN and the baselines), ``classifier``
  (:func:`load_classifier`: shipped weights, ``predict``), ``io``, ``colmap``, ``errors``;
- ``reconstruct/`` (the scan, its discontinuities, what each is, the repair), ``capture/`` (real
  phone captures), ``headset/`` (the headset call, :class:`~vrecho.headset.BoundaryMonitor`;
  ``vrecho.boundary`` is its name too).

Apart from the method: ``sim/`` (the simulator: truth to recordings, and scoring against the
truth; the method never imports it), ``learn/`` (datasets, training, evaluation), ``app/`` (what
each ``vrecho`` command does) and ``cli`` (the command's arguments).
"""

from .errors import VrechoError
from .scene import Scene, builtin_scene, load_scene

__all__ = ["Classifier", "Prediction", "load_classifier", "VrechoError", "Scene", "builtin_scene", "load_scene"]
__version__ = "0.1.0"


def load_classifier(path=None):
    """EchoCNN with the weights shipped in the package (or ``path``); see :mod:`vrecho.classifier`.

    Nothing is downloaded; torch is imported on the first call.

    Parameters
    ----------
    path : str or path, optional
        A ``classifier.pt`` written by ``vrecho train``; None for the shipped weights.

    Returns
    -------
    Classifier
        ``predict(audio, fs, *, image=None, emitted=None)`` for one 1 s frame at ``fs`` Hz,
        ``predict_batch`` for many.

    Raises
    ------
    VrechoError
        When ``path`` is not a file, or not a vrecho classifier.
    """
    from .classifier import load_classifier as load  # torch-bound (1.7 s): loaded when the classifier is asked for

    return load(path)


def __getattr__(name):  # torch loads only when the classifier is asked for
    if name in ("Classifier", "Prediction"):
        from . import classifier  # torch-bound (1.7 s), as above

        return getattr(classifier, name)
    raise AttributeError(f"module 'vrecho' has no attribute {name!r}")
