"""People walking past a headset's wearer (:func:`passersby`), and their bodies' echoes added to
a simulated walk's responses (:func:`with_passersby`): a person is an upright body the probe's
sound reflects off, walking straight at a steady pace while in the room. The benchmark's row
"people walking past" (``benchmarks/bench_boundary.py``) hears them through the headset call.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ..signals import SPEED_OF_SOUND
from .acoustics import direct_amplitude
from .walks import WalkResponses


@dataclass(frozen=True)
class Passerby:
    """Someone walking past the wearer (:func:`passersby`): an upright body the probe's sound
    reflects off (:func:`with_passersby`), walking straight at a steady pace while in the room.

    Parameters
    ----------
    start_m : tuple of (float, float)
        Where they are (x, y in metres) at the walk's first sample.
    velocity_mps : tuple of (float, float)
        Their walk, in m/s.
    radius_m : float
        The body's, shoulders and torso taken as an upright cylinder, in metres.
    height_m : float
        Their height in metres: above the shoulders (0.1 m below it), the head, a sphere of 0.1 m.
    reflectance : float
        The share of the sound's pressure the (clothed) body sends back.
    present_s : tuple of (float, float)
        When they are in the room, in seconds of the walk (come in, gone out: no echo).
    """

    start_m: tuple[float, float]
    velocity_mps: tuple[float, float]
    radius_m: float = 0.2
    height_m: float = 1.75
    reflectance: float = 0.5
    present_s: tuple[float, float] = (0.0, np.inf)

    def at(self, t_s: float) -> np.ndarray:
        """Where they are (x, y in metres) ``t_s`` seconds into the walk.

        Parameters
        ----------
        t_s : float

        Returns
        -------
        numpy.ndarray [shape=(2,)]
        """
        return np.asarray(self.start_m, float) + t_s * np.asarray(self.velocity_mps, float)


def passersby(walk: WalkResponses, n: int, rng: np.random.Generator, *, gap_m: tuple[float, float] = (0.6, 2.0)) -> list:
    """``n`` people walking past the wearer, at 0.8 to 1.6 m/s in any direction (across the way
    ahead or behind, the other way alongside, overtaking): each passes the headset within
    ``gap_m`` of their body at some moment of the walk's middle half, and their straight path
    never nearer than its lower bound over the whole walk (nothing the wearer walks into, nor
    anyone on a course to meet the wearer). They are in the room (its air, clear of its
    furniture) for at least a second about that moment, and heard while they are.

    Parameters
    ----------
    walk : WalkResponses
        The wearer's walk (its headset's positions at the pulses).
    n : int
        How many people.
    rng : numpy.random.Generator
        Their paths and bodies.
    gap_m : tuple of float
        The nearest their body comes to the headset, in metres: drawn between the two.

    Returns
    -------
    list of Passerby
        Fewer than ``n`` where the room leaves no such path (100 tries each).
    """
    t = walk.written / walk.fs
    head = walk.position_m[:, :2]
    out = []
    for _ in range(n):
        for _attempt in range(100):
            radius = float(rng.uniform(0.15, 0.25))
            k = int(rng.integers(len(t) // 4, max(3 * len(t) // 4, len(t) // 4 + 1)))
            angle, heading = rng.uniform(0, 2 * np.pi, 2)
            where = head[k] + (radius + rng.uniform(*gap_m)) * np.array([np.cos(angle), np.sin(angle)])
            velocity = rng.uniform(0.8, 1.6) * np.array([np.cos(heading), np.sin(heading)])
            path = where + (t - t[k])[:, None] * velocity
            body = np.c_[path, np.full(len(t), 1.0)]
            inside = walk.scene.room.contains(body, margin_m=radius + 0.05)
            for f in walk.scene.furniture:
                inside &= ~f.contains(body, margin_m=radius)
            if not inside[k]:
                continue
            lo, hi = k, k  # the stretch of the walk they are in the room for, about pulse k
            while lo > 0 and inside[lo - 1]:
                lo -= 1
            while hi + 1 < len(t) and inside[hi + 1]:
                hi += 1
            # Past, not into: their straight path keeps its distance over the whole walk, out of the room
            # too (one who came that near, there, would have been walking into the wearer).
            if (np.linalg.norm(path - head, axis=1).min() - radius >= gap_m[0]
                    and t[hi] - t[lo] >= min(1.0, t[-1] - t[0])):
                out.append(Passerby(tuple(where - t[k] * velocity), tuple(velocity), radius,
                                    float(rng.uniform(1.55, 1.95)), float(rng.uniform(0.5, 0.9)),
                                    (float(t[lo]), float(t[hi]))))
                break
    return out


def with_passersby(walk: WalkResponses, people: list) -> WalkResponses:
    """The walk's responses with each person's echo added: one specular reflection off their
    body, loudspeaker to body to microphone (geometric acoustics: a convex body's echo is a
    plane's, :func:`~vrecho.sim.acoustics.direct_amplitude` of the path as pyroomacoustics scales
    its own, times sqrt(a / (a + R)) for an upright cylinder of radius a at range R, a / (a + R)
    for a sphere), through the loudspeaker's directivity toward them, at its fractional delay (a
    Hann-windowed sinc, as pyroomacoustics places its own). Their reflections by way of the
    room's surfaces, and the shadow they cast on its echoes, are not simulated.

    Parameters
    ----------
    walk : WalkResponses
        The wearer's walk.
    people : list of Passerby
        Who walks past.

    Returns
    -------
    WalkResponses
        A copy; ``walk`` is left as it was.
    """
    fs = walk.fs
    p = walk.scene.emitter_p if walk.headset.speaker_p is None else walk.headset.speaker_p
    taps = np.arange(-16, 17)
    window = np.hanning(len(taps) + 2)[1:-1]
    responses = []
    for k, h in enumerate(walk.responses):
        h = h.copy()
        speaker, mic = walk.position_m[k], walk.mic_m[k]
        axis = walk.headset.world(walk.forward[k]) @ np.asarray(walk.headset.speaker_axis, float)
        mid = 0.5 * (speaker + mic)
        t = walk.written[k] / fs
        for person in people:
            if not person.present_s[0] <= t <= person.present_s[1]:
                continue
            where = person.at(t)
            body = mid[2] < person.height_m - 0.1  # level with the body: an upright cylinder
            if body:
                a, centre = person.radius_m, np.r_[where, mid[2]]
            else:  # above the shoulders: the head, a sphere
                a, centre = 0.1, np.r_[where, person.height_m - 0.1]
            toward = mid - centre
            point = centre + a * toward / np.linalg.norm(toward)  # where the echo reflects
            r_s, r_m = np.linalg.norm(point - speaker), np.linalg.norm(point - mic)
            r = 0.5 * (r_s + r_m)
            curved = np.sqrt(a / (a + r)) if body else a / (a + r)
            gain = p + (1 - p) * float(axis @ (point - speaker)) / (np.linalg.norm(axis) * r_s)
            at = (r_s + r_m) / SPEED_OF_SOUND * fs
            i = int(np.floor(at))
            idx = i + taps
            keep = (idx >= 0) & (idx < len(h))
            h[idx[keep]] += (direct_amplitude(r_s + r_m, person.reflectance * gain * curved)
                             * np.sinc(taps - (at - i)) * window)[keep]
        responses.append(h)
    return replace(walk, responses=responses)
