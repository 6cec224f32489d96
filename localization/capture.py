"""What localization listens to: multichannel captures along the walkthrough, and their simulation.

A :class:`Capture` is one short stretch of recording (about 2 s) from a microphone array at one
device pose: the samples (channels x samples), the sample rate and the microphones' world
positions (metres, vrecho's frame, Z up). A walkthrough gives a list of them, one per pose the
wearer passes through; the device is taken as still within a capture (a pause or a slow turn of
the head: at 0.5 m/s a 2 s stretch spans 1 m, so a walking capture is cut shorter).

The documented array is the headset's, :data:`vrecho.scene.MIC_ARRAYS` ``"headset4"``: four
microphones on the visor, in the device frame (forward, left, up) from the emitter: (0, 0, 0.07),
(0.03, 0.08, 0.03), (0.03, -0.08, 0.03), (0, 0, 0.13) m (16 cm wide, 10 cm tall, 3 cm deep).

:func:`simulate_walk_capture` records a room's ambient sources (:mod:`vrecho.sim.sounds`)
with the foundation's acoustics: a :class:`vrecho.scene.Scene`'s room (image sources plus ray
tracing, :func:`vrecho.sim.acoustics.impulse_responses`) or a :class:`Shoebox` of a chosen
reverberation time (pyroomacoustics' image sources, absorption from Sabine's formula). Each
source plays continuously; capture ``k`` hears the stretch of it from ``k * segment_s``, with
the room's reverberation of what came before. Pink background noise and microphone self-noise
are added (PROTOCOL.md). The per-source images at every microphone come back too: they are the
reference for separation metrics.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.signal import resample_poly

from vrecho.device import MIC_ARRAYS, DevicePose, MicArray
from vrecho.errors import VrechoError, check_number
from vrecho.signals import check_fs

FS = 16_000
"""Localization's sample rate in Hz (speech and music carry little above 8 kHz)."""


SILENT_RMS = 1e-7
MAX_SAMPLE = 1e12
"""The largest sample magnitude a capture may hold: far beyond any audio format's full scale
(int32's 2^31 included), and low enough that spectra's powers stay finite in single precision."""
MAX_COORD_M = 1e6
"""The farthest a world position (microphone, source, search box) may lie from the origin, in
metres: a room's coordinates, with float64's millimetres to spare."""


