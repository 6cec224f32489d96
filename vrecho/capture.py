"""Real captures: a phone's recording of vrecho's pulse train, cut into PROTOCOL.md's frames.

The capture (PROTOCOL.md): a loudspeaker beside the camera plays a pulse train (100 ms of the
probe, then 900 ms of silence) while the camera films; each frame is 1.0 s of microphone signal
from a pulse's onset. A real recording does not say where its pulses are: it starts anywhere,
the two clocks drift apart (a player's 44.1 kHz is not the recorder's), pulses are drowned by a
door slam or lost to a dropout, the microphone clips. :func:`find_onsets` finds them:

1. **Matched filter.** The recording correlated with the emitted pulse (FFT), and its envelope
   (analytic signal): a pulse's direct sound stands out by the pulse's time-bandwidth product
   (about 36 dB for the 100 ms probe) above noise, and clipping keeps the peak where it was.
2. **Candidates.** The strongest lag within each half period, at least ``min_snr_db`` above the
   envelope's median (the noise floor).
3. **The train.** The period is measured (the median spacing of candidates 0.95 to 1.05 nominal
   periods apart: the clocks' drift); a candidate is a pulse when another lies one to four whole
   periods away (within ``tolerance_s`` per period): a clap or a door does not recur on the
   period, and pulses missing on both sides of one do not lose it (nor does one alone between
   two pauses, as loud as the train to 1.5 dB). Where two pulses lie a whole number of periods
   apart (to a millisecond a period), the pulses between are missing; where the gap is not
   whole (the player paused, or looped its file), the train starts again and nothing is
   missing. A
   stronger echo is not taken for the direct sound: the onset is the highest lag within a
   quarter millisecond of the first, within 20 ms before the peak, whose envelope reaches half
   of it.
4. **Sub-sample time.** A parabola through the envelope's three samples at the peak.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .errors import VrechoError
from .signals import FS, PERIOD_S, analytic_envelope, analytic_filter, parabolic_peaks


@dataclass
class Onsets:
    """Pulses found in a recording.

    ``samples`` (K,) where each pulse's direct sound begins (fractional samples from the
    recording's first), ``strength_db`` (K,) its matched-filter peak above the noise floor,
    ``missing`` (J,) where a pulse was due but none was found, ``period_s`` the train's period
    as measured (the clocks' drift included), ``fs`` the rate.
    """

    samples: np.ndarray
    strength_db: np.ndarray
    missing: np.ndarray
    period_s: float
    fs: int

    @property
    def seconds(self) -> np.ndarray:
        return self.samples / self.fs


def _mono(audio, fs) -> tuple[np.ndarray, int]:
    x = np.asarray(audio, dtype=np.float64)
    if x.ndim == 2:  # (n, channels) or (channels, n): the first channel
        x = x[:, 0] if x.shape[0] > x.shape[1] else x[0]
    if x.ndim != 1 or x.size == 0:
        raise VrechoError(f"audio: expected a 1-D recording (or channels x samples), got shape {np.shape(audio)}")
    if not np.all(np.isfinite(x)):
        raise VrechoError("audio: the recording holds NaN or infinite samples")
    if not isinstance(fs, (int, np.integer)) or fs < 8000:
        raise VrechoError(f"fs: expected an integer sample rate of at least 8000 Hz, got {fs!r}")
    return x, int(fs)


def matched_envelope(audio, emitted, fs: int = FS) -> np.ndarray:
    """Envelope of the recording correlated with the emitted pulse: entry ``l`` is how much of
    the pulse starts at sample ``l`` (length len(audio) - len(emitted) + 1)."""
    from scipy import fft

    x, fs = _mono(audio, fs)
    s = np.asarray(emitted, dtype=np.float64)
    if s.ndim != 1 or not 8 <= s.size <= x.size:
        raise VrechoError(f"emitted: expected a 1-D pulse shorter than the recording ({x.size} samples), got shape {s.shape}")
    n = fft.next_fast_len(x.size + s.size, real=True)
    return analytic_envelope(x, analytic_filter(s, n), n)[:x.size - s.size + 1] / np.linalg.norm(s)


def find_onsets(audio, fs: int = FS, emitted=None, period_s: float = PERIOD_S, min_snr_db: float = 12.0,
                tolerance_s: float = 0.01) -> Onsets:
    """The pulse train's onsets in a recording (see the module's notes).

    Parameters
    ----------
    audio : array, shape (n,) or (n, channels)
        The recording (the first channel is used).
    fs : int
        Its sample rate (Hz).
    emitted : array, optional
        The pulse played (default: vrecho's probe, :func:`~vrecho.signals.probe`, at ``fs``).
    period_s : float
        The nominal period (PROTOCOL.md: 1 s); the measured one may differ by a few per cent.
    min_snr_db : float
        How far above the noise floor a pulse's matched-filter peak must rise.
    tolerance_s : float
        How far from its due time a pulse may be (per period of a gap).

    Raises
    ------
    VrechoError
        When no pulse train is found (fewer than two pulses a period apart).
    """
    from scipy.ndimage import maximum_filter1d

    from .signals import probe

    x, fs = _mono(audio, fs)
    s = probe(fs) if emitted is None else np.asarray(emitted, dtype=np.float64)
    if not 0.1 <= period_s <= 10:
        raise VrechoError(f"period_s: expected 0.1 to 10 s, got {period_s}")
    env = matched_envelope(x, s, fs)
    period = period_s * fs
    floor = float(np.median(env)) + 1e-12
    half = max(int(period // 2), 1)
    peaks = np.flatnonzero((env == maximum_filter1d(env, half, mode="nearest")) & (env > floor * 10 ** (min_snr_db / 20)))
    if len(peaks) < 2:
        raise VrechoError(f"audio: no pulse train found ({len(peaks)} pulse(s) {min_snr_db:.0f} dB above the noise "
                          f"in {x.size / fs:.1f} s); expected vrecho's pulse every {period_s:g} s")
    # The train: candidates with another a whole number of periods away (up to four: pulses may be
    # missing on both sides); a clap or a door does not recur on the period.
    tol = tolerance_s * fs
    pairs = [(j, peaks[j:] - peaks[:-j]) for j in range(1, len(peaks)) if (peaks[j:] - peaks[:-j]).min() < 4.5 * period]
    near = np.concatenate([d[(d > 0.95 * period) & (d < 1.05 * period)] for _, d in pairs])
    period = float(np.median(near)) if len(near) else period  # the clocks' drift, measured
    support = np.zeros(len(peaks), bool)
    for j, d in pairs:
        m = np.round(d / period)
        ok = (m >= 1) & (m <= 4) & (np.abs(d - m * period) <= tol * np.maximum(m, 1))
        support[j:] |= ok
        support[:-j] |= ok
    # The direct sound comes as loud every time (the loudspeaker stays beside the microphone):
    # two noise peaks that happen to lie periods apart are far weaker than the train, and a
    # pulse alone between two pauses is as strong as the rest.
    if support.any():
        level = np.median(env[peaks[support]])
        support = (support & (env[peaks] >= 0.1 * level)) | (np.abs(20 * np.log10(env[peaks] / level)) <= 1.5)
    idx = peaks[support]
    if len(idx) < 2:
        raise VrechoError(f"audio: no pulse train found: pulses do not recur every {period_s:g} s "
                          f"(within {tolerance_s * 1000:.0f} ms)")
    # The direct sound is the first strong arrival: an echo may outdo it by a little.
    lead, lobe = int(0.02 * fs), max(int(0.00025 * fs), 3)  # a quarter millisecond: past the main lobe, before any echo
    for j, i in enumerate(idx):
        w = env[max(i - lead, 0):i + 1]
        first = max(i - lead, 0) + int(np.flatnonzero(w >= 0.5 * env[i])[0])
        idx[j] = first + int(np.argmax(env[first:first + lobe]))  # that arrival's own peak
    samples = parabolic_peaks(env, idx)
    gaps = np.diff(samples)
    k = np.round(gaps / period)
    whole = (k >= 1) & (np.abs(gaps - k * period) <= tol * np.maximum(k, 1))
    period = float(np.median(gaps[whole] / k[whole])) if whole.any() else period
    # Missing pulses: where two found lie a whole number of periods apart, to a millisecond a
    # period (the player's clock keeps the beat to a sample); any other gap (the player paused,
    # or looped its file) starts the train again and misses nothing.
    k = np.round(gaps / period).astype(int)
    missing = [a + j * g / m for a, g, m in zip(samples, gaps, k)
               if m >= 2 and abs(g - m * period) <= 0.001 * fs * m for j in range(1, m)]
    return Onsets(samples, 20 * np.log10(env[idx] / floor), np.array(missing), period / fs, fs)


def cut_frames(audio, onsets: Onsets, length_s: float = 1.0, mic_offset_m: float | None = None) -> np.ndarray:
    """PROTOCOL.md's frames: ``length_s`` of the recording from each pulse's emission (the direct
    sound's onset less its flight from the loudspeaker, ``mic_offset_m`` away: PROTOCOL's device
    by default), resampled to 44.1 kHz, each shifted by its fraction of a sample (a linear phase)
    so that sample 0 is the emission. Frames that would run past the recording's end are left
    out. Returns (K, n) float32."""
    import librosa

    from .acoustics import SPEED_OF_SOUND
    from .scene import MIC_ABOVE_EMITTER_M

    x, fs = _mono(audio, onsets.fs)
    offset = MIC_ABOVE_EMITTER_M if mic_offset_m is None else mic_offset_m
    starts = (onsets.samples - offset / SPEED_OF_SOUND * fs) * FS / fs
    if fs != FS:
        x = librosa.resample(x, orig_sr=fs, target_sr=FS)
    n, pad = int(round(length_s * FS)), 64
    frames = []
    for t in starts:
        i = int(np.floor(t))
        if i - pad < 0 or i + n + pad > x.size:
            continue
        seg = x[i - pad:i + n + pad]
        f = np.fft.rfftfreq(seg.size)
        seg = np.fft.irfft(np.fft.rfft(seg) * np.exp(2j * np.pi * f * (t - i)), seg.size)  # advance by the fraction
        frames.append(seg[pad:pad + n])
    return np.array(frames, np.float32).reshape(-1, n)


def read_video(path) -> tuple[np.ndarray, int, np.ndarray]:
    """A video's sound and the times of its pictures, decoded with PyAV (FFmpeg's libraries).

    Returns the first audio stream mixed to mono (float32, its own rate), the rate (Hz), and
    each video frame's presentation time (s, from the audio's start). One :class:`VrechoError`
    for a file that is not a video, a codec FFmpeg cannot decode, or a video without sound."""
    import av

    path = str(path)
    try:
        with av.open(path) as container:
            if not container.streams.audio:
                raise VrechoError(f"{path}: the video has no audio track; vrecho needs the microphone's recording "
                                  "of its pulses (or give --audio WAV)")
            astream = container.streams.audio[0]
            chunks, times, a0 = [], [], None
            streams = [astream] + list(container.streams.video[:1])
            for packet in container.demux(streams):
                if packet.stream.type == "video":  # its time is enough: pictures are decoded only when wanted
                    if packet.pts is not None:
                        times.append(float(packet.pts * packet.time_base))
                    continue
                for frame in packet.decode():
                    if a0 is None:
                        a0 = float(frame.time or 0.0)
                    raw = frame.to_ndarray()
                    a = raw.astype(np.float32)
                    if frame.format.is_planar:
                        a = a.mean(axis=0)
                    else:  # interleaved: (1, n * channels)
                        a = a.reshape(-1, len(frame.layout.channels)).mean(axis=1)
                    if np.issubdtype(raw.dtype, np.integer):
                        a /= float(np.iinfo(raw.dtype).max)
                    chunks.append(a)
            fs = int(astream.rate)
    except av.FFmpegError as e:
        raise VrechoError(f"{path}: cannot decode it ({e}); expected a video FFmpeg reads (MP4/MOV/MKV with "
                          "H.264/HEVC and AAC/PCM/FLAC sound)") from None
    if not chunks:
        raise VrechoError(f"{path}: the audio track holds no samples")
    return np.concatenate(chunks), fs, np.array(sorted(times)) - (a0 or 0.0)


def video_images(path, times_s, width: int | None = None) -> np.ndarray:
    """Grayscale pictures (K, H, W) uint8 of a video at the given times (s from the sound's start;
    the picture shown then: the last one that started), decoded in one pass (FFmpeg's threads),
    scaled to ``width`` pixels across (aspect kept) if given."""
    import av

    times_s = np.asarray(times_s, float)
    try:
        return _pictures(av.open(str(path)), times_s, width)
    except av.FFmpegError as e:
        raise VrechoError(f"{path}: cannot decode its pictures ({e}); expected H.264 or HEVC video") from None


def _pictures(container, times_s: np.ndarray, width: int | None) -> np.ndarray:
    out = [None] * len(times_s)
    order = np.argsort(times_s)
    k, last, t0 = 0, None, None
    with container:
        if not container.streams.video:
            raise VrechoError(f"{container.name}: the file has no pictures; give a video (or --audio with --images)")
        a = container.streams.audio
        container.streams.video[0].thread_type = "AUTO"
        size = {}
        for frame in container.decode(video=0):
            if width is not None and not size:
                size = {"width": width, "height": int(round(frame.height * width / frame.width))}
            if t0 is None:
                t0 = float(a[0].start_time * a[0].time_base) if a and a[0].start_time is not None else 0.0
            t = float(frame.time) - t0
            while k < len(order) and times_s[order[k]] < t:
                out[order[k]] = (last if last is not None else frame).to_ndarray(format="gray", **size)
                k += 1
            if k == len(order):
                break
            last = frame  # converted only if a time falls in it
    for j in order[k:]:
        out[j] = last.to_ndarray(format="gray", **size)
    return np.stack(out)


def write_video(path, gray: np.ndarray, fps: float, audio: np.ndarray, fs: int, audio_codec: str = "flac",
                audio_bit_rate: int = 256_000) -> None:
    """Mux grayscale pictures (K, H, W) uint8 (an array, or any iterable of (H, W) pictures) at
    ``fps`` and a mono sound (float in [-1, 1]) into a video file with PyAV (H.264; the sound as
    ``audio_codec``: "flac" in MKV is lossless, "aac" in MP4 is what phones write, at
    ``audio_bit_rate``). For simulated captures, tests and benchmarks."""
    import itertools
    from fractions import Fraction

    import av

    pictures = iter(gray)
    first = np.asarray(next(pictures), np.uint8)
    with av.open(str(path), "w") as container:
        v = container.add_stream("libx264", rate=Fraction(fps).limit_denominator(1000))
        v.width, v.height, v.pix_fmt = first.shape[1], first.shape[0], "yuv420p"
        a = container.add_stream(audio_codec, rate=fs, layout="mono")
        if audio_codec != "flac":
            a.bit_rate = audio_bit_rate
        pcm = np.clip(np.asarray(audio, np.float32), -1, 1)
        fmt = "s16" if audio_codec == "flac" else "fltp"
        block = 1024
        for k in range(0, len(pcm), block):
            chunk = pcm[k:k + block][None]
            frame = av.AudioFrame.from_ndarray((chunk * 32767).astype(np.int16) if fmt == "s16" else chunk,
                                               format=fmt, layout="mono")
            frame.sample_rate, frame.pts = fs, k
            for packet in a.encode(frame):
                container.mux(packet)
        for packet in a.encode(None):
            container.mux(packet)
        for i, g in enumerate(itertools.chain([first], pictures)):
            frame = av.VideoFrame.from_ndarray(np.asarray(g, np.uint8), format="gray")
            frame.pts = i
            for packet in v.encode(frame):
                container.mux(packet)
        for packet in v.encode(None):
            container.mux(packet)


def simulate_recording(ir: np.ndarray, n_pulses: int, rng: np.random.Generator, fs: int = FS, emitted=None,
                       snr_db: float = 30.0, drift: float = 0.0, clip: float | None = None,
                       dropped: tuple[int, ...] = (), lead_s: float = 0.3,
                       pauses: dict[int, float] | None = None) -> tuple[np.ndarray, np.ndarray]:
    """A recording of the pulse train as a phone makes it, with the truth: the microphone's
    signal (float32) and where each pulse's direct sound begins (fractional samples; NaN for a
    dropped pulse).

    ``ir``: the room's impulse response from the loudspeaker to the microphone (sample 0: the
    emission; :func:`~vrecho.acoustics.device_impulse_response`), whose first arrival is the
    direct sound; or one per pulse (n_pulses, n), the device moving; pulses every ``PERIOD_S * (1 + drift)`` s from ``lead_s`` plus a random
    fraction of a sample (the two clocks are not aligned), pulses in ``dropped`` not played,
    the train held back by ``pauses[k]`` seconds from pulse k on (the player paused, or looping
    its file with a gap at the seam);
    pink noise ``snr_db`` below the direct sound, clipped at ``clip`` times the direct sound's
    peak (if given).
    """
    from .acoustics import _microphone
    from .signals import probe

    s = probe(fs) if emitted is None else np.asarray(emitted, dtype=np.float64)
    irs = np.asarray(ir, dtype=np.float64)
    irs = np.broadcast_to(irs, (n_pulses, irs.shape[-1])) if irs.ndim == 1 else irs
    if irs.shape[0] != n_pulses:
        raise VrechoError(f"ir: expected one response, or one per pulse ({n_pulses}), got shape {np.shape(ir)}")
    period = PERIOD_S * (1 + drift) * fs
    n = int(lead_s * fs + (n_pulses + 0.5) * period) + irs.shape[1]
    starts = lead_s * fs + rng.uniform(0, 1) + np.arange(n_pulses) * period
    for k, pause in (pauses or {}).items():
        starts[k:] += pause * fs
    n += int(sum((pauses or {}).values()) * fs)
    x = np.zeros(n)
    m = 1 << int(np.ceil(np.log2(s.size + irs.shape[1] + 64)))
    spectrum = np.fft.rfft(s, m)
    freqs = np.fft.rfftfreq(m)
    shared = np.fft.rfft(irs[0], m) if np.ndim(ir) == 1 else None
    for k, t in enumerate(starts):
        if k in dropped:
            continue
        i = int(np.floor(t))  # the pulse delayed by its fraction of a sample, through its response
        heard = np.fft.irfft(spectrum * np.exp(-2j * np.pi * freqs * (t - i))
                             * (shared if shared is not None else np.fft.rfft(irs[k], m)), m)
        x[i:i + m] += heard[:n - i]
    a = np.abs(irs)
    direct = np.argmax(a > 0.5 * a.max(axis=1, keepdims=True), axis=1)  # each response's first strong arrival
    offset = np.array([parabolic_peaks(r, np.array([d]))[0] for r, d in zip(a, direct)])  # its sub-sample time
    amp = float(a.max())
    x = _microphone(x, s, amp, rng, snr_db, 80.0, 0.0).astype(np.float64)
    if clip is not None:
        rail = clip * amp * np.abs(s).max()
        x = np.clip(x, -rail, rail)
    truth = starts + offset
    truth[list(dropped)] = np.nan
    return x.astype(np.float32), truth


PULSE_TRAIN_WAV = Path(__file__).parent / "assets" / "pulse_train.wav"
"""The pulse train for the second phone to play (on repeat): 30 s of vrecho's probe once a
second (:func:`~vrecho.signals.pulse_train` of :func:`~vrecho.signals.probe`), 44.1 kHz, 16-bit
PCM. A player's gap at the loop's seam costs nothing: :func:`find_onsets` restarts the train."""
VIEW_WIDTH = 320
"""Pictures and depth frames of a posed capture are worked at this width (pixels), as the
simulator's camera: hole carving and EchoCNN's 64 x 25 crop need no more."""
MAX_POSE_GAP_S = 1.0
"""A pulse takes the pose of the pictures around it (interpolated) when one lies this close."""


def read_audio(path) -> tuple[np.ndarray, int]:
    """A sound file (WAV, FLAC, ...) mixed to mono, float32, and its rate."""
    import soundfile as sf

    try:
        x, fs = sf.read(str(path), dtype="float32", always_2d=True)
    except (sf.LibsndfileError, RuntimeError) as e:
        raise VrechoError(f"{path}: cannot read it as sound ({e}); expected WAV or FLAC") from None
    return x.mean(axis=1), int(fs)


def interpolate_poses(times, key_times, key_poses, max_gap_s: float = MAX_POSE_GAP_S) -> tuple[np.ndarray, np.ndarray]:
    """Camera-to-world poses (K, 4, 4) at ``times`` (s) from posed pictures at ``key_times``:
    positions linear and rotations spherical between the two pictures around each time, or the
    nearest picture's beyond either end. ``ok`` (K,) says which times have a picture within
    ``max_gap_s``; the others get the nearest pose, not to be used."""
    from scipy.spatial.transform import Rotation, Slerp

    times = np.asarray(times, float)
    order = np.argsort(key_times)
    kt, kp = np.asarray(key_times, float)[order], np.asarray(key_poses, float)[order]
    kt, first = np.unique(kt, return_index=True)  # one pose per time
    kp = kp[first]
    ok = np.min(np.abs(times[:, None] - kt[None]), axis=1) <= max_gap_s if len(times) else np.zeros(0, bool)
    tc = np.clip(times, kt[0], kt[-1])
    out = np.tile(np.eye(4), (len(times), 1, 1))
    if len(kt) == 1:
        out[:] = kp[0]
        return out, ok
    out[:, :3, :3] = Slerp(kt, Rotation.from_matrix(kp[:, :3, :3]))(tc).as_matrix()
    for axis in range(3):
        out[:, axis, 3] = np.interp(tc, kt, kp[:, axis, 3])
    return out, ok


def _view_intrinsics(camera, width: int = VIEW_WIDTH) -> tuple[np.ndarray, int, int]:
    """A COLMAP camera's pinhole matrix scaled to ``width`` pixels across (pixel centres at
    integers), and the scaled size."""
    s = width / camera.width
    K = camera.intrinsics.copy()
    K[:2, :2] *= s
    K[:2, 2] = s * (K[:2, 2] + 0.5) - 0.5
    return K, width, int(round(camera.height * s))


def _image_files(folder: Path, names: list[str] | None) -> list[Path]:
    if not folder.is_dir():
        raise VrechoError(f"images: {folder} is not a folder of pictures")
    if names is None:
        files = sorted(p for p in folder.iterdir() if p.suffix.lower() in (".png", ".jpg", ".jpeg"))
        if not files:
            raise VrechoError(f"images: {folder} holds no .png or .jpg pictures")
        return files
    files = [folder / n for n in names]
    absent = [f.name for f in files if not f.is_file()]
    if absent:
        raise VrechoError(f"images: {len(absent)} of the pictures images.txt names are not in {folder} "
                          f"(first: {absent[0]})")
    return files


def _load_pictures(files: list[Path], width: int | None) -> np.ndarray:
    from PIL import Image

    out = []
    for f in files:
        im = Image.open(f).convert("L")
        if width is not None:
            im = im.resize((width, int(round(im.height * width / im.width))), Image.BILINEAR)
        out.append(np.asarray(im, np.uint8))
    return np.stack(out)


@dataclass
class Poses:
    """A capture's posed pictures (from COLMAP's text model, :mod:`vrecho.colmap`): the camera's
    ``intrinsics`` at the working size (``width`` x ``height``), each picture's ``name``,
    ``time_s`` on the recording's clock and camera-to-world ``pose`` in a z-up world;
    ``to_z_up`` (4, 4) turns the model's world into that one (identity, or a y-up world turned)."""

    intrinsics: np.ndarray
    width: int
    height: int
    names: list[str]
    time_s: np.ndarray
    pose: np.ndarray
    to_z_up: np.ndarray


