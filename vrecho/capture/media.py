"""A capture's media: a video's sound and pictures decoded with PyAV (FFmpeg's libraries), sound
files, folders of pictures, and videos written (for simulated captures).
"""

from __future__ import annotations

import itertools
from fractions import Fraction
from pathlib import Path

import numpy as np
import soundfile as sf
from PIL import Image

from ..errors import VrechoError
from ..signals import CLIP_LEVEL


def read_video(path) -> tuple[np.ndarray, int, np.ndarray]:
    """A video's sound and the times of its pictures, decoded with PyAV (FFmpeg's libraries).

    Only the sound is decoded; the pictures' times come from their packets.

    Parameters
    ----------
    path : str or pathlib.Path
        The video (MP4, MOV, MKV, ...).

    Returns
    -------
    audio : numpy.ndarray [shape=(n,)], float32
        The first audio stream mixed to mono, at its own rate (integer samples scaled to
        [-1, 1]).
    fs : int
        Its sample rate in Hz.
    times : numpy.ndarray [shape=(F,)], float
        Each video frame's presentation time in seconds from the audio's start, sorted.

    Raises
    ------
    VrechoError
        One error for a file that is not a video, a codec FFmpeg cannot decode, a video without
        sound (no audio track, or one holding no samples), a sound with samples not finite, or a
        file whose sound or pictures decode for less than its header's length, by more than
        0.5 s and 2 % (and two pictures' interval): truncated or damaged.
    """
    import av  # FFmpeg's libraries: only when a video is read or written

    path = str(path)
    try:
        with av.open(path, metadata_errors="replace") as container:  # tags need not be UTF-8
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
            fs = int(astream.rate or 0)
            declared = container.duration / av.time_base if container.duration else None
    except av.FFmpegError as e:
        raise VrechoError(f"{path}: cannot decode it ({e}); expected a video FFmpeg reads (MP4/MOV/MKV with "
                          "H.264/HEVC and AAC/PCM/FLAC sound)") from None
    if not chunks or fs <= 0:
        raise VrechoError(f"{path}: the audio track holds no samples")
    audio = np.concatenate(chunks)
    # A truncated or damaged file decodes in part, without an error from FFmpeg: measured against
    # the length its header says, a part short by over 0.5 s and 2 % (and two pictures) is refused.
    times = sorted(times)
    gap = float(np.median(np.diff(times))) if len(times) > 1 else 0.0
    spans = {"sound": (audio.size / fs, 0.0), "pictures": (times[-1] - times[0] if times else None, 2 * gap)}
    for what, (span, slack) in spans.items():
        if declared and span is not None and span < declared - 0.5 - 0.02 * declared - slack:
            raise VrechoError(f"{path}: its {what}: {span:.1f} s decoded of the {declared:.1f} s its header says; "
                              "the file is truncated or damaged (expected the whole video)")
    if not np.all(np.isfinite(audio)):
        raise VrechoError(f"{path}: its sound holds samples that are not finite numbers")
    return audio, fs, np.array(times) - (a0 or 0.0)


def video_images(path, times_s, *, width: int | None = None) -> np.ndarray:
    """Grayscale pictures of a video at the given times, decoded in one pass (FFmpeg's threads).

    At each time, the picture shown then: the last one that started (the first picture before
    it, the last picture after the end).

    Parameters
    ----------
    path : str or pathlib.Path
        The video.
    times_s : numpy.ndarray [shape=(K,)], float
        The times in seconds from the sound's start, in any order.
    width : int, optional
        Width in pixels to scale the pictures to (aspect kept); their own size by default.

    Returns
    -------
    numpy.ndarray [shape=(K, H, W)], uint8
        One picture per time, in the order of ``times_s``.

    Raises
    ------
    VrechoError
        For a file FFmpeg cannot decode, one without pictures, or one none of whose pictures
        decodes.
    """
    import av  # FFmpeg's libraries: only when a video is read or written

    times_s = np.asarray(times_s, float)
    try:
        return _pictures(av.open(str(path), metadata_errors="replace"), times_s, width)
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
    if last is None and k < len(order):
        raise VrechoError(f"{container.name}: none of its pictures decodes; the file is truncated or damaged")
    for j in order[k:]:
        out[j] = last.to_ndarray(format="gray", **size)
    return np.stack(out)


def write_video(path, gray: np.ndarray, fps: float, audio: np.ndarray, fs: int, *, audio_codec: str = "flac",
                audio_bit_rate: int = 256_000) -> None:
    """Mux grayscale pictures and a mono sound into a video file with PyAV (H.264; the sound as
    ``audio_codec``: "flac" in MKV is lossless, "aac" in MP4 is what phones write, at
    ``audio_bit_rate``). For simulated captures, tests and benchmarks.

    Parameters
    ----------
    path : str or pathlib.Path
        The file to write; its suffix picks the container (.mkv, .mp4).
    gray : numpy.ndarray [shape=(K, H, W)], uint8
        The pictures: an array, or any iterable of (H, W) pictures.
    fps : float
        Pictures per second.
    audio : numpy.ndarray [shape=(n,)], float
        The sound, in [-1, 1] (clipped to it).
    fs : int
        Its sample rate in Hz.
    audio_codec : str
        FFmpeg's encoder for the sound (default "flac", stored as 16-bit).
    audio_bit_rate : int
        Bit rate of a lossy sound codec, in bits per second (default 256000; not used for
        "flac").
    """
    import av  # FFmpeg's libraries: only when a video is read or written

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