@dataclass
class Capture:
    """One stretch of multichannel recording at one device pose.

    Checked on construction: one :class:`VrechoError` says what is wrong (channels of different
    lengths may be passed as a list of 1-D arrays and are refused).

    Parameters
    ----------
    audio : numpy.ndarray [shape=(M, N)] or list of M 1-D arrays
        The samples, one row per microphone, of a real number type (integers or floats; not
        bool, complex or text); kept as float64. At least one channel, at least 0.25 s (longer
        than every STFT window localization uses), finite, within :data:`MAX_SAMPLE` of zero,
        and no channel silent (rms under 1e-7).
    fs : int
        Sample rate in Hz, a whole number of at least 8000 (:data:`FS`, 16 kHz, is
        localization's own).
    mics : numpy.ndarray [shape=(M, 3)]
        The microphones' world positions in metres (vrecho's frame, Z up), one per channel,
        finite, within :data:`MAX_COORD_M` of the origin and at least 1 mm apart; kept as
        float64.
    start_s : float
        When the stretch begins in the walk, in seconds (default 0), finite.

    Raises
    ------
    VrechoError
        For any of the above not met, or ``mics`` None (unknown geometry).

    Examples
    --------
    >>> import numpy as np
    >>> from localization import Capture
    >>> mics = [[0, 0, 1.5], [0.1, 0, 1.5], [0, 0.1, 1.5], [0, 0, 1.6]]
    >>> audio = 0.01 * np.random.default_rng(0).standard_normal((4, 16000))
    >>> c = Capture(audio, 16000, mics)
    >>> c.n_mics, c.center.round(3)
    (4, array([0.025, 0.025, 1.525]))
    """

    audio: np.ndarray
    fs: int
    mics: np.ndarray
    start_s: float = 0.0

    def __post_init__(self):
        self.fs = check_fs(self.fs)
        self.start_s = check_number(self.start_s, "capture.start_s")
        if isinstance(self.audio, (list, tuple)):
            try:
                lengths = {np.shape(c) for c in self.audio}
            except ValueError:  # a ragged channel: _real_array says so
                lengths = set()
            if len(lengths) > 1:
                raise VrechoError(f"capture: channels of different lengths {[np.shape(c) for c in self.audio]}; "
                                  "every microphone must deliver the same samples")
        audio = _real_array(self.audio, "capture.audio")
        if audio.ndim != 2 or audio.shape[0] < 1:
            raise VrechoError(f"capture.audio: must be (channels, samples) with at least one channel, got shape {audio.shape}")
        if self.mics is None:
            raise VrechoError("capture: unknown microphone geometry (mics is None); give the microphones' positions")
        mics = _real_array(self.mics, "capture.mics")
        if mics.ndim != 2 or mics.shape[1] != 3 or len(mics) != len(audio):
            raise VrechoError(f"capture: mics must be ({len(audio)}, 3) positions, one per channel, got shape {mics.shape}")
        if not np.all(np.isfinite(mics)) or np.max(np.abs(mics)) > MAX_COORD_M:
            raise VrechoError(f"capture: microphone positions must be finite metres within {MAX_COORD_M:g} m of the origin")
        if len(mics) > 1 and np.min(_pair_distances(mics)) < 1e-3:
            raise VrechoError("capture: two microphones at the same position (at least 1 mm apart)")
        if audio.shape[1] < int(0.25 * self.fs):
            raise VrechoError(f"capture: {audio.shape[1]} samples is under 0.25 s at {self.fs} Hz")
        if not np.all(np.isfinite(audio)):
            raise VrechoError("capture: audio has NaN or infinite samples")
        if np.max(np.abs(audio)) > MAX_SAMPLE:
            raise VrechoError(f"capture: audio samples must lie within +/- {MAX_SAMPLE:g}, got {np.max(np.abs(audio)):g}")
        rms = np.sqrt(np.mean(audio ** 2, axis=1))
        if np.any(rms < SILENT_RMS):
            raise VrechoError(f"capture: channel {int(np.argmax(rms < SILENT_RMS))} is silent: is that microphone connected?")
        self.audio, self.mics = audio, mics

    @property
    def n_mics(self) -> int:
        """The number of microphones, M."""
        return len(self.mics)

    def audio_at(self, fs: int = FS) -> np.ndarray:
        """The recording (M, samples) at ``fs`` Hz (by default localization's own 16 kHz),
        resampled by a polyphase filter where it was recorded at another rate; the capture's
        own array (not a copy) where not.

        Parameters
        ----------
        fs : int
            The rate wanted, in Hz.

        Returns
        -------
        numpy.ndarray [shape=(M, samples')], float
        """
        if fs == self.fs:
            return self.audio
        g = np.gcd(self.fs, fs)
        return resample_poly(self.audio, fs // g, self.fs // g, axis=1)

    @property
    def center(self) -> np.ndarray:
        """The array's centre (3,) in metres: the mean of the microphones' positions."""
        return self.mics.mean(axis=0)

    @classmethod
    def at_pose(cls, audio, fs: int, pose: DevicePose, array: MicArray | str = "headset4", *, start_s: float = 0.0):
        """A capture from a known device pose and array.

        Parameters
        ----------
        audio : numpy.ndarray [shape=(M, N)]
            The samples, one row per microphone of ``array``.
        fs : int
            Sample rate in Hz.
        pose : vrecho.scene.DevicePose
            The device's pose in the world.
        array : str or vrecho.scene.MicArray
            The array, by name in :data:`vrecho.scene.MIC_ARRAYS` (default ``"headset4"``) or
            given.
        start_s : float
            When the stretch begins in the walk, in seconds.

        Returns
        -------
        Capture
            With the microphones at their world positions for ``pose``.

        Raises
        ------
        VrechoError
            For an unknown array name, or as :class:`Capture` does.
        """
        if not isinstance(pose, DevicePose):  # its checks make the rotation orthonormal
            raise VrechoError(f"pose: expected a vrecho.device.DevicePose, got {type(pose).__name__}")
        if isinstance(array, str):
            if array not in MIC_ARRAYS:
                raise VrechoError(f"array: expected one of {tuple(MIC_ARRAYS)}, got {array!r}")
            array = MIC_ARRAYS[array]
        if not isinstance(array, MicArray):
            raise VrechoError(f"array: expected a name in {tuple(MIC_ARRAYS)} or a MicArray, got {type(array).__name__}")
        offsets = _real_array(array.offsets, f"array {array.name!r}: offsets")
        if offsets.ndim != 2 or offsets.shape[1] != 3 or not np.all(np.isfinite(offsets)):
            raise VrechoError(f"array {array.name!r}: offsets must be finite (forward, left, up) triples, got {array.offsets!r}")
        return cls(audio, fs, pose.microphones(array), start_s)


def _real_array(x, where: str) -> np.ndarray:
    """``x`` as a float64 array if it holds real numbers (integers or floats): bool, complex,
    text and ragged nesting are refused rather than cast."""
    try:
        a = np.asarray(x)
    except (TypeError, ValueError):
        raise VrechoError(f"{where}: expected an array of numbers, got a ragged or mixed {type(x).__name__}") from None
    if a.dtype.kind not in "iuf":
        raise VrechoError(f"{where}: expected real numbers (integers or floats), got dtype {a.dtype}")
    return a.astype(np.float64, copy=False)


def _pair_distances(mics: np.ndarray) -> np.ndarray:
    i, j = np.triu_indices(len(mics), 1)
    return np.linalg.norm(mics[i] - mics[j], axis=1)