def read_poses(folder, image_fps: float, duration_s: float, video_start_s: float = 0.0) -> Poses:
    """COLMAP's text model in ``folder`` for a capture of ``duration_s`` seconds, its pictures
    numbered from 1 at ``image_fps`` (:func:`vrecho.colmap.image_times`) from the video's first
    picture, ``video_start_s`` after the sound's start. Checked: one camera, pictures within the
    recording, the cameras upright in a z-up world (a y-up world is turned z up)."""
    from . import colmap

    cameras, images = colmap.read_model(folder)
    used = {im.camera_id for im in images}
    if len({(cameras[c].model, cameras[c].width, cameras[c].height, tuple(cameras[c].params)) for c in used}) > 1:
        raise VrechoError(f"poses: the images use {len(used)} different cameras; expected the one camera of a video "
                          "(COLMAP: --ImageReader.single_camera 1)")
    K, w, h = _view_intrinsics(cameras[images[0].camera_id])
    names = [im.name for im in images]
    times = colmap.image_times(names, image_fps) + video_start_s
    if times.max() > duration_s + 1.0 or times.min() < -1.0:
        raise VrechoError(f"poses do not match the recording: images.txt's pictures lie at {times.min():.1f} to "
                          f"{times.max():.1f} s (numbered at --image-fps {image_fps:g}), the recording lasts "
                          f"{duration_s:.1f} s; expected the poses of this video's pictures and their extraction rate")
    pose = np.stack([im.pose for im in images])
    up = np.median(-pose[:, :3, 1], axis=0)  # OpenCV's y points down
    to_z_up = np.eye(4)
    if up[1] >= np.cos(np.radians(45)):  # a y-up world (ARKit's, OpenGL's): turned z up
        to_z_up[:3, :3] = [[1, 0, 0], [0, 0, -1], [0, 1, 0]]
        pose = to_z_up @ pose
    elif up[2] < np.cos(np.radians(45)):
        raise VrechoError(f"poses: the cameras' up axes point {np.round(up, 2).tolist()}, up neither the world's z nor "
                          "its y; expected a metric model with gravity along -z or -y (a phone's tracked poses, or "
                          "a COLMAP model scaled and levelled with `colmap model_aligner`)")
    order = np.argsort(times, kind="stable")
    return Poses(K, w, h, [names[k] for k in order], times[order], pose[order], to_z_up)


