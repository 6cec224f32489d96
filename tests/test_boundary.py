"""vrecho.headset.BoundaryMonitor (also vrecho.boundary): the headset call, on walks simulated with pyroomacoustics in a small room."""

import dataclasses

import numpy as np
import pytest

from conftest import small_room
from vrecho.headset import BoundaryMonitor, ranging_probe
from vrecho.errors import VrechoError
from vrecho.sim.render import World
from vrecho.sim.walks import echo_round_trip_s, headset_frames, simulate_walk

FS = 48000


def _walk(kind: str, speed: float = 1.0, seed: int = 0):
    scene = small_room()
    if kind == "open":  # the small room's opening made a door, reaching the floor
        d = scene.discontinuities[2]
        scene.discontinuities[2] = dataclasses.replace(d, center_z_m=1.05, height_m=2.1, width_m=1.2)
    wall = {"glass": 0, "open": 2}[kind]
    d = scene.discontinuities[wall]
    origin, u, normal = scene.room.wall_frame(wall)
    target = origin + d.center_u_m * u + [0.0, 0.0, 1.55]
    start = target - 2.4 * normal
    return simulate_walk(scene, start, target, speed, ranging_probe(FS), 0.04, FS, np.random.default_rng(seed),
                         (origin, normal), stop_m=0.15 if kind == "glass" else 0.0)


@pytest.fixture(scope="module")
def glass():
    return _walk("glass")


@pytest.fixture(scope="module")
def door():
    return _walk("open")


def _run(walk, mic=None, sizes=None, rng=None, frames=()):
    """The monitor over a walk, in blocks; ``frames``: (time, gray, depth, intrinsics) shown to
    it once the block that reaches their time has been processed."""
    mon = BoundaryMonitor(FS)
    x = walk.mic if mic is None else mic
    frames = list(frames)
    alerts, ends, i = [], [], 0
    while i < len(x):
        n = 480 if sizes is None else int(rng.integers(*sizes))
        block = x[i:i + n]
        speaker = np.zeros(len(block))
        alerts.append(mon.process(block, speaker))
        i += len(block)
        ends.append(i)
        while frames and frames[0][0] <= i / FS:
            mon.see(*frames.pop(0)[1:])
    return mon, alerts, np.array(ends)


def _true_distance(walk, t_s):
    k = min(int(t_s / 0.04), len(walk.distance_m) - 1)
    return walk.distance_m[k]


def _first(alerts, ends, walk, level):
    for a, e in zip(alerts, ends):
        if a.level in level:
            return a, e, _true_distance(walk, e / FS)
    return None, None, None


def test_walking_into_glass_raises_caution_then_stop(glass):
    mon, alerts, ends = _run(glass)
    a, _, at = _first(alerts, ends, glass, ("caution", "stop"))
    assert a is not None and at >= 0.5, at  # caution before 0.5 m
    s, end, at_stop = _first(alerts, ends, glass, ("stop",))
    assert s is not None and 0.2 <= at_stop <= 0.55 and s.surface == "closed"
    # The alert comes in the block in which the echo that crossed 0.5 m ended.
    k = int(round(s.pulse_time_s * FS / mon.period))
    echo_end = k * mon.period / FS + glass.latency_s + echo_round_trip_s(s.distance_m) + len(mon.probe) / FS
    assert (end - 480) / FS < echo_end <= end / FS
    # Distances to a centimetre: against the truth at the pulse that measured them.
    err = [abs(a.distance_m - glass.distance_m[int(round(a.pulse_time_s * FS / mon.period))])
           for a in alerts if a.distance_m is not None and a.pulse_time_s is not None]
    assert len(err) > 20 and np.median(err) < 0.01
    assert 0.7 < alerts[-1].closing_speed_mps < 1.3  # the walk's 1 m/s


def test_the_headset_camera_tells_glass(glass):
    # The camera's frames along the walk, 4 a second: the alert names the surface once seen.
    _, alerts, ends = _run(glass, frames=headset_frames(World(small_room()), glass))
    a, _, at = _first(alerts, ends, glass, ("caution", "stop"))
    assert a is not None and at >= 0.5  # seeing changes no level
    s, _, _ = _first(alerts, ends, glass, ("stop",))
    assert s.surface == "glass"
    assert {a.surface for a in alerts if a.level != "clear"} <= {"closed", "glass"}


