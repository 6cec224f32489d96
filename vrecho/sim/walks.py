"""Simulated walks for the headset call: a wearer walks toward (or past) a surface while the
headset plays :class:`vrecho.headset.BoundaryMonitor`'s probe on the monitor's own schedule; what
its microphone hands back through an audio stream.

Two steps, so that one walk's room is simulated once and heard through many streams:

- :func:`walk_responses`: the room's impulse response from the headset's loudspeaker to its
  microphone at each pulse (pyroomacoustics' image sources up to second order: the specular
  echoes that ranging is about; glass, mirrors, openings and furniture as their own patches).
  The walk gets under way at 3 m/s^2, bobs the head (2 cm at 1.8 Hz) and sways it (3 degrees
  at 0.9 Hz). The headset
  (:class:`Headset`) places its microphone 1 to 15 cm from the loudspeaker in any direction and
  points its loudspeaker along any axis, omnidirectional to cardioid.
- :func:`record_walk`: those responses played through an audio stream (:class:`AudioLink`: a
  round trip from loudspeaker write to microphone read, steps of it by whole blocks as after an
  underrun, the two clocks drifting apart), with the pings of other headsets in the room
  (:func:`other_headsets`, each on its own dithered schedule), ambient sound (speech, music, TV,
  a fan) and pink noise below the direct sound the reference headset hears (a room is no
  louder to a microphone a centimetre from its loudspeaker: :attr:`WalkResponses.room_level`),
  and microphone self-noise. People walking past add their bodies' echoes to the responses
  (:mod:`vrecho.sim.people`).

:func:`simulate_walk` does both. Times: the monitor writes pulse ``k`` at sample ``e_k`` of the
stream (:class:`~vrecho.headset.ProbeSchedule`); the loudspeaker plays it ``output_share`` of the
round trip later; the walk is laid out so that pulse ``k`` leaves from the walk's position at
``e_k / fs`` (the walk starts that much later: the wearer's motion does not follow the stream).
"""

from __future__ import annotations

import zlib
from dataclasses import dataclass, field

import numpy as np

from ..camera import Camera, camera_pose
from ..device import MIC_ABOVE_EMITTER_M
from ..errors import VrechoError
from ..headset.ranging import ProbeSchedule
from ..scene import Scene
from ..signals import SPEED_OF_SOUND, colored_noise
from .acoustics import Simulation, build_room, direct_amplitude, emitter_directivity
from .render import render_view
from .sounds import ambient_sound

WALK_SIMULATION = Simulation(max_order=2, n_rays=0, length_s=0.06, air_absorption=True)

HEADSET_CAMERA = Camera(width=320, height=240, fov_deg=100.0)
"""The simulated headset's camera (benchmarks, tests): wide, as headsets' tracking cameras are."""

AMBIENT_KINDS = ("speech", "music", "tv", "fan")
"""Ambient sounds a walk may hear (:func:`record_walk`)."""

ACCELERATION_MPS2 = 3.0
"""How fast a walk gets under way (a brisk start: 2 m/s within two thirds of a second)."""


def _walked(t: float, speed: float) -> float:
    """Metres walked ``t`` seconds after setting off, speeding up at :data:`ACCELERATION_MPS2`."""
    ramp = speed / ACCELERATION_MPS2
    return 0.5 * ACCELERATION_MPS2 * t * t if t < ramp else speed * (t - 0.5 * ramp)