def posed_scan(mesh, poses: Poses, pictures: np.ndarray, frames: np.ndarray, frame_times: np.ndarray,
               frame_pictures: np.ndarray, emitted: np.ndarray, min_hit: float = 0.3):
    """A :class:`~vrecho.reconstruct.Scan` of a user's mesh and capture: one view per posed
    picture and one per pulse frame (the pose interpolated at its emission), each with the depth
    the mesh gives along its rays (:func:`~vrecho.render.mesh_depth`) and its picture (uint8 at
    the working size), and the pulses' frames as its echoes. Pulses with no posed picture within
    :data:`MAX_POSE_GAP_S` are left out; returns the scan and which frames it holds."""
    from .reconstruct import Echoes, Scan
    from .render import View, mesh_depth

    pulse_pose, ok = interpolate_poses(frame_times, poses.time_s, poses.pose)
    if not ok.any():
        raise VrechoError(f"poses do not match the recording: no pulse ({len(frame_times)} from "
                          f"{frame_times.min():.1f} to {frame_times.max():.1f} s) lies within {MAX_POSE_GAP_S:g} s of "
                          f"a posed picture ({poses.time_s.min():.1f} to {poses.time_s.max():.1f} s)")
    all_pose = np.concatenate([poses.pose, pulse_pose[ok]])
    depth = mesh_depth(mesh, all_pose, poses.intrinsics, poses.width, poses.height)
    hit = float(np.mean(depth[len(poses.pose):] > 0))
    if hit < min_hit:
        raise VrechoError(f"mesh: only {hit:.0%} of what the camera sees at the pulses meets the mesh; expected the "
                          "surfaces in view (the mesh and images.txt in one world frame, metric, z up)")
    gray = np.concatenate([pictures, frame_pictures[ok]]).astype(np.float32) / 255
    if gray.shape[1:] != depth.shape[1:]:
        raise VrechoError(f"images: pictures of {gray.shape[2]} x {gray.shape[1]} pixels at the working width, the "
                          f"camera's are {poses.width} x {poses.height}: cameras.txt is not this video's camera")
    views = [View(g, d, poses.intrinsics, p) for g, d, p in zip(gray, depth, all_pose)]
    n = len(poses.pose)
    echoes = Echoes(np.arange(n, n + int(ok.sum())), frames[ok], FS, np.asarray(emitted, float))
    return Scan(views, mesh, echoes), ok