def test_walking_through_a_door_raises_nothing(door):
    _, alerts, _ = _run(door)
    assert all(a.level == "clear" for a in alerts)
    assert any(a.surface == "opening" for a in alerts)


def test_the_speaker_gets_the_probe_on_the_same_clock():
    mon = BoundaryMonitor(44100)
    out = np.zeros(0)
    for n in (100, 441, 1000, 2048, 7):  # block sizes change from call to call
        block = np.zeros(n)
        mon.process(np.full(n, 1e-4), block)
        out = np.r_[out, block]
    probe, period = mon.probe, mon.period
    assert np.allclose(out[:len(probe)], probe) and np.allclose(out[period:period + len(probe)], probe)
    assert np.all(out[len(probe):period] == 0)
    stereo = np.zeros((256, 2))
    mon.process(np.zeros((256, 2)), stereo)  # (frames, channels) blocks, as sounddevice gives them
    assert np.array_equal(stereo[:, 0], stereo[:, 1])


def test_disturbed_input_is_flagged_and_survived(glass):
    rng = np.random.default_rng(1)
    x = np.clip(glass.mic.copy(), -0.25, 0.25)  # clipped at half the direct sound
    sec = FS
    x[int(0.6 * sec):int(0.62 * sec)] = 0.0  # a dropout
    x[int(1.1 * sec):int(1.11 * sec)] = np.nan  # a block of NaNs
    mon, alerts, ends = _run(glass, x, sizes=(1, 2049), rng=rng)
    flags = {f for a in alerts for f in a.flags}
    assert {"clipped", "dropout", "nan"} <= flags
    a, _, at = _first(alerts, ends, glass, ("caution", "stop"))
    assert a is not None and at >= 0.5


def test_a_clipped_direct_sound_raises_no_false_alarm():
    # Clipped at 40 % of its peak, the direct sound's distortion spreads over one probe's length
    # after it, above the clean sidelobes: it must not read as surfaces a few decimetres away
    # (this walk raised caution and stop on 37 blocks when it did).
    door = _walk("open", speed=1.3, seed=1)
    _, alerts, _ = _run(door, np.clip(door.mic, -0.2, 0.2))
    assert all(a.level == "clear" for a in alerts)
    assert any("clipped" in a.flags for a in alerts)


def test_a_fast_walk_into_glass_is_warned_in_time():
    fast = _walk("glass", speed=2.0, seed=3)  # 8 cm a pulse
    _, alerts, ends = _run(fast)
    a, _, at = _first(alerts, ends, fast, ("caution", "stop"))
    assert a is not None and at >= 0.5, at
    assert 1.6 < alerts[-1].closing_speed_mps < 2.4


def test_a_dropout_late_in_every_pulse_keeps_the_echoes_before_it(glass):
    # 5 ms of zeros 25 ms after every pulse (beyond the echoes of the last 3.5 m): the echoes
    # wholly heard before the damage still count (a damaged window used to be dropped whole).
    x = glass.mic.copy()
    period = int(0.04 * FS)
    for e in range(0, len(x), period):
        x[e + int(0.025 * FS):e + int(0.030 * FS)] = 0.0
    _, alerts, ends = _run(glass, x)
    assert any("dropout" in a.flags for a in alerts)
    a, _, at = _first(alerts, ends, glass, ("caution", "stop"))
    assert a is not None and at >= 0.5, at


def test_no_echo_at_all_is_clear_and_says_so():
    mon = BoundaryMonitor(FS)
    rng = np.random.default_rng(0)
    for _ in range(100):
        a = mon.process(1e-3 * rng.standard_normal(480))
    assert a.level == "clear" and a.distance_m is None and "no_echo" in a.flags
    for _ in range(10):
        a = mon.process(np.zeros(480))  # silence: a dropout, not a crash
    assert a.level == "clear"


def test_bad_settings_and_blocks_say_why():
    with pytest.raises(VrechoError, match="44100 or 48000"):
        BoundaryMonitor(16000)
    with pytest.raises(VrechoError, match="period_s"):
        BoundaryMonitor(FS, period_s=0.01)
    with pytest.raises(VrechoError, match="stop_m"):
        BoundaryMonitor(FS, stop_m=1.5, caution_m=1.0)
    mon = BoundaryMonitor(FS)
    with pytest.raises(VrechoError, match="mic"):
        mon.process(np.zeros((4, 4, 4)))
    with pytest.raises(VrechoError, match="speaker"):
        mon.process(np.zeros(480), np.zeros(100))