def read_audio(path) -> tuple[np.ndarray, int]:
    """A sound file (WAV, FLAC, ...) mixed to mono, float32, and its rate.

    Parameters
    ----------
    path : str or pathlib.Path
        The sound file.

    Returns
    -------
    audio : numpy.ndarray [shape=(n,)], float32
        The channels averaged; where any channel reaches full scale (clipped), the mix is at
        full scale too, with that channel's sign, so that the clipping test
        (:func:`~vrecho.signals.clipped`) sees a clipped channel in the mix.
    fs : int
        Its sample rate in Hz.

    Raises
    ------
    VrechoError
        For a file libsndfile cannot read as sound, or one with no samples or samples not
        finite.
    """
    try:
        x, fs = sf.read(str(path), dtype="float32", always_2d=True)
    except (sf.LibsndfileError, RuntimeError) as e:
        raise VrechoError(f"{path}: cannot read it as sound ({e}); expected WAV or FLAC") from None
    if not x.size or not np.all(np.isfinite(x)):
        raise VrechoError(f"{path}: {'holds no samples' if not x.size else 'holds samples that are not finite numbers'}")
    mono = x.mean(axis=1)
    if x.shape[1] > 1:
        mag = np.abs(x)
        rail = max(float(mag.max()), 1.0)
        row, col = np.nonzero(mag >= CLIP_LEVEL * rail)
        mono[row] = np.sign(x[row, col]) * rail
    return mono, int(fs)


def image_files(folder: Path, names: list[str] | None) -> list[Path]:
    """The picture files of a capture.

    Parameters
    ----------
    folder : pathlib.Path
        The folder of pictures.
    names : list of str or None
        The file names to take (COLMAP's ``images.txt`` names); None for every .png, .jpg and
        .jpeg file in the folder, sorted by name.

    Returns
    -------
    list of pathlib.Path
        The files, in the order of ``names`` (or sorted).

    Raises
    ------
    VrechoError
        When ``folder`` is not a folder, holds no pictures, or lacks one of ``names``.
    """
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


def _open_picture(f: Path) -> Image.Image:
    """A picture file opened (its header read), or one error naming it."""
    try:
        return Image.open(f)
    except (OSError, ValueError, Image.DecompressionBombError) as e:
        raise VrechoError(f"images: {f}: cannot read it as a picture ({e}); expected PNG or JPEG") from None


def check_pictures(files: list[Path]) -> tuple[int, int]:
    """The common size of picture files, from their headers (fast: nothing decoded).

    Parameters
    ----------
    files : list of pathlib.Path
        The pictures (:func:`image_files`).

    Returns
    -------
    width, height : int
        Their size in pixels.

    Raises
    ------
    VrechoError
        Naming the file, for one that is not a picture PIL reads (or is over its 179-million-
        pixel guard), one of another size than the first, or pictures more than 10 times as wide
        as high (or the reverse).
    """
    sizes = []
    for f in files:
        with _open_picture(f) as im:
            sizes.append(im.size)
        if sizes[-1] != sizes[0]:
            raise VrechoError(f"images: {f} is {sizes[-1][0]} x {sizes[-1][1]} pixels, {files[0].name} "
                              f"{sizes[0][0]} x {sizes[0][1]}; expected the pictures of one video")
    w, h = sizes[0]
    if not w / 10 <= h <= 10 * w:
        raise VrechoError(f"images: the pictures are {w} x {h} pixels; expected a video's (at most 10 times as high as "
                          "wide, and 10 times as wide as high)")
    return w, h


def load_pictures(files: list[Path], width: int | None) -> np.ndarray:
    """Picture files read as grayscale.

    Parameters
    ----------
    files : list of pathlib.Path
        The pictures, all of one size.
    width : int or None
        Width in pixels to scale them to (bilinearly, aspect kept); None for their own size.

    Returns
    -------
    numpy.ndarray [shape=(K, H, W)], uint8
        One picture per file, in order.

    Raises
    ------
    VrechoError
        Naming the file, for one that does not decode (truncated or damaged) or is not of the
        first one's size (:func:`check_pictures` checks the headers beforehand).
    """
    out = []
    for f in files:
        with _open_picture(f) as im:
            try:
                im = im.convert("L")
            except (OSError, ValueError, Image.DecompressionBombError) as e:
                raise VrechoError(f"images: {f}: cannot decode it ({e}); the file is truncated or damaged") from None
        if width is not None:
            im = im.resize((width, max(1, int(round(im.height * width / im.width)))), Image.BILINEAR)
        out.append(np.asarray(im, np.uint8))
        if out[-1].shape != out[0].shape:
            raise VrechoError(f"images: {f} is not of {files[0].name}'s size; expected the pictures of one video")
    return np.stack(out)