def _answers(clf, frames, emitted, images=None) -> list[dict]:
    preds = clf.predict_batch(frames, FS, images, emitted) if len(frames) else []
    return [{"model": p.model, "open": p.is_open, "material": "-" if p.is_open else p.material,
             "depth_m": round(float(p.depth_m), 4), "p_open": round(p.probabilities["open"], 4),
             "p_mirror": round(p.probabilities["mirror"], 4), "confidence": round(p.confidence, 4),
             "flags": " ".join(p.flags)} for p in preds]


def run(out, video=None, audio=None, images=None, poses=None, mesh=None, image_fps: float | None = None,
        labels: str = "echocnn", emitter_distance_m: float | None = None, classifier=None,
        progress: bool = False) -> dict:
    """``vrecho capture``: a phone's capture in, EchoCNN's answers (and a repaired scan) out.

    The pulses of the recording (a video's sound, or ``audio``) are found and cut into frames,
    and EchoCNN answers each, the probe known (EchoCNN-E). Written to ``out``: ``frames.csv``
    (one row per frame: its time in the recording, the answers and their probabilities),
    ``capture.png`` (the recording, the pulses found and the answers) and ``images.npz`` (the
    picture at each frame's time, from the video or the numbered pictures in ``images``).

    With ``poses`` (COLMAP's text model of the pictures, numbered at ``image_fps``) and the
    user's ``mesh`` (.ply or .obj, in the poses' world; a y-up world is turned z up, and the
    meshes written are in that z-up world): each frame takes the pose of its
    pulse, the frames that face a hole of the mesh are asked again with the camera's crop
    around it (EchoCNN-EV, PROTOCOL.md's 64 x 25), and the reconstruction's repair runs on
    the mesh (``labels`` as :func:`vrecho.reconstruct.reconstruct`): ``initial.ply``,
    ``repaired.ply``, ``report.json``, ``before_after.png`` and ``scan/`` (which ``vrecho
    export`` turns into USD). ``emitter_distance_m``: from the loudspeaker to the microphone
    (default PROTOCOL.md's 7 cm; a second phone held elsewhere, measured), which places each
    frame's start, the emission, before the direct sound's arrival. Returns ``{"rows": [...],
    "result": Reconstruction or None}``.
    """
    import csv

    from .classifier import load_classifier
    from .colmap import image_times
    from .io import ensure_writable_dir, read_mesh
    from .reconstruct import LABELS, facing, reconstruct, write
    from .render import crop_view
    from .signals import probe

    if (video is None) == (audio is None):
        raise VrechoError("capture: give a video, or --audio with a sound file (not both)")
    if images is not None and video is not None:
        raise VrechoError("capture: --images goes with --audio (a video's pictures are its own)")
    if (poses is None) != (mesh is None):
        raise VrechoError("capture: --poses and --mesh go together (COLMAP's poses of the pictures, and the mesh)")
    if (poses is not None or images is not None) and image_fps is None:
        raise VrechoError("capture: --poses and --images need --image-fps, the rate the pictures were extracted at")
    if poses is not None and video is None and images is None:
        raise VrechoError("capture: --poses needs the pictures: a video, or --audio with --images")
    if labels not in LABELS[:2]:
        raise VrechoError(f"labels: expected one of {LABELS[:2]}, got {labels!r}")
    if emitter_distance_m is not None and not 0 <= emitter_distance_m <= 3:
        raise VrechoError(f"emitter-distance: expected 0 to 3 m from the loudspeaker to the microphone, "
                          f"got {emitter_distance_m}")
    if audio is not None:
        x, fs = read_audio(audio)
        video_start = 0.0
    else:
        x, fs, vtimes = read_video(video)
        video_start = float(vtimes[0]) if len(vtimes) else 0.0
    posed = None
    if poses is not None:
        posed = read_poses(poses, image_fps, x.size / fs, video_start)
        user_mesh = read_mesh(mesh).transform(posed.to_z_up)
    files = _image_files(Path(images), None if posed is None else posed.names) if images is not None else None
    out = ensure_writable_dir(out)
    onsets = find_onsets(x, fs)
    frames = cut_frames(x, onsets, mic_offset_m=emitter_distance_m)
    if not len(frames):
        raise VrechoError("capture: no pulse has a whole second of recording after it")
    times = onsets.seconds[:len(frames)]
    width = VIEW_WIDTH if posed is not None else None
    if video is not None:
        shots = video_images(video, np.r_[times, posed.time_s if posed is not None else []], width)
        frame_pictures, pictures = shots[:len(times)], shots[len(times):]
    elif files is not None:
        file_times = posed.time_s if posed is not None else image_times([f.name for f in files], image_fps)
        pictures = _load_pictures(files, width)
        frame_pictures = pictures[np.argmin(np.abs(times[:, None] - file_times[None]), axis=1)]
    else:
        pictures = frame_pictures = None
    clf = load_classifier() if classifier is None else classifier
    emitted = probe(FS)
    rows = [{"frame": k, "time_s": round(float(t), 6)} | a
            for k, (t, a) in enumerate(zip(times, _answers(clf, frames, emitted)))]
    result = None
    if posed is not None:
        scan, ok = posed_scan(user_mesh, posed, pictures, frames, times, frame_pictures, emitted)
        result = reconstruct(scan, None, labels, progress=progress, classifier=clf)
        if result.holes and not any(d.frames for d in result.decisions):  # only pulses' views have echoes
            raise VrechoError(f"capture: the mesh has {len(result.holes)} hole(s) and no pulse was played facing one "
                              "(within 25 degrees of its normal, 0.25 to 3.5 m away); film each glass, mirror or "
                              "opening from in front while the pulses play")
        views, first = scan.views, len(posed.pose)
        frame_of = dict(zip(range(first, len(views)), np.flatnonzero(ok)))
        for k, v in zip(np.flatnonzero(ok), views[first:]):
            rows[k].update(x_m=round(float(v.pose[0, 3]), 4), y_m=round(float(v.pose[1, 3]), 4),
                           z_m=round(float(v.pose[2, 3]), 4))
        for h, hole in enumerate(result.holes):  # frames facing a hole: asked again with the crop around it
            for i in facing(views, hole):
                if i in frame_of and "hole" not in rows[frame_of[i]]:
                    crop, inside = crop_view(views[i], hole.corners())
                    a = _answers(clf, frames[frame_of[i]][None], emitted, crop[None] if inside >= 0.98 else None)[0]
                    rows[frame_of[i]].update(a, hole=h)
        write(result, out, save_scan=True)
    fields = ["frame", "time_s", "x_m", "y_m", "z_m", "hole", "model", "open", "material", "depth_m", "p_open",
              "p_mirror", "confidence", "flags"]
    with open(out / "frames.csv", "w", newline="") as f:
        w = csv.DictWriter(f, fields if posed is not None else [c for c in fields if c not in ("x_m", "y_m", "z_m", "hole")],
                           restval="")
        w.writeheader()
        w.writerows(rows)
    if frame_pictures is not None:
        np.savez_compressed(out / "images.npz", time_s=times, gray=frame_pictures)
    _figure(x, fs, onsets, rows, out / "capture.png", None if result is None else result.decisions)
    return {"rows": rows, "result": result}


