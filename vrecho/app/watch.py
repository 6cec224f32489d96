"""``vrecho watch``: the headset call live on this computer's sound card.

The loudspeaker plays :class:`~vrecho.headset.BoundaryMonitor`'s probe and the microphone is
read on the same full-duplex stream (sounddevice, PortAudio); each change of the alert's level
is printed with the distance and the surface, and the lock on the stream's round trip as it is
found, lost or moves. A laptop pointed at a glass door is a user: its loudspeaker and microphone
are some 10 to 30 cm apart (``--mic-offset``).
"""

from __future__ import annotations

import queue
import time

from ..errors import VrechoError
from ..headset import BoundaryMonitor

RATES = (44100, 48000)


def _sounddevice():
    """sounddevice, or one clear error where PortAudio is missing."""
    try:
        import sounddevice  # PortAudio's bindings (0.3 s): only the live command needs them
    except (ImportError, OSError) as e:
        raise VrechoError(f"watch: no audio library ({e}); install PortAudio (Debian: libportaudio2) and "
                          "the sounddevice package") from None
    return sounddevice


def list_devices() -> str:
    """The sound devices PortAudio sees, as sounddevice lists them.

    Returns
    -------
    str
        One line per device (``>`` the default input, ``<`` the default output), or one line
        saying that PortAudio sees none (no sound card, no audio server running).

    Raises
    ------
    VrechoError
        Where PortAudio is missing.
    """
    devices = _sounddevice().query_devices()
    return str(devices) if len(devices) else "no sound devices: PortAudio sees no sound card and no audio server"


def watch(*, device=None, samplerate: int = 48000, blocksize: int = 0, mic_offset_m: float = 0.07,
          seconds: float | None = None, seed: int | None = None, out=print) -> list:
    """``vrecho watch``: run the headset call on a sound card until interrupted (or ``seconds``).

    Parameters
    ----------
    device : int or str, optional
        The sound device (a number or a part of its name, as ``--list-devices`` shows them; the
        default device by default).
    samplerate : {44100, 48000}
        The stream's rate in Hz (default 48000).
    blocksize : int
        Frames per callback; 0 (the default) lets the audio system choose, block by block.
    mic_offset_m : float
        Loudspeaker to microphone in metres, as the maker gives it (default 0.07).
    seconds : float, optional
        Stop after this long (default: run until interrupted).
    seed : int, optional
        The probe's dither and codes (default: fresh, as every headset's should be).
    out : callable
        Where each line goes (default: print).

    Returns
    -------
    list of Alert
        Every change of level, in order.

    Raises
    ------
    VrechoError
        For a rate other than 44.1 or 48 kHz, a block size outside 0 to 4096, where there is no
        audio library, no such device, no device with an input and an output, or the stream
        cannot be opened.
    """
    if samplerate not in RATES:
        raise VrechoError(f"samplerate: expected 44100 or 48000 Hz, got {samplerate}")
    if not 0 <= blocksize <= 4096:
        raise VrechoError(f"blocksize: expected 0 (the audio system's choice) to 4096 frames, got {blocksize}")
    sd = _sounddevice()
    try:
        devices = sd.query_devices()
        inp = sd.query_devices(device, "input")
        outp = sd.query_devices(device, "output")
    except (ValueError, sd.PortAudioError) as e:
        found = len(devices) if "devices" in locals() else 0
        raise VrechoError(f"watch: no usable audio device ({e}; {found} device(s) found; --list-devices "
                          "lists them)") from None
    changes: queue.Queue = queue.Queue()
    monitor = BoundaryMonitor(samplerate, mic_offset_m=mic_offset_m, seed=seed, on_alert=changes.put)
    channels = (1, max(1, min(2, int(outp["max_output_channels"]))))
    try:
        stream = sd.Stream(device=device, samplerate=samplerate, blocksize=blocksize, channels=channels,
                           dtype="float32", callback=monitor.callback)
    except (ValueError, sd.PortAudioError) as e:
        raise VrechoError(f"watch: cannot open {inp['name']!r} for a full-duplex stream at {samplerate} Hz: {e}") from None
    heard = []
    latency = None
    out(f"listening on {inp['name']!r} at {samplerate} Hz (Ctrl-C stops); the loudspeaker ticks")
    with stream:
        started = time.monotonic()
        while seconds is None or time.monotonic() - started < seconds:
            try:
                alert = changes.get(timeout=0.1)
            except queue.Empty:
                alert = None
            now = monitor.alert
            if now.latency_s is not None and (latency is None or abs(now.latency_s - latency) > 0.0005):
                latency = now.latency_s
                out(f"round trip {latency * 1e3:.1f} ms (locked)")
            elif now.latency_s is None and latency is not None:
                latency = None
                out("round trip lost: searching (no alarm meanwhile)")
            if alert is None:
                continue
            heard.append(alert)
            if alert.level == "clear":
                out("clear")
            else:
                ttc = "" if alert.time_to_contact_s is None else f", contact in {alert.time_to_contact_s:.1f} s"
                out(f"{alert.level}: {alert.surface or 'surface'} at {alert.distance_m:.2f} m{ttc}")
        if "no_direct_sound" in monitor.alert.flags:
            out("the loudspeaker is not heard: is it muted, or the microphone off?")
    return heard