@dataclass(frozen=True)
class Headset:
    """A simulated headset's loudspeaker and microphone, in its own frame (forward, left, up).

    Parameters
    ----------
    mic_offset_m : tuple of (float, float, float)
        The microphone's place from the loudspeaker, metres (default 7 cm up: PROTOCOL.md's
        device).
    speaker_axis : tuple of (float, float, float)
        Where the loudspeaker points (default forward).
    speaker_p : float or None
        Its directivity, pyroomacoustics' cardioid family: gain p + (1 - p) cos(angle), 1
        omnidirectional, 0.5 a cardioid (default: the scene's ``emitter_p``).
    """

    mic_offset_m: tuple[float, float, float] = (0.0, 0.0, MIC_ABOVE_EMITTER_M)
    speaker_axis: tuple[float, float, float] = (1.0, 0.0, 0.0)
    speaker_p: float | None = None

    @property
    def spacing_m(self) -> float:
        """Loudspeaker to microphone, in metres."""
        return float(np.linalg.norm(self.mic_offset_m))

    def world(self, forward: np.ndarray) -> np.ndarray:
        """The headset's frame in the world for a horizontal ``forward``.

        Parameters
        ----------
        forward : numpy.ndarray [shape=(3,)]
            The wearer's facing, unit and horizontal.

        Returns
        -------
        numpy.ndarray [shape=(3, 3)]
            Columns forward, left, up.
        """
        up = np.array([0.0, 0.0, 1.0])
        return np.c_[forward, np.cross(up, forward), up]


@dataclass(frozen=True)
class AudioLink:
    """The audio stream between the monitor and the room.

    Parameters
    ----------
    latency_s : float
        The round trip from loudspeaker write to microphone read at the start, in seconds.
    output_share : float
        The part of it on the loudspeaker's side, 0 to 1 (default 0.5).
    steps : tuple of (float, int)
        (time in seconds, samples): from that time on the round trip is longer by that many
        samples (shorter if negative), as after an underrun (a whole block) or an overrun.
    drift_ppm : float
        How much faster the microphone's clock runs than the loudspeaker's, in parts per million.
    """

    latency_s: float = 0.0
    output_share: float = 0.5
    steps: tuple[tuple[float, int], ...] = ()
    drift_ppm: float = 0.0

    def arrival(self, written: np.ndarray, fs: int) -> np.ndarray:
        """Where a sample written at ``written`` comes back through a direct path of no length.

        Parameters
        ----------
        written : numpy.ndarray [shape=(K,)]
            Samples of the loudspeaker's stream.
        fs : int
            Sample rate in Hz.

        Returns
        -------
        numpy.ndarray [shape=(K,)], float
            Samples of the microphone's stream.
        """
        written = np.asarray(written, float)
        delay = np.full(written.shape, self.latency_s * fs)
        for t, samples in self.steps:
            delay += np.where(written >= t * fs, samples, 0)
        if len(delay) and delay.min() < 0:
            raise VrechoError(f"AudioLink: its steps take the round trip below zero ({delay.min() / fs * 1e3:.1f} ms): "
                              "a microphone cannot hear a sample before it is played")
        return written * (1 + self.drift_ppm * 1e-6) + delay


