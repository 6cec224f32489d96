"""What the headset call says after each block: :class:`Alert`."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Alert:
    """What the monitor says after a block.

    Parameters
    ----------
    level : str
        "clear", "caution" or "stop".
    distance_m : float or None
        The distance in metres of the surface the alert rests on (of those in the wearer's way,
        the gravest, then the soonest to contact; None if none), as the pulse emitted at
        ``pulse_time_s`` measured it. The level reckons with the wearer's walk since: the
        pulse may have left as soon as it was written, a round trip before its echo came back.
    surface : str or None
        "wall", "glass", "mirror" (what the camera made of the surface,
        :meth:`BoundaryMonitor.see`), "closed" (not yet seen), "opening" or None (see the
        module's notes).
    confidence : float
        In [0, 1].
    closing_speed_mps : float or None
        That surface's closing speed in m/s (positive: nearing).
    time_to_contact_s : float or None
        That surface's time to contact in seconds, from now (None when it closes at 5 cm/s or
        less).
    flags : tuple of str
        What was wrong with the input so far in this block ("nan", "dropout", "clipped"), and
        the monitor's state: "unlocked" (its own direct sound not found yet, or lost after the
        round trip changed: no alarm then), "no_direct_sound" (unlocked for over a second: the
        loudspeaker muted, the microphone off?), "no_echo" (no surface heard: no echo
        confirmed over several pulses, stray peaks aside).
    pulse_time_s : float or None
        When (seconds, on the stream's clock, from the first sample) the pulse that measured
        ``distance_m`` was written to the loudspeaker.
    latency_s : float or None
        The round trip the monitor is locked on, loudspeaker write to microphone read, in
        seconds (None while unlocked).
    """

    level: str = "clear"
    distance_m: float | None = None
    surface: str | None = None
    confidence: float = 0.0
    closing_speed_mps: float | None = None
    time_to_contact_s: float | None = None
    flags: tuple[str, ...] = ()
    pulse_time_s: float | None = None
    latency_s: float | None = None
