"""The capture device (PROTOCOL.md): a loudspeaker (the emitter), a microphone 7 cm above it and a
camera at the microphone, and the microphone arrays a device may carry; :class:`DevicePose`
places one in the world.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .errors import VrechoError, check_field, check_keys, check_number, check_unit, check_vector

MIC_ABOVE_EMITTER_M = 0.07

REACH_M = 1000.0
"""The largest ``|x|``, ``|y|`` or ``|z|`` of a point read from a scene, in metres (its scene then
checks that it lies in the room): where open3d's float32 still places a point to 0.1 mm."""


@dataclass(frozen=True)
class MicArray:
    """Microphone positions in the device frame (forward, left, up), metres from the emitter.

    :data:`MIC_ARRAYS` holds the arrays a device may carry, by name.

    Parameters
    ----------
    name : str
        The array's name, its key in :data:`MIC_ARRAYS` (e.g. ``"phone"``, ``"headset4"``).
    offsets : tuple of (float, float, float)
        One (forward, left, up) offset in metres per microphone, from the emitter; channel 0
        first.
    """

    name: str
    offsets: tuple[tuple[float, float, float], ...]

    @property
    def n_mics(self) -> int:
        """Number of microphones."""
        return len(self.offsets)


MIC_ARRAYS = {
    "phone": MicArray("phone", ((0.0, 0.0, MIC_ABOVE_EMITTER_M),)),
    # Four microphones on the front corners of a headset visor, 16 cm wide and 6 cm tall, plus
    # the protocol's microphone position as the reference channel 0.
    "headset4": MicArray("headset4", ((0.0, 0.0, MIC_ABOVE_EMITTER_M), (0.03, 0.08, 0.03),
                                      (0.03, -0.08, 0.03), (0.0, 0.0, 0.13))),
}


@dataclass
class DevicePose:
    """The capture device: emitter position, forward and up axes (unit, orthogonal).

    The microphone sits 7 cm above the emitter along ``up``; the camera is at the microphone,
    looking along ``forward``. The vectors are checked and kept as float arrays (3,): ``up`` is
    made orthogonal to ``forward``, both unit length.

    Parameters
    ----------
    emitter : array_like [shape=(3,)]
        World position of the loudspeaker, in metres.
    forward : array_like [shape=(3,)]
        The direction the device faces; scaled to unit length.
    up : array_like [shape=(3,)]
        The device's up axis; its part along ``forward`` is removed, then it is scaled to unit
        length.
    target : int or None
        Index of the discontinuity the device faces (in its scene's list); None by default.

    Raises
    ------
    VrechoError
        For a vector that is not three finite numbers, a zero ``forward``, or an ``up``
        parallel to ``forward``.

    Examples
    --------
    >>> pose = DevicePose([1.0, 2.0, 1.2], forward=[1, 0, 0], up=[0, 0, 1])
    >>> pose.microphone
    array([1.  , 2.  , 1.27])
    >>> pose.microphones(MIC_ARRAYS["headset4"]).shape
    (4, 3)
    """

    emitter: np.ndarray
    forward: np.ndarray
    up: np.ndarray
    target: int | None = None

    def __post_init__(self):
        self.emitter = check_vector(self.emitter, "pose.emitter")
        self.forward = check_unit(self.forward, "pose.forward")
        up = check_unit(self.up, "pose.up")
        if abs(np.dot(up, self.forward)) > 1e-12:
            up = up - np.dot(up, self.forward) * self.forward
        if np.linalg.norm(up) < 1e-6:
            raise VrechoError("pose.up: must not be parallel to pose.forward")
        self.up = check_unit(up, "pose.up")

    @property
    def rotation(self) -> np.ndarray:
        """3 x 3 matrix whose columns are forward, left, up in the world frame."""
        return np.stack([self.forward, np.cross(self.up, self.forward), self.up], axis=1)

    @property
    def microphone(self) -> np.ndarray:
        """World position (3,) of the microphone (and camera), 7 cm above the emitter."""
        return self.emitter + MIC_ABOVE_EMITTER_M * self.up

    camera = microphone

    def microphones(self, array: MicArray) -> np.ndarray:
        """World positions of an array's microphones at this pose.

        Parameters
        ----------
        array : MicArray
            The microphones, e.g. ``MIC_ARRAYS["headset4"]``.

        Returns
        -------
        numpy.ndarray [shape=(M, 3)], float64
            One world position in metres per microphone, in the array's channel order.
        """
        return self.emitter + np.asarray(array.offsets) @ self.rotation.T

    def to_dict(self) -> dict:
        """The pose's JSON form.

        Returns
        -------
        dict
            ``emitter``, ``forward``, ``up`` (lists of 3 floats) and ``target`` (int or None).
        """
        return {"emitter": self.emitter.tolist(), "forward": self.forward.tolist(), "up": self.up.tolist(),
                "target": self.target}

    @classmethod
    def from_dict(cls, d, where: str) -> "DevicePose":
        """A pose from its JSON form (``up`` +z by default).

        Parameters
        ----------
        d : dict
            The JSON object, as :meth:`to_dict` writes it; ``up`` and ``target`` may be left out.
        where : str
            The pose's path in the file (e.g. ``"poses[0]"``), which errors name.

        Returns
        -------
        DevicePose

        Raises
        ------
        VrechoError
            Naming the field under ``where`` that is missing or impossible, e.g. a ``target``
            that is not an index or null.
        """
        check_keys(d, ("emitter", "forward", "up", "target"), where)
        target = check_field(d, "target", where, None)
        if target is not None:
            check_number(target, f"{where}.target", lo=0)  # its scene checks it names one of its own
            if not isinstance(target, int):
                raise VrechoError(f"{where}.target: expected a discontinuity index (a whole number) or null, "
                                  f"got {target!r}")
        try:
            return cls(check_vector(check_field(d, "emitter", where), f"{where}.emitter", lo=-REACH_M, hi=REACH_M),
                       check_field(d, "forward", where), check_field(d, "up", where, [0.0, 0.0, 1.0]), target)
        except VrechoError as e:
            raise VrechoError(str(e).replace("pose.", f"{where}.", 1)) from None