@dataclass
class WalkResponses:
    """A walk's room, simulated: one impulse response per pulse, and the truth.

    Parameters
    ----------
    fs : int
        Sample rate in Hz.
    schedule : vrecho.headset.ProbeSchedule
        The monitor's pulses.
    responses : list of numpy.ndarray
        Per pulse, loudspeaker to microphone; sample 0 is the emission.
    written : numpy.ndarray [shape=(K,)], int
        The sample of the loudspeaker's stream each pulse is written at.
    distance_m : numpy.ndarray [shape=(K,)]
        The loudspeaker's distance to the target's plane at each pulse, in metres.
    position_m : numpy.ndarray [shape=(K, 3)]
        The loudspeaker's position, in metres.
    forward : numpy.ndarray [shape=(K, 3)]
        The wearer's facing, unit: the heading swayed.
    mic_m : numpy.ndarray [shape=(K, 3)]
        The microphone's position, in metres.
    direct : float
        The direct sound's matched-filter-free peak (the probe through the direct path), for
        levels.
    headset : Headset
        The headset walked with.
    scene : Scene
        The room.
    """

    fs: int
    schedule: object
    responses: list
    written: np.ndarray
    distance_m: np.ndarray
    position_m: np.ndarray
    forward: np.ndarray
    mic_m: np.ndarray
    direct: float
    headset: Headset
    scene: Scene = field(repr=False)

    @property
    def room_level(self) -> float:
        """The level the room's sounds are set against (:func:`record_walk`): the direct sound the
        reference headset (PROTOCOL.md's device: the microphone 7 cm to the side of a loudspeaker
        facing forward) would hear from this loudspeaker. A room is no louder to a microphone a
        centimetre from its loudspeaker, nor quieter to one behind it: :attr:`direct` scaled by the
        reference's gain over distance, p / 7 cm, against this headset's, (p + (1 - p) cos a) / r
        (a the angle from the loudspeaker's axis to the microphone, r their spacing), as
        :mod:`vrecho.sim.devices` sets its frames' noise."""
        h = self.headset
        p = self.scene.emitter_p if h.speaker_p is None else h.speaker_p
        axis = np.asarray(h.speaker_axis, float)
        r = max(h.spacing_m, 1e-3)
        gain = p + (1 - p) * float(np.asarray(h.mic_offset_m, float) @ axis) / (r * float(np.linalg.norm(axis)))
        return self.direct * direct_amplitude(MIC_ABOVE_EMITTER_M, p) / direct_amplitude(r, max(gain, 1e-3))


@dataclass
class Walk:
    """A walk's recording, with the truth per pulse.

    Parameters
    ----------
    mic : numpy.ndarray [shape=(n,)], float64
        The microphone's stream at ``fs``.
    fs : int
        Sample rate in Hz.
    pulse_times_s : numpy.ndarray [shape=(K,)]
        When each pulse was written to the loudspeaker's stream, in seconds.
    distance_m : numpy.ndarray [shape=(K,)]
        The loudspeaker's true distance to the target's plane at each pulse, in metres.
    latency_s : float
        The round trip at the start (loudspeaker write to microphone read), in seconds, which
        the monitor does not know.
    position_m : numpy.ndarray [shape=(K, 3)]
        The loudspeaker's position, in metres.
    forward : numpy.ndarray [shape=(K, 3)]
        The wearer's facing, unit: the heading swayed.
    arrival : numpy.ndarray [shape=(K,)]
        Where each pulse's emission instant lies in the microphone's stream (fractional
        samples; its direct sound arrives the loudspeaker-to-microphone flight later).
    output_lag_s : float
        How long after being written a pulse is played, at the start, in seconds: the walk's
        position at a time ``t`` of the microphone's stream is that of the pulse written at
        ``t - output_lag_s``.
    """

    mic: np.ndarray
    fs: int
    pulse_times_s: np.ndarray
    distance_m: np.ndarray
    latency_s: float
    position_m: np.ndarray
    forward: np.ndarray
    arrival: np.ndarray = None
    output_lag_s: float = 0.0

    def distance_at(self, t_s: float) -> float:
        """The wearer's true distance to the target at a time of the microphone's stream.

        Parameters
        ----------
        t_s : float
            Seconds from the stream's start.

        Returns
        -------
        float
            Metres, from the pulses' truth (the nearest pulse written ``output_lag_s`` before).
        """
        k = int(np.clip(np.searchsorted(self.pulse_times_s, t_s - self.output_lag_s), 0, len(self.distance_m) - 1))
        return float(self.distance_m[k])


