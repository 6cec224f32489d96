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
3. **The train.** Chained from the strongest candidate outward, one period at a time, the period
   re-estimated from the onsets so far (drift): the candidate within ``tolerance_s`` of where the
   next pulse is due is taken; where none is, the pulse is missing (and the next is looked for
   one more period on). A stronger echo is not taken for the direct sound: the onset is the
   highest lag within a quarter millisecond of the first, within 20 ms before the peak, whose
   envelope reaches half of it.
4. **Sub-sample time.** A parabola through the envelope's three samples at the peak.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .errors import VrechoError
from .signals import FS, PERIOD_S, parabolic_peaks


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
    spec = fft.rfft(x, n) * np.conj(fft.rfft(s, n))
    analytic = np.zeros(n, complex)  # one inverse FFT gives the correlation and its Hilbert pair
    analytic[:spec.size] = spec
    analytic[1:(n + 1) // 2] *= 2.0
    return np.abs(fft.ifft(analytic))[:x.size - s.size + 1] / np.linalg.norm(s)


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
    # Chain the train from the strongest pulse, both ways, one period at a time.
    tol = tolerance_s * fs
    start = int(peaks[np.argmax(env[peaks])])
    onsets, missing = {0: start}, []
    for direction in (1, -1):
        k, last, gap = 0, start, 1
        while True:
            known = sorted(onsets.items())
            p = period if len(known) < 2 else (known[-1][1] - known[0][1]) / (known[-1][0] - known[0][0])
            due = last + direction * gap * p
            if not 0 <= due < env.size:
                break
            near = peaks[np.abs(peaks - due) <= tol * gap]
            if len(near):
                k += direction * gap
                last = int(near[np.argmax(env[near])])
                onsets[k] = last
                gap = 1
            else:
                missing.append(due)
                gap += 1
                if gap > 4:  # four missing in a row: resume from the nearest candidate beyond
                    ahead = peaks[(peaks - last) * direction > (gap - 0.5) * p]
                    if not len(ahead):
                        break
                    nxt = int(ahead[0] if direction > 0 else ahead[-1])
                    k += direction * int(round(abs(nxt - last) / p))
                    last, gap = nxt, 1
                    onsets[k] = last
    if len(onsets) < 2:
        raise VrechoError(f"audio: no pulse train found: pulses do not recur every {period_s:g} s "
                          f"(within {tolerance_s * 1000:.0f} ms)")
    ks = np.array(sorted(onsets))
    idx = np.array([onsets[k] for k in ks])
    # The direct sound is the first strong arrival: an echo may outdo it by a little.
    lead, lobe = int(0.02 * fs), max(int(0.00025 * fs), 3)  # a quarter millisecond: past the main lobe, before any echo
    for j, i in enumerate(idx):
        w = env[max(i - lead, 0):i + 1]
        first = max(i - lead, 0) + int(np.flatnonzero(w >= 0.5 * env[i])[0])
        idx[j] = first + int(np.argmax(env[first:first + lobe]))  # that arrival's own peak
    samples = parabolic_peaks(env, idx)
    period_fit = float(np.polyfit(ks, samples, 1)[0]) / fs
    # Only gaps the found pulses straddle are missing pulses (not the recording's ends).
    missing = np.array(sorted(m for m in missing if samples[0] < m < samples[-1]))
    return Onsets(samples, 20 * np.log10(env[idx] / floor), missing, period_fit, fs)


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
                for frame in packet.decode():
                    if packet.stream.type == "audio":
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
                    elif frame.time is not None:
                        times.append(float(frame.time))
            fs = int(astream.rate)
    except av.FFmpegError as e:
        raise VrechoError(f"{path}: cannot decode it ({e}); expected a video FFmpeg reads (MP4/MOV/MKV with "
                          "H.264/HEVC and AAC/PCM/FLAC sound)") from None
    if not chunks:
        raise VrechoError(f"{path}: the audio track holds no samples")
    return np.concatenate(chunks), fs, np.array(sorted(times)) - (a0 or 0.0)


def video_images(path, times_s) -> np.ndarray:
    """Grayscale pictures (K, H, W) uint8 of a video at the given times (the frame shown then:
    the last one that started), decoded in one pass."""
    import av

    times_s = np.asarray(times_s, float)
    out = [None] * len(times_s)
    order = np.argsort(times_s)
    k, last, t0 = 0, None, None
    with av.open(str(path)) as container:
        a = container.streams.audio
        for frame in container.decode(video=0):
            if t0 is None:
                t0 = float(a[0].start_time * a[0].time_base) if a and a[0].start_time is not None else 0.0
            t = float(frame.time) - t0
            while k < len(order) and times_s[order[k]] < t:
                out[order[k]] = (last if last is not None else frame).to_ndarray(format="gray")
                k += 1
            if k == len(order):
                break
            last = frame  # converted only if a time falls in it
    for j in order[k:]:
        out[j] = last.to_ndarray(format="gray")
    return np.stack(out)


def write_video(path, gray: np.ndarray, fps: float, audio: np.ndarray, fs: int, audio_codec: str = "flac",
                audio_bit_rate: int = 256_000) -> None:
    """Mux grayscale pictures (K, H, W) uint8 at ``fps`` and a mono sound (float in [-1, 1]) into
    a video file with PyAV (H.264; the sound as ``audio_codec``: "flac" in MKV is lossless,
    "aac" in MP4 is what phones write, at ``audio_bit_rate``). For simulated captures and tests."""
    import av
    from fractions import Fraction

    gray = np.asarray(gray, np.uint8)
    with av.open(str(path), "w") as container:
        v = container.add_stream("libx264", rate=Fraction(fps).limit_denominator(1000))
        v.width, v.height, v.pix_fmt = gray.shape[2], gray.shape[1], "yuv420p"
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
        for i, g in enumerate(gray):
            frame = av.VideoFrame.from_ndarray(np.repeat(g[..., None], 3, axis=2), format="rgb24")
            frame.pts = i
            for packet in v.encode(frame):
                container.mux(packet)
        for packet in v.encode(None):
            container.mux(packet)


def simulate_recording(ir: np.ndarray, n_pulses: int, rng: np.random.Generator, fs: int = FS, emitted=None,
                       snr_db: float = 30.0, drift: float = 0.0, clip: float | None = None,
                       dropped: tuple[int, ...] = (), lead_s: float = 0.3) -> tuple[np.ndarray, np.ndarray]:
    """A recording of the pulse train as a phone makes it, with the truth: the microphone's
    signal (float32) and where each pulse's direct sound begins (fractional samples; NaN for a
    dropped pulse).

    ``ir``: the room's impulse response from the loudspeaker to the microphone (sample 0: the
    emission; :func:`~vrecho.acoustics.device_impulse_response`), whose first arrival is the
    direct sound; pulses every ``PERIOD_S * (1 + drift)`` s from ``lead_s`` plus a random
    fraction of a sample (the two clocks are not aligned), pulses in ``dropped`` not played;
    pink noise ``snr_db`` below the direct sound, clipped at ``clip`` times the direct sound's
    peak (if given).
    """
    from .acoustics import _microphone
    from .signals import probe

    s = probe(fs) if emitted is None else np.asarray(emitted, dtype=np.float64)
    ir = np.asarray(ir, dtype=np.float64)
    period = PERIOD_S * (1 + drift) * fs
    n = int(lead_s * fs + (n_pulses + 0.5) * period) + ir.size
    starts = lead_s * fs + rng.uniform(0, 1) + np.arange(n_pulses) * period
    emission = np.zeros(n)
    m = 1 << int(np.ceil(np.log2(s.size + 64)))
    spectrum = np.fft.rfft(s, m)
    freqs = np.fft.rfftfreq(m)
    for k, t in enumerate(starts):
        if k in dropped:
            continue
        i = int(np.floor(t))
        pulse = np.fft.irfft(spectrum * np.exp(-2j * np.pi * freqs * (t - i)), m)  # a fractional delay
        emission[i:i + m] += pulse[:n - i]
    x = np.fft.irfft(np.fft.rfft(emission, 2 * n) * np.fft.rfft(ir, 2 * n), 2 * n)[:n]
    direct = int(np.argmax(np.abs(ir) > 0.5 * np.abs(ir).max()))  # the first strong arrival
    offset = float(parabolic_peaks(np.abs(ir), np.array([direct]))[0])  # its sub-sample time
    amp = float(np.abs(ir).max())
    x = _microphone(x, s, amp, rng, snr_db, 80.0, 0.0).astype(np.float64)
    if clip is not None:
        rail = clip * amp * np.abs(s).max()
        x = np.clip(x, -rail, rail)
    truth = starts + offset
    truth[list(dropped)] = np.nan
    return x.astype(np.float32), truth


def run(out, video=None, audio=None, classifier=None) -> list[dict]:
    """``vrecho capture``: find the pulses of a capture (a video, or a sound file), cut its frames,
    ask EchoCNN about each (the probe known: EchoCNN-E), and write ``frames.csv`` (one row per
    frame: its time in the recording, the answers and their probabilities), ``images.npz`` (the
    video's picture at each frame's time) and ``capture.png`` (the recording with the pulses
    found and the answers). Returns the rows."""
    import csv

    import soundfile as sf

    from .classifier import load_classifier
    from .io import ensure_writable_dir
    from .signals import probe

    if (video is None) == (audio is None):
        raise VrechoError("capture: give a video, or --audio with a sound file (not both)")
    if audio is not None:
        try:
            x, fs = sf.read(str(audio), dtype="float32", always_2d=True)
        except (sf.LibsndfileError, RuntimeError) as e:
            raise VrechoError(f"{audio}: cannot read it as sound ({e}); expected WAV or FLAC") from None
        x = x.mean(axis=1)
    else:
        x, fs, _ = read_video(video)
    out = ensure_writable_dir(out)
    onsets = find_onsets(x, fs)
    frames = cut_frames(x, onsets)
    if not len(frames):
        raise VrechoError("capture: no pulse has a whole second of recording after it")
    clf = load_classifier() if classifier is None else classifier
    preds = clf.predict_batch(frames, FS, None, probe(FS))
    times = onsets.seconds[:len(frames)]
    rows = [{"frame": k, "time_s": round(float(t), 6), "open": p.is_open, "material": "-" if p.is_open else p.material,
             "depth_m": round(float(p.depth_m), 4), "p_open": round(p.probabilities["open"], 4),
             "p_mirror": round(p.probabilities["mirror"], 4), "confidence": round(p.confidence, 4),
             "flags": " ".join(p.flags)} for k, (t, p) in enumerate(zip(times, preds))]
    with open(out / "frames.csv", "w", newline="") as f:
        w = csv.DictWriter(f, list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    if video is not None:
        np.savez_compressed(out / "images.npz", time_s=times, gray=video_images(video, times))
    _figure(x, fs, onsets, rows, out / "capture.png")
    return rows


def _figure(x, fs, onsets: Onsets, rows: list[dict], path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    t = np.arange(len(x)) / fs
    fig, (a, b) = plt.subplots(2, 1, figsize=(11, 5), sharex=True)
    step = max(len(x) // 200_000, 1)
    a.plot(t[::step], x[::step], lw=0.4, color="0.3")
    for s in onsets.seconds:
        a.axvline(s, color="tab:green", lw=0.8)
    for m in onsets.missing / fs:
        a.axvline(m, color="tab:red", lw=1.2, ls="--")
    a.set_ylabel("recording")
    a.set_title(f"{len(onsets.samples)} pulses found (green), {len(onsets.missing)} missing (red); "
                f"period {onsets.period_s:.5f} s")
    times = [r["time_s"] for r in rows]
    b.scatter(times, [1 - r["p_open"] for r in rows], c=["tab:blue" if not r["open"] else "tab:orange" for r in rows],
              s=14, label="p(closed)")
    b.plot(times, [r["depth_m"] / 3 for r in rows], color="tab:gray", lw=0.8, label="depth / 3 m")
    b.set_ylim(-0.05, 1.05)
    b.set_xlabel("time (s)")
    b.set_ylabel("EchoCNN")
    b.legend(loc="upper right", fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