def _figure(x, fs, onsets: Onsets, rows: list[dict], path, decisions=None) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    t = np.arange(len(x)) / fs
    fig, (a, b) = plt.subplots(2, 1, figsize=(13, 5), sharex=True)
    step = max(len(x) // 200_000, 1)
    a.plot(t[::step], x[::step], lw=0.4, color="0.3")
    for s in onsets.seconds:
        a.axvline(s, color="tab:green", lw=0.8)
    for m in onsets.missing / fs:
        a.axvline(m, color="tab:red", lw=1.2, ls="--")
    a.set_ylabel("recording")
    a.set_title(f"{len(onsets.samples)} pulses found (green), {len(onsets.missing)} missing (red); "
                f"period {onsets.period_s:.5f} s")
    times = np.array([r["time_s"] for r in rows])
    p_closed = np.array([1 - r["p_open"] for r in rows])
    b.plot(times, [r["depth_m"] / 3 for r in rows], color="tab:gray", lw=0.8, label="depth / 3 m")
    if decisions is None:
        b.scatter(times, p_closed, c=["tab:orange" if r["open"] else "tab:blue" for r in rows], s=14,
                  label="p(closed): blue closed, orange open")
    else:  # a posed capture: the frames coloured by the hole they face, and what the hole was judged
        hole = np.array([r.get("hole", -1) if r.get("hole", "") != "" else -1 for r in rows])
        b.scatter(times[hole < 0], p_closed[hole < 0], color="0.7", s=10, label="p(closed), facing no hole")
        for h in sorted(set(hole[hole >= 0])):
            d = decisions[h]
            b.scatter(times[hole == h], p_closed[hole == h], color=plt.cm.tab10(h % 10), s=16,
                      label=f"hole {h}: {d.state}{' ' + d.material if d.material else ''} (p {d.p_closed:.2f})")
    b.set_ylim(-0.05, 1.05)
    b.set_xlabel("time (s)")
    b.set_ylabel("EchoCNN")
    b.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=7, frameon=False)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def simulate_capture(scene, folder, n_pulses: int = 20, fps: float = 4.0, camera=None, seed: int = 0,
                     audio_codec: str = "flac", snr_db: float = 30.0, video: tuple[int, int, float] | None = None,
                     progress: bool = False) -> dict:
    """A phone capture of a scene as a user brings it to ``vrecho capture``, made by the simulator:
    the device walks the scene's path (:func:`~vrecho.scene.walkthrough_path` if it has none)
    for ``n_pulses`` seconds playing the pulse train; ``capture.mkv`` (H.264 pictures at ``fps``
    and the microphone's sound; ``audio_codec`` "flac", or "aac" in ``capture.mp4``), the
    pictures' poses as COLMAP's text model in ``poses/`` (numbered from 1 at ``fps``, as ffmpeg
    extracts them), and the depth camera's scan fused into ``mesh.ply``. Each pulse is heard
    through the room's response where the device is when it plays. ``video`` (width, height,
    rate): the video as a phone writes it instead, each rendered picture scaled up and shown
    until the next, with a little sensor noise. Returns the paths, and the true onsets (s) and
    device poses of the pulses."""
    import dataclasses

    import open3d as o3d
    from tqdm import tqdm

    from . import colmap
    from .acoustics import device_impulse_response
    from .io import ensure_writable_dir
    from .reconstruct import device_pose, fuse
    from .render import Camera, View, World, camera_pose, render_view
    from .scene import walkthrough_path

    camera = Camera() if camera is None else camera
    if scene.camera_path is None:
        scene = dataclasses.replace(scene, camera_path=walkthrough_path(scene))
    folder = ensure_writable_dir(folder)
    rng = np.random.default_rng(seed)
    lead_s = 0.3
    walk = lambda t: np.clip((np.asarray(t, float) - lead_s) / max(n_pulses - 1, 1), 0, 1)  # noqa: E731 (pulse k at k/(n-1))
    pulse_t = lead_s + np.arange(n_pulses) * PERIOD_S
    pos, fwd = scene.camera_path.at(walk(pulse_t))
    poses = [camera_pose(p, f) for p, f in zip(pos, fwd)]
    irs = np.stack([device_impulse_response(scene, device_pose(View(None, None, None, q)))[0]
                    for q in tqdm(poses, desc="simulate pulses", unit="pulse", disable=not progress)])
    x, onsets = simulate_recording(irs, n_pulses, rng, snr_db=snr_db, lead_s=lead_s)
    x = 0.5 * x / np.abs(x).max()
    duration = len(x) / FS
    pic_t = np.arange(int(duration * fps)) / fps
    pos, fwd = scene.camera_path.at(walk(pic_t))
    world = World(scene)
    views = [render_view(world, camera_pose(p, f), camera)
             for p, f in tqdm(list(zip(pos, fwd)), desc="render pictures", unit="picture", disable=not progress)]
    path = folder / ("capture.mkv" if audio_codec == "flac" else "capture.mp4")
    gray = [np.round(255 * v.gray).astype(np.uint8) for v in views]
    if video is None:
        write_video(path, np.stack(gray), fps, x, FS, audio_codec)
    else:
        from PIL import Image

        width, height, rate = video
        big = [np.asarray(Image.fromarray(g).resize((width, height), Image.BILINEAR), np.int16) for g in gray]

        def frames():
            for i in range(int(duration * rate)):
                noise = rng.integers(-2, 3, (height, width), dtype=np.int16)
                yield np.clip(big[min(int(i / rate * fps), len(big) - 1)] + noise, 0, 255).astype(np.uint8)

        write_video(path, tqdm(frames(), total=int(duration * rate), desc="encode video", unit="frame",
                               disable=not progress), rate, x, FS, audio_codec)
    names = [f"{k + 1:06d}.png" for k in range(len(views))]
    colmap.write_model(folder / "poses", colmap.pinhole(camera.intrinsics, camera.width, camera.height), names,
                       np.stack([v.pose for v in views]))
    o3d.io.write_triangle_mesh(str(folder / "mesh.ply"), fuse(views, progress=progress))
    return {"video": path, "poses": folder / "poses", "mesh": folder / "mesh.ply", "fps": fps,
            "onsets_s": onsets / FS, "pulse_poses": np.stack(poses)}