def walk_responses(scene: Scene, start: np.ndarray, goal: np.ndarray, speed_mps: float, schedule,
                   plane: tuple[np.ndarray, np.ndarray], rng: np.random.Generator, *, headset: Headset = Headset(),
                   stop_m: float = 0.15, lead_s: float = 0.3) -> WalkResponses:
    """The room's responses along a walk from ``start`` toward ``goal`` at ``speed_mps``.

    The wearer walks level (along the heading's horizontal part), stopping ``stop_m`` before
    the target's plane (a walk that passes by goes on as far as its heading allows), after
    standing ``lead_s`` at the start.

    Parameters
    ----------
    scene : Scene
        The room walked in.
    start, goal : numpy.ndarray [shape=(3,)]
        Loudspeaker positions in metres: where the walk starts, and a point it heads toward.
    speed_mps : float
        Walking speed in metres per second.
    schedule : vrecho.headset.ProbeSchedule
        The monitor's pulses (its ``schedule``): their times, probe and rate.
    plane : tuple of (numpy.ndarray, numpy.ndarray)
        The target's plane: a point on it and its unit normal, each (3,).
    rng : numpy.random.Generator
        Source of the head's motion.
    headset : Headset
        The loudspeaker and microphone (default PROTOCOL.md's device).
    stop_m : float
        Where the walk stops, in metres before the plane (default 0.15).
    lead_s : float
        Time standing still at the start, in seconds (default 0.3).

    Returns
    -------
    WalkResponses

    Raises
    ------
    VrechoError
        If the heading is not level with the walk, or a pulse's loudspeaker or microphone
        would leave the room.
    """
    import pyroomacoustics as pra  # heavy (1.4 s to import): only where it simulates or analyses

    fs = schedule.fs
    start, goal = np.asarray(start, float), np.asarray(goal, float)
    p0, normal = np.asarray(plane[0], float), np.asarray(plane[1], float)
    heading = goal - start
    heading[2] = 0.0
    if np.linalg.norm(heading) < 1e-9:
        raise VrechoError("walk: the goal must lie away from the start, horizontally")
    heading /= np.linalg.norm(heading)
    # pyroomacoustics' inside test draws from its own generator (a reference point off the room):
    # seeded from the walk, so that the same walk is simulated, or refused, the same in every run.
    pra.random.seed(zlib.crc32(np.r_[start, goal, speed_mps, schedule.emission(1)].tobytes()))
    dist0 = abs((start - p0) @ normal)
    along = float(heading @ (-np.sign((start - p0) @ normal) * normal))  # > 0: toward the plane
    length = (dist0 - stop_m) / along if along > 0.05 else np.linalg.norm(goal - start)
    duration = lead_s + length / speed_mps + 0.5 * speed_mps / ACCELERATION_MPS2
    n_pulses = schedule.first_at_or_after(int(duration * fs))
    bob_phase, sway_phase = rng.uniform(0, 2 * np.pi, 2)
    lag = pra.constants.get("frac_delay_length") // 2
    n_ir = int(WALK_SIMULATION.length_s * fs)
    p_speaker = scene.emitter_p if headset.speaker_p is None else headset.speaker_p
    written = np.array([schedule.emission(k) for k in range(n_pulses)], int)
    out = WalkResponses(fs, schedule, [], written, np.zeros(n_pulses), np.zeros((n_pulses, 3)), np.zeros((n_pulses, 3)),
                        np.zeros((n_pulses, 3)), 0.0, headset, scene)
    for k in range(n_pulses):
        t = written[k] / fs
        s = _walked(max(0.0, t - lead_s), speed_mps)
        pos = start + heading * min(s, length) + [0.0, 0.0, 0.02 * np.sin(2 * np.pi * 1.8 * t + bob_phase)]
        yaw = np.radians(3.0) * np.sin(2 * np.pi * 0.9 * t + sway_phase)
        c, sn = np.cos(yaw), np.sin(yaw)
        fwd = np.array([c * heading[0] - sn * heading[1], sn * heading[0] + c * heading[1], 0.0])
        frame = headset.world(fwd)
        mic = pos + frame @ np.asarray(headset.mic_offset_m, float)
        if not scene.room.contains(np.array([pos, mic])).all() or any(
                f.contains(np.array([pos, mic]), margin_m=0.02).any() for f in scene.furniture):
            raise VrechoError(f"walk: the headset leaves the room's air at pulse {k} ({np.round(pos, 2).tolist()})")
        room = build_room(scene, fs, sim=WALK_SIMULATION)  # pyroomacoustics keeps per-source state
        directivity = None if p_speaker >= 1.0 else emitter_directivity(frame @ np.asarray(headset.speaker_axis, float),
                                                                        p_speaker)
        try:
            room.add_source(pos, directivity=directivity)
            room.add_microphone(mic)
            room.compute_rir()
        except ValueError as e:  # (pyroomacoustics, where its image sources find no path: said, not hidden)
            raise VrechoError(f"walk: pyroomacoustics could not simulate pulse {k} at {np.round(pos, 2).tolist()}: {e}") from e
        out.responses.append(np.asarray(room.rir[0][0], float)[lag:lag + n_ir])
        out.distance_m[k] = abs((pos - p0) @ normal)
        out.position_m[k], out.forward[k], out.mic_m[k] = pos, fwd, mic
    # The direct path's share of the first response: the level every other sound is set against.
    direct_len = int((headset.spacing_m / SPEED_OF_SOUND + 0.0008) * fs) + 1
    out.direct = float(np.max(np.abs(np.convolve(out.responses[0][:direct_len], schedule.probe(0)))))
    return out


