"""Simulated walks for the headset call: a wearer walks toward a surface while the device plays
:class:`vrecho.headset.BoundaryMonitor`'s probe; what its microphone records.

Each probe pulse gets its own impulse response at the device's pose of that instant
(pyroomacoustics' image sources up to second order: the specular echoes that ranging is about;
the same room as the foundation's simulator, its glass, mirrors and openings as their own wall
patches). The walk bobs the head (2 cm at 1.8 Hz) and sways it (3 degrees at 0.9 Hz); the audio
stream has an output latency of 0 to 5 ms the monitor does not know; pink background noise 20
to 40 dB below the direct sound and microphone self-noise are added as PROTOCOL.md says.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..camera import Camera, camera_pose
from ..device import MIC_ABOVE_EMITTER_M
from ..errors import VrechoError
from ..scene import Scene
from ..signals import SPEED_OF_SOUND, colored_noise
from .acoustics import Simulation, build_room, emitter_directivity
from .render import render_view

WALK_SIMULATION = Simulation(max_order=2, n_rays=0, length_s=0.06, air_absorption=True)


HEADSET_CAMERA = Camera(width=320, height=240, fov_deg=100.0)
"""The simulated headset's camera (benchmarks, tests): wide, as headsets' tracking cameras are."""


@dataclass
class Walk:
    """A walk's recording, with the truth per pulse.

    Parameters
    ----------
    mic : numpy.ndarray [shape=(n,)], float64
        The microphone's signal at ``fs``.
    fs : int
        Sample rate in Hz.
    pulse_times_s : numpy.ndarray [shape=(K,)]
        Each pulse's emission, on the stream's clock, in seconds.
    distance_m : numpy.ndarray [shape=(K,)]
        The emitter's true distance to the target's plane in metres.
    latency_s : float
        The audio stream's output latency in seconds (0 to 5 ms), which the monitor does not
        know: a pulse is emitted this much after its time on the stream's clock.
    position_m : numpy.ndarray [shape=(K, 3)]
        The emitter's position in metres.
    forward : numpy.ndarray [shape=(K, 3)]
        The wearer's facing, unit: the heading swayed.
    """

    mic: np.ndarray
    fs: int
    pulse_times_s: np.ndarray
    distance_m: np.ndarray
    latency_s: float
    position_m: np.ndarray
    forward: np.ndarray


def simulate_walk(scene: Scene, start: np.ndarray, goal: np.ndarray, speed_mps: float, probe: np.ndarray,
                  period_s: float, fs: int, rng: np.random.Generator, plane: tuple[np.ndarray, np.ndarray],
                  *, stop_m: float = 0.15, snr_db: float | None = None, lead_s: float = 0.3) -> Walk:
    """The microphone signal of a walk from ``start`` toward ``goal`` at ``speed_mps``.

    The wearer walks level (along the heading's horizontal part), stopping ``stop_m`` before
    the target's plane, and the device plays ``probe`` every ``period_s`` (see the module's
    docstring for the head's motion, the latency and the noise). The signal is scaled so that
    the direct sound peaks at half scale.

    Parameters
    ----------
    scene : Scene
        The room walked in.
    start, goal : numpy.ndarray [shape=(3,)]
        Emitter positions in metres: where the walk starts, and a point it heads toward.
    speed_mps : float
        Walking speed in metres per second.
    probe : numpy.ndarray [shape=(k,)]
        The sound played at each pulse, at ``fs``.
    period_s : float
        Time between pulses in seconds.
    fs : int
        Sample rate in Hz.
    rng : numpy.random.Generator
        Source of the latency, the head's motion and the noise.
    plane : tuple of (numpy.ndarray, numpy.ndarray)
        The target's plane: a point on it and its unit normal, each (3,).
    stop_m : float
        Where the walk stops, in metres before the plane (default 0.15).
    snr_db : float, optional
        Pink background noise in dB below the direct sound (drawn from 20 to 40 dB by default).
    lead_s : float
        Time standing still at the start first, in seconds (default 0.3).

    Returns
    -------
    Walk
        The recording, to at most one period past the last pulse, and the truth.

    Raises
    ------
    VrechoError
        If the heading does not meet the target's plane within 60 degrees.
    """
    import pyroomacoustics as pra  # heavy (1.4 s to import): only where it simulates or analyses

    start, goal = np.asarray(start, float), np.asarray(goal, float)
    p0, normal = np.asarray(plane[0], float), np.asarray(plane[1], float)
    heading = goal - start
    heading[2] = 0.0
    heading /= np.linalg.norm(heading)
    dist0 = abs((start - p0) @ normal)
    along = abs(heading @ normal)
    if along < 0.5:
        raise VrechoError("walk: the heading must meet the target's plane within 60 degrees")
    length = (dist0 - stop_m) / along
    duration = lead_s + length / speed_mps
    period = int(round(period_s * fs))
    n_pulses = int(duration * fs) // period
    latency = int(rng.integers(0, int(0.005 * fs)))
    snr = float(rng.uniform(20, 40)) if snr_db is None else snr_db
    bob_phase, sway_phase = rng.uniform(0, 2 * np.pi, 2)
    lag = pra.constants.get("frac_delay_length") // 2
    n_ir = int(WALK_SIMULATION.length_s * fs)
    total = n_pulses * period + n_ir + len(probe) + latency
    x = np.zeros(total)
    times, dists, where, facing = np.zeros(n_pulses), np.zeros(n_pulses), np.zeros((n_pulses, 3)), np.zeros((n_pulses, 3))
    for k in range(n_pulses):
        t = k * period / fs
        s = max(0.0, t - lead_s) * speed_mps
        pos = start + heading * min(s, length)
        pos = pos + [0.0, 0.0, 0.02 * np.sin(2 * np.pi * 1.8 * t + bob_phase)]
        yaw = np.radians(3.0) * np.sin(2 * np.pi * 0.9 * t + sway_phase)
        c, sn = np.cos(yaw), np.sin(yaw)
        fwd = np.array([c * heading[0] - sn * heading[1], sn * heading[0] + c * heading[1], 0.0])
        room = build_room(scene, fs, sim=WALK_SIMULATION)  # pyroomacoustics keeps per-source state
        room.add_source(pos, directivity=emitter_directivity(fwd, scene.emitter_p))
        room.add_microphone(pos + [0.0, 0.0, MIC_ABOVE_EMITTER_M])
        room.compute_rir()
        h = np.asarray(room.rir[0][0], float)[lag:lag + n_ir]
        e = k * period + latency
        seg = np.convolve(h, probe)
        x[e:e + len(seg)] += seg
        times[k] = t
        dists[k] = abs((pos - p0) @ normal)
        where[k] = pos
        facing[k] = fwd
    direct = np.max(np.abs(np.convolve(np.asarray(room.rir[0][0], float)[lag:lag + 64], probe)))
    n = len(x)
    x += direct * (10 ** (-snr / 20) * colored_noise(n, 1.0, rng) + 10 ** (-60 / 20) * rng.standard_normal(n))
    gain = 0.5 / direct  # the direct sound peaks at half scale
    return Walk((x * gain)[:n_pulses * period + period], fs, times, dists, latency / fs, where, facing)


def headset_frames(world, walk: Walk, *, every: int = 6, latency_s: float = 0.05) -> list:
    """What the headset's camera shows along a walk.

    The camera (:data:`vrecho.sim.walks.HEADSET_CAMERA`) is at the microphone, facing the
    wearer's way: a frame at every ``every``-th pulse, arriving ``latency_s`` after it.

    Parameters
    ----------
    world : World
        The walk's scene as a :class:`vrecho.sim.render.World`.
    walk : Walk
        The walk, from :func:`simulate_walk`.
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
        frames.append((walk.pulse_times_s[k] + latency_s, view.gray, view.depth, view.intrinsics))
    return frames


def echo_round_trip_s(distance_m: float) -> float:
    """Seconds from emission to the echo of a surface ``distance_m`` straight ahead.

    The microphone is 7 cm above the emitter; sound travels at 343 m/s.

    Parameters
    ----------
    distance_m : float
        The surface's distance from the emitter in metres.

    Returns
    -------
    float
        The echo's arrival in seconds after emission.

    Examples
    --------
    >>> round(echo_round_trip_s(1.0), 6)
    0.005834
    """
    return float(np.sqrt((2 * distance_m) ** 2 + MIC_ABOVE_EMITTER_M ** 2) / SPEED_OF_SOUND)
