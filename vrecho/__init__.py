"""vrecho: audio-augmented 3D scene reconstruction.

A phone or headset emits short pulses while it films; the echoes tell whether a hole in the scan
is an opening, a pane of glass or a mirror, and how far away it is. Modules, one idea each:
``scene`` (rooms, surfaces, the device; JSON), ``signals`` (the 16 emitted sounds, the probe),
``acoustics`` (pyroomacoustics impulse responses and recordings), ``render`` (the ray-cast camera),
``features`` (log-mel and echo features), ``data`` (datasets), ``models`` (EchoCNN and baselines),
``train`` (targets, losses, the training loop), ``evaluate`` (the benchmark harness and tables),
``classifier`` (``load_classifier``: shipped weights, ``predict``), ``reconstruct`` (the camera's
scan and its repair), ``scan_metrics`` (a repair against the truth), ``boundary`` (the headset
call), ``headset_view`` (what the headset's camera says of the surface an echo found) and
``walks`` (simulated walks and the camera along them), ``capture`` and ``colmap`` (real captures), ``listen``
(what the device hears in front of each surface), ``cli`` (the ``vrecho`` command; ``demo``
runs the top-level :mod:`demo` package).
"""

from .errors import VrechoError
from .scene import Scene, builtin_scene, load_scene, random_scene

__all__ = ["Classifier", "Prediction", "load_classifier", "VrechoError", "Scene", "builtin_scene", "load_scene", "random_scene"]
__version__ = "0.1.0"


def load_classifier(path=None):
    """EchoCNN with the weights shipped in the package (or ``path``); see :mod:`vrecho.classifier`."""
    from .classifier import load_classifier as load

    return load(path)


def __getattr__(name):  # torch loads only when the classifier is asked for
    if name in ("Classifier", "Prediction"):
        from . import classifier

        return getattr(classifier, name)
    raise AttributeError(f"module 'vrecho' has no attribute {name!r}")