def other_headsets(walk: WalkResponses, n: int, rng: np.random.Generator) -> np.ndarray:
    """What ``n`` other headsets in the room, running the same call, put into this one's
    microphone: each wearer stands or walks slowly 0.8 to 3 m from the walk's start, its
    loudspeaker as loud as this one's, its pulses on its own dithered schedule and clock.

    Parameters
    ----------
    walk : WalkResponses
        This headset's walk (its microphone's positions and the pulses' times).
    n : int
        How many others.
    rng : numpy.random.Generator
        Their places, facings, seeds and start times.

    Returns
    -------
    numpy.ndarray [shape=(samples,)]
        Their pings at this headset's microphone, on its loudspeaker's clock from its first
        pulse (unscaled: the probe as written).
    """
    import pyroomacoustics as pra  # heavy (1.4 s to import): only where it simulates or analyses

    sch, fs, room = walk.schedule, walk.fs, walk.scene.room
    total = int(walk.written[-1]) + sch.period + int(WALK_SIMULATION.length_s * fs) + sch.length
    out = np.zeros(total)
    lag = pra.constants.get("frac_delay_length") // 2
    n_ir = int(WALK_SIMULATION.length_s * fs)
    for _ in range(n):
        for _attempt in range(50):
            angle = rng.uniform(0, 2 * np.pi)
            where = walk.position_m[0] + rng.uniform(0.8, 3.0) * np.array([np.cos(angle), np.sin(angle), 0.0])
            where[2] = rng.uniform(1.45, 1.85)
            drift = rng.uniform(-0.3, 0.3) * np.array([np.cos(angle + 1.5), np.sin(angle + 1.5), 0.0])
            path = where + np.linspace(0.0, total / fs, 8)[:, None] * drift
            if room.contains(path, margin_m=0.3).all() and not any(f.contains(path, margin_m=0.2).any()
                                                                   for f in walk.scene.furniture):
                break
        else:
            continue
        facing = rng.normal(size=3)
        facing[2] *= 0.2
        seed = int(rng.integers(2 ** 32))
        other = ProbeSchedule(fs, sch.probes, period_s=sch.period / fs, dither_s=sch.dither / fs, seed=seed)
        pra.random.seed(seed)  # (its inside tests: as walk_responses')
        offset = int(rng.integers(0, sch.period))
        p = float(rng.uniform(0.55, 1.0))
        response = None
        for k in range(total // sch.period + 1):
            e = other.emission(k) + offset
            if e >= total:
                break
            if k % 4 == 0:  # its wearer moves a few centimetres a pulse: a response every fourth
                i = min(int(np.searchsorted(walk.written, e)), len(walk.written) - 1)
                r = build_room(walk.scene, fs, sim=WALK_SIMULATION)
                try:
                    r.add_source(where + drift * (e / fs), directivity=None if p >= 1 else emitter_directivity(facing, p))
                    r.add_microphone(walk.mic_m[i])
                    r.compute_rir()
                    response = np.asarray(r.rir[0][0], float)[lag:lag + n_ir]
                except ValueError:  # pyroomacoustics may refuse a point (its randomised inside test, no
                    pass  # image source found): the last response stands
            if response is None:
                continue
            seg = np.convolve(response, other.probe(k))[:total - e]
            out[e:e + len(seg)] += seg
    return out


def record_walk(walk: WalkResponses, rng: np.random.Generator, *, link: AudioLink = AudioLink(),
                snr_db: float | None = None, ambient: str | None = None, ambient_db: float | None = None,
                others: np.ndarray | None = None) -> Walk:
    """A walk's responses heard through an audio stream (see the module's notes).

    Parameters
    ----------
    walk : WalkResponses
        The walk's room (:func:`walk_responses`).
    rng : numpy.random.Generator
        Source of the noise and the ambient sound.
    link : AudioLink
        The stream's round trip, its steps and the clocks' drift (default: none).
    snr_db : float, optional
        Pink background noise in dB below the direct sound's peak as the reference headset
        hears it (:attr:`WalkResponses.room_level`; drawn from 20 to 40 dB by default), and the
        microphone's self-noise 60 dB below it.
    ambient : {"speech", "music", "tv", "fan"}, optional
        An ambient sound (:data:`AMBIENT_KINDS`), its RMS ``ambient_db`` below the same level
        (drawn from 0 to 30 dB by default).
    ambient_db : float, optional
        See ``ambient``.
    others : numpy.ndarray, optional
        Other headsets' pings (:func:`other_headsets`).

    Returns
    -------
    Walk
        The microphone's stream, scaled so that its loudest sample sits at half scale, to one
        period past the last pulse.

    Raises
    ------
    VrechoError
        For an unknown ``ambient``.
    """
    fs, sch = walk.fs, walk.schedule
    arrival = link.arrival(walk.written, fs)
    n_ir = len(walk.responses[0])
    total = int(np.ceil(arrival.max())) + sch.period + n_ir + sch.length + 1
    x = np.zeros(total)
    for k, (a, h) in enumerate(zip(arrival, walk.responses)):
        seg = np.convolve(h, sch.probe(k))
        e = int(round(a))
        x[e:e + len(seg)] += seg
    if others is not None:  # (where their pings fall on this stream's clock is arbitrary: their own start)
        at = link.arrival(np.arange(len(others)), fs).round().astype(int)
        keep = at < total
        np.add.at(x, at[keep], others[keep])
    n = len(x)
    d = walk.room_level
    snr = float(rng.uniform(20, 40)) if snr_db is None else snr_db
    x += d * (10 ** (-snr / 20) * colored_noise(n, 1.0, rng) + 10 ** (-60 / 20) * rng.standard_normal(n))
    if ambient is not None:
        if ambient not in AMBIENT_KINDS:
            raise VrechoError(f"ambient: expected one of {AMBIENT_KINDS}, got {ambient!r}")
        kinds = {"speech": ("speech",), "music": ("music",), "tv": ("speech", "music"), "fan": ("hum",)}[ambient]
        sound = sum(ambient_sound(kind, n / fs + 0.01, fs, rng)[:n] for kind in kinds)
        level = float(rng.uniform(0, 30)) if ambient_db is None else ambient_db
        x += d * 10 ** (-level / 20) * sound / (np.sqrt(np.mean(sound ** 2)) + 1e-12)
    end = int(np.ceil(arrival[-1])) + sch.period
    x = x[:end]
    gain = 0.5 / max(float(np.max(np.abs(x))), 1e-12)
    return Walk(x * gain, fs, walk.written / fs, walk.distance_m.copy(), link.latency_s, walk.position_m,
                walk.forward, arrival, link.latency_s * link.output_share)


def simulate_walk(scene: Scene, start: np.ndarray, goal: np.ndarray, speed_mps: float, schedule,
                  plane: tuple[np.ndarray, np.ndarray], rng: np.random.Generator, *, headset: Headset = Headset(),
                  link: AudioLink | None = None, stop_m: float = 0.15, snr_db: float | None = None,
                  lead_s: float = 0.3) -> Walk:
    """The microphone's stream of a walk (:func:`walk_responses` then :func:`record_walk`).

    Parameters
    ----------
    scene, start, goal, speed_mps, schedule, plane, headset, stop_m, lead_s
        As for :func:`walk_responses`.
    rng : numpy.random.Generator
        Source of the head's motion, the round trip (when ``link`` is None) and the noise.
    link : AudioLink, optional
        The audio stream (default: a round trip of 0 to 5 ms, as a headset's own audio path).
    snr_db : float, optional
        As for :func:`record_walk`.

    Returns
    -------
    Walk
    """
    walk = walk_responses(scene, start, goal, speed_mps, schedule, plane, rng, headset=headset, stop_m=stop_m,
                          lead_s=lead_s)
    if link is None:
        link = AudioLink(int(rng.integers(0, int(0.005 * schedule.fs))) / schedule.fs)
    return record_walk(walk, rng, link=link, snr_db=snr_db)


def headset_frames(world, walk: Walk, *, every: int = 6, latency_s: float = 0.05) -> list:
    """What the headset's camera shows along a walk.

    The camera (:data:`vrecho.sim.walks.HEADSET_CAMERA`) is 7 cm above the loudspeaker, facing
    the wearer's way: a frame at every ``every``-th pulse, arriving ``latency_s`` after the
    wearer was there (on the microphone stream's clock).

    Parameters
    ----------
    world : World
        The walk's scene as a :class:`vrecho.sim.render.World`.
    walk : Walk
        The walk, from :func:`simulate_walk` or :func:`record_walk`.
    every : int
        A frame at every ``every``-th pulse (default 6).
    latency_s : float
        The camera's latency in seconds (default 0.05).

    Returns
    -------
    list of tuple
        [(arrival time on the stream's clock in seconds, gray (240, 320) float32 in [0, 1],
        depth (240, 320) float32 in metres, intrinsics (3, 3))], for
        :meth:`vrecho.headset.BoundaryMonitor.see`.
    """
    frames = []
    for k in range(0, len(walk.pulse_times_s), every):
        pose = camera_pose(walk.position_m[k] + [0.0, 0.0, MIC_ABOVE_EMITTER_M], walk.forward[k])
        view = render_view(world, pose, camera=HEADSET_CAMERA)
        frames.append((walk.pulse_times_s[k] + walk.output_lag_s + latency_s, view.gray, view.depth, view.intrinsics))
    return frames


def echo_round_trip_s(distance_m: float, *, spacing_m: float = MIC_ABOVE_EMITTER_M) -> float:
    """Seconds from emission to the echo of a surface ``distance_m`` straight ahead.

    The microphone is ``spacing_m`` across the way from the loudspeaker (7 cm above it by
    default); sound travels at 343 m/s.

    Parameters
    ----------
    distance_m : float
        The surface's distance from the loudspeaker in metres.
    spacing_m : float
        Loudspeaker to microphone, across the way, in metres.

    Returns
    -------
    float
        The echo's arrival in seconds after emission.

    Examples
    --------
    >>> round(echo_round_trip_s(1.0), 6)
    0.005834
    """
    return float(np.sqrt((2 * distance_m) ** 2 + spacing_m ** 2) / SPEED_OF_SOUND)
