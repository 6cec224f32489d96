"""vrecho.headset.BoundaryMonitor (also vrecho.boundary): the headset call, on walks simulated with pyroomacoustics in a small room."""

import dataclasses

import numpy as np
import pytest

from conftest import small_room
from vrecho.errors import VrechoError
from vrecho.signals import SPEED_OF_SOUND
from vrecho.headset import BoundaryMonitor
from vrecho.sim.render import World
from vrecho.sim.people import Passerby, passersby, with_passersby
from vrecho.sim.walks import AudioLink, Headset, echo_round_trip_s, headset_frames, other_headsets, record_walk, simulate_walk, \
    walk_responses

FS = 48000
SEED = 3  # the monitor's dither: the walks are simulated on its schedule


def _monitor(**kwargs) -> BoundaryMonitor:
    return BoundaryMonitor(FS, seed=SEED, **kwargs)


def _geometry(kind: str):
    scene = small_room()
    if kind == "open":  # the small room's opening made a door, reaching the floor
        d = scene.discontinuities[2]
        scene.discontinuities[2] = dataclasses.replace(d, center_z_m=1.05, height_m=2.1, width_m=1.2)
    wall = {"glass": 0, "open": 2}[kind]
    d = scene.discontinuities[wall]
    origin, u, normal = scene.room.wall_frame(wall)
    target = origin + d.center_u_m * u + [0.0, 0.0, 1.55]
    return scene, target - 2.4 * normal, target, (origin, normal)


def _walk(kind: str, speed: float = 1.0, seed: int = 0):
    scene, start, target, plane = _geometry(kind)
    return simulate_walk(scene, start, target, speed, _monitor().schedule, plane, np.random.default_rng(seed),
                         stop_m=0.15 if kind == "glass" else 0.0)


@pytest.fixture(scope="module")
def glass():
    return _walk("glass")


@pytest.fixture(scope="module")
def door():
    return _walk("open")


def _run(walk, mic=None, sizes=None, rng=None, frames=(), **settings):
    """The monitor (``settings`` its own) over a walk, in blocks; ``frames``: (time, gray, depth,
    intrinsics) shown to it once the block that reaches their time has been processed."""
    mon = _monitor(**settings)
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
    return walk.distance_at(t_s)


def _pulse(walk, a):
    """The pulse that measured an alert's distance."""
    return int(np.argmin(np.abs(walk.pulse_times_s - a.pulse_time_s)))


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
    # Stop comes no later than the block in which the echo of the first pulse sent from within
    # 0.5 m ends (sooner when the walk so far says the wearer is there by now).
    k = int(np.argmax(glass.distance_m < 0.5))
    echo_end = glass.arrival[k] / FS + echo_round_trip_s(glass.distance_m[k]) + mon.schedule.length / FS
    assert end / FS < echo_end + 480 / FS
    # Distances to a centimetre: against the truth at the pulse that measured them.
    err = [abs(a.distance_m - glass.distance_m[_pulse(glass, a)])
           for a in alerts if a.distance_m is not None and a.pulse_time_s is not None]
    assert len(err) > 20 and np.median(err) < 0.01
    assert all(abs(a.latency_s - glass.latency_s) < 1e-4 for a in alerts[20:])  # locked on its round trip
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
    mon = BoundaryMonitor(44100, seed=SEED)
    out = np.zeros(0)
    for n in (100, 441, 1000, 2048, 7):  # block sizes change from call to call
        block = np.zeros(n)
        mon.process(np.full(n, 1e-4), block)
        out = np.r_[out, block]
    sch = mon.schedule
    e0, e1, m = sch.emission(0), sch.emission(1), sch.length
    assert np.allclose(out[e0:e0 + m], sch.probe(0)) and np.allclose(out[e1:e1 + m], sch.probe(1))
    assert np.all(out[:e0] == 0) and np.all(out[e0 + m:e1] == 0)
    # Each pulse plays one of two codes (a chirp up or down), drawn from the seed.
    codes = [sch.code(k) for k in range(400)]
    assert set(codes) == {0, 1} and max(np.bincount(codes)) < 230
    # Pulses leave a period apart plus a dither of up to 5 ms, drawn from the monitor's seed.
    gaps = np.diff([mon.schedule.emission(k) for k in range(200)])
    assert gaps.min() >= mon.period - 0.005 * 44100 and gaps.max() <= mon.period + 0.005 * 44100 and gaps.std() > 20
    other = BoundaryMonitor(44100)  # a fresh seed: another headset's pulses fall elsewhere
    assert [other.schedule.emission(k) for k in range(5)] != [mon.schedule.emission(k) for k in range(5)]
    stereo = np.zeros((256, 2))
    mon.process(np.zeros((256, 2)), stereo)  # (frames, channels) blocks, as sounddevice gives them
    assert np.array_equal(stereo[:, 0], stereo[:, 1])
    # Blocks of 1 to 700 samples (most of them between two pulses: filled with zeros at once)
    # play what the schedule plays at once.
    rng = np.random.default_rng(SEED)
    fresh = BoundaryMonitor(48000, seed=SEED).schedule
    played, start, k = [], 0, 0
    while start < 96000:
        block = np.full((int(rng.integers(1, 700)), 2), np.nan)
        k = fresh.fill(start, block, k)
        played.append(block[:, 0])
        start += len(block)
    assert np.array_equal(np.concatenate(played)[:96000], BoundaryMonitor(48000, seed=SEED).schedule.block(0, 96000))


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


def test_the_rooms_noise_is_the_rooms_whatever_the_headset():
    """record_walk sets the room's noise against the direct sound the reference headset would hear
    (WalkResponses.room_level): a microphone a centimetre from its loudspeaker hears its own
    probe eight times louder than one 7 cm away, and the room no louder."""
    scene, start, target, plane = _geometry("glass")
    start = target + (start - target) * 0.25  # a short walk: 0.6 m from the glass
    sch = _monitor().schedule
    walks = [walk_responses(scene, start, target, 1.5, sch, plane, np.random.default_rng(0), headset=h, lead_s=0.0)
             for h in (Headset(), Headset((0.0, 0.0, 0.01)), Headset((0.10, 0.0, 0.0)),
                       Headset((0.0, -0.15, 0.0), (0.0, 0.0, -1.0), 0.6))]
    direct = [w.direct for w in walks]
    level = [w.room_level for w in walks]
    assert level[0] == direct[0]  # the reference headset: its own direct sound
    assert max(direct[:3]) / min(direct[:3]) > 5 and max(level[:3]) / min(level[:3]) < 1.15
    assert abs(level[3] / (level[0] * 0.6 / scene.emitter_p) - 1) < 0.05  # a cardioid 0.6: its side's gain


def test_a_loudspeaker_facing_away_in_a_quiet_room_is_warned_in_time():
    # The loudspeaker faces back, the microphone 2.4 cm from it: the glass's echo comes back 50 dB
    # under the direct sound, yet in a quiet room 10 to 30 times the envelope's median. A floor
    # beside the direct sound falling only 6 dB per doubling of the lag hid it until 0.31 to 0.36 m
    # (three walks); the transducers' ringing decays far faster than that past one code's length.
    away = Headset((0.013, 0.019, 0.006), (-1.0, 0.0, 0.0), 0.63)
    scene, start, target, plane = _geometry("glass")
    for seed in range(2):
        walk = simulate_walk(scene, start, target, 1.3, _monitor().schedule, plane, np.random.default_rng(seed),
                             headset=away, stop_m=0.15, snr_db=45.0)
        _, alerts, ends = _run(walk, mic_offset_m=away.mic_offset_m)
        a, _, at = _first(alerts, ends, walk, ("caution", "stop"))
        assert a is not None and at >= 0.8, at


def test_no_echo_at_all_is_clear_and_says_so():
    # The loudspeaker heard 0.1 s later, nothing echoing: locked, clear, "no_echo".
    mon = _monitor()
    rng = np.random.default_rng(0)
    heard = np.zeros(int(0.1 * FS))
    for _ in range(100):
        out = np.zeros(480)
        a = mon.process(0.3 * heard[:480] + 1e-4 * rng.standard_normal(480), out)
        heard = np.r_[heard[480:], out]
    assert a.level == "clear" and a.distance_m is None and "no_echo" in a.flags
    assert abs(a.latency_s - 0.1 + 0.07 / 343) < 1e-4  # the mic offset's flight taken out
    for _ in range(10):
        a = mon.process(np.zeros(480))  # silence: a dropout, not a crash
    assert a.level == "clear"


def test_a_muted_loudspeaker_says_so_within_a_second_and_never_alarms():
    mon = _monitor()
    rng = np.random.default_rng(0)
    flags = []
    for i in range(150):
        a = mon.process(1e-3 * rng.standard_normal(480), np.zeros(480))  # the probe never reaches the mic
        flags.append(a.flags)
        assert a.level == "clear" and a.latency_s is None
    assert all("unlocked" in f for f in flags)
    assert "no_direct_sound" in flags[105] and "no_direct_sound" not in flags[50]


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


# -- The audio stream's round trip, other headsets (issue 25) -----------------------------------------------

def test_an_echo_louder_than_the_direct_sound_is_not_taken_for_a_step():
    # Seed 30000's room 13 (latency 0-30 ms): the microphone 8 cm behind a cardioid loudspeaker
    # hears its direct sound faintly, and a mirror 0.2 m ahead echoes as loud, 55 samples later,
    # within the lock's guard. The lock took the louder peak for a step, the next pulse's direct
    # sound where due set it back, and the monitor heard the same two pulses again and again: the
    # callback never returned. The direct sound where it is due is taken before a louder echo, and
    # a replay never starts where the last one did.
    import signal

    behind = Headset((-0.079, 0.032, 0.044), speaker_p=0.5)
    scene, start, target, plane = _geometry("glass")
    walk = simulate_walk(scene, start, target, 1.0, _monitor().schedule, plane, np.random.default_rng(0),
                         headset=behind, stop_m=0.15)

    def hung(*_):
        raise TimeoutError("the monitor never returned")

    previous = signal.signal(signal.SIGALRM, hung)
    signal.alarm(60)
    try:
        _, alerts, ends = _run(walk, mic_offset_m=behind.mic_offset_m)
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, previous)
    locked = [a.latency_s for a in alerts if a.latency_s is not None]
    assert alerts[-1].latency_s is not None and max(locked) - min(locked) < 1e-4  # locked to the end, unmoved
    assert _first(alerts, ends, walk, ("caution", "stop"))[2] >= 0.5


@pytest.fixture(scope="module")
def glass_room():
    """The glass walk's room, simulated once, to be heard through many streams."""
    scene, start, target, plane = _geometry("glass")
    return walk_responses(scene, start, target, 1.2, _monitor().schedule, plane, np.random.default_rng(5))


def _judged(walk, alerts, ends):
    """Caution's true distance, the distance errors against each measuring pulse, the latencies."""
    _, _, at = _first(alerts, ends, walk, ("caution", "stop"))
    err = [abs(a.distance_m - walk.distance_m[_pulse(walk, a)]) for a in alerts if a.distance_m is not None]
    return at, np.median(err), [a.latency_s for a in alerts]


@pytest.mark.parametrize("latency_s", [0.0, 0.073, 0.231])
def test_the_monitor_finds_its_round_trip_however_long(glass_room, latency_s):
    # Up to six periods of 40 ms: the dithered pulses tell which pulse an arrival is.
    walk = record_walk(glass_room, np.random.default_rng(1), link=AudioLink(latency_s, output_share=0.3))
    mon, alerts, ends = _run(walk)
    at, err, latencies = _judged(walk, alerts, ends)
    assert at is not None and at >= 0.5 and err < 0.01
    locked = [lat for lat in latencies if lat is not None]
    assert latencies.index(locked[0]) * 0.01 < latency_s + 0.2  # locked within three pulses of hearing one
    assert all(abs(lat - latency_s) < 1e-4 for lat in locked)
    assert all(a.level == "clear" for a in alerts if a.latency_s is None)  # no alarm unlocked


def test_the_search_locks_on_the_direct_sound_not_on_its_sidelobes(glass_room):
    # A round trip just over two periods: when the search looked, the direct sound had come after
    # two pulses, not yet after the third, while delays 150 samples short of it, in the probe's
    # sidelobes (a third of its peak), had come after three. It locked there, some 17 samples
    # short, and the echoes timed off it made a stop on a door walk (seed 5000's room 7, drift).
    missed = []
    for i, latency_s in enumerate(np.arange(0.0836, 0.0853, 0.0002)):
        walk = record_walk(glass_room, np.random.default_rng(43 + i), link=AudioLink(latency_s, output_share=0.6,
                                                                                      drift_ppm=-95))
        mon, alerts, _ = _run(dataclasses.replace(walk, mic=walk.mic[:int(0.8 * FS)]))
        locked = [a.latency_s for a in alerts if a.latency_s is not None]
        if not locked or abs(locked[0] - walk.latency_s) > 2e-4:
            missed.append((latency_s, locked[:1]))
    assert not missed


@pytest.mark.parametrize("latency_s", [0.0852, 0.090])
def test_pulses_whose_dithers_happen_alike_are_told_apart_by_their_codes(latency_s):
    # This schedule's first pulses leave 141, 0, 156, 15 and 171 samples into their periods (44.1
    # kHz): pulse k + 2 follows pulse k as closely as k + 3 follows k + 1, and the direct sounds of
    # pulses 0 to 2 arrive, all three, where pulses 2 to 4 would have theirs two periods sooner.
    # By the dithers alone that shorter round trip was locked on (seed 34000's room 6); the codes
    # (up and down chirps) tell the pulses apart.
    mon = BoundaryMonitor(44100, seed=4265929704)
    sch, rng = mon.schedule, np.random.default_rng(0)
    x = 0.01 * rng.standard_normal(int(0.8 * 44100) + 8192)
    for k in range(18):  # (0.8 s)
        at = int(sch.emission(k) + latency_s * 44100)
        x[at:at + sch.length] += 0.5 * sch.probe(k) / np.abs(sch.probe(k)).max()
    x = x[:int(0.8 * 44100)]
    locked = [a.latency_s for a in (mon.process(x[i:i + 480], np.zeros(len(x[i:i + 480]))) for i in range(0, len(x), 480))
              if a.latency_s is not None]
    assert locked and all(abs(lat + 0.07 / SPEED_OF_SOUND - latency_s) < 1e-4 for lat in locked)


def test_a_round_trip_that_steps_after_an_underrun_is_followed(glass_room):
    # An underrun adds a 10 ms block to the round trip, an overrun later takes 21 ms off.
    link = AudioLink(0.04, steps=((0.9, 480), (1.5, -1024)), drift_ppm=80)
    walk = record_walk(glass_room, np.random.default_rng(2), link=link)
    mon, alerts, ends = _run(walk, sizes=(16, 4097), rng=np.random.default_rng(3))  # blocks of 16 to 4096
    at, err, latencies = _judged(walk, alerts, ends)
    assert at is not None and at >= 0.5 and err < 0.01
    final = (0.04 * FS + 480 - 1024) / FS
    assert abs(latencies[-1] - final) < 0.0002  # (the drift: 80 ppm of the walk's 2 s)
    first = next(i for i, lat in enumerate(latencies) if lat is not None)
    assert None not in latencies[first:]  # each step taken as a step: the lock is never lost
    assert all(a.level == "clear" for a in alerts if a.latency_s is None)
    with pytest.raises(VrechoError, match="below zero"):  # (a simulated link, too, keeps to what hardware can do)
        AudioLink(0.01, steps=((0.5, -1024),)).arrival(np.arange(0, 48000, 1920), FS)


def test_a_walk_is_simulated_alike_whatever_pyroomacoustics_generator_held():
    # pyroomacoustics' inside test draws a reference point from its own generator, and may refuse
    # a point it cannot place: the walk (and each other headset) seeds that generator, so a
    # benchmark's walk is simulated, or refused, the same in every run and process.
    import pyroomacoustics as pra

    scene, start, target, plane = _geometry("glass")
    start = target - 0.7 * (target - start) / np.linalg.norm(target - start)  # (a short walk: 10 pulses)
    held = []
    for s in (1, 2):
        pra.random.seed(s)
        room = walk_responses(scene, start, target, 2.0, _monitor().schedule, plane, np.random.default_rng(5))
        after_walk = pra.random.get_rng().random()
        other_headsets(room, 1, np.random.default_rng(7))
        held.append((after_walk, pra.random.get_rng().random(), len(room.responses)))
    assert held[0] == held[1]


def test_a_step_of_about_a_period_is_found_though_the_next_pulse_lands_where_one_was_due(glass_room):
    # Seed 24000's room 2 (another simulator): an overrun took 2048 samples (43 ms at 48 kHz) off
    # the round trip, and every other pulse the next pulse's direct sound (the same code) fell
    # where the missing one was due. Taken as "not trusted", it made the lock forget the pulses
    # it had missed, and seven pulses went by before the step was found. Each step here is found
    # within four pulses (the round trip's 17 ms and a window's arrival included).
    new = 0.06 - 2048 / FS
    for at in (0.7, 1.3, 1.5):
        walk = record_walk(glass_room, np.random.default_rng(2), link=AudioLink(0.06, steps=((at, -2048),)))
        _, alerts, ends = _run(walk)
        found = next(e / FS for e, a in zip(ends, alerts) if e / FS > at and a.latency_s is not None
                     and abs(a.latency_s - new) < 2e-4)
        assert found - at < 0.17


def test_the_pulses_a_step_hid_are_heard_once_it_is_found(glass_room):
    # A step of the round trip is found from two pulses whose direct sounds were not where they
    # were due; their echoes were dropped, and a wall's young track, two pulses short, lost its
    # surface (seed 23000's room 12, all at once). Once the step is found they are heard again
    # with the new round trip: no pulse of the walk goes uncommitted, whichever way it steps.
    # A small step (1 ms, within the lock's guard) is trusted when seen twice, and heard from the first.
    for at, step in ((0.7, -2048), (1.0, 1024), (1.2, 512), (1.3, 48), (0.9, -40)):
        walk = record_walk(glass_room, np.random.default_rng(2), link=AudioLink(0.06, steps=((at, step),)))
        mon = _monitor()
        heard, commit = [], mon._commit
        mon._commit = lambda t, *args: (heard.append(t), commit(t, *args))
        for i in range(0, len(walk.mic), 480):
            mon.process(walk.mic[i:i + 480], np.zeros(len(walk.mic[i:i + 480])))
        emitted = [mon.schedule.emission(k) / FS for k in range(100)]
        assert [t for t in emitted if 0.3 < t < len(walk.mic) / FS - 0.1 and t not in heard] == []


@pytest.fixture(scope="module")
def door_room():
    scene, start, target, plane = _geometry("open")
    return walk_responses(scene, start, target, 1.3, _monitor().schedule, plane, np.random.default_rng(6), stop_m=0.0)


def test_other_headsets_pings_are_never_taken_for_echoes(glass_room, door_room):
    # Two more headsets in the room running the same call (their own seeds): nothing through the
    # door, and the glass still warned in time.
    for room, closed in ((door_room, False), (glass_room, True)):
        others = other_headsets(room, 2, np.random.default_rng(7))
        walk = record_walk(room, np.random.default_rng(8), link=AudioLink(0.03), others=others)
        _, alerts, ends = _run(walk)
        if closed:
            at, err, _ = _judged(walk, alerts, ends)
            assert at is not None and at >= 0.5 and err < 0.01
        else:
            assert all(a.level == "clear" for a in alerts)


def test_a_surfaces_echoes_taken_by_a_track_it_crosses_still_start_its_own():
    # A surface heard from 1.7 m on, nearing at 1.9 m/s, crosses the range of a track whose echoes
    # scattered (a 12 cm gate): that track takes its echoes, far off its own line. They still start
    # the surface's track, at 1.55 m (seed 28000's room 3 wall; taken, they started none until 1.17 m).
    mon = _monitor()
    rng = np.random.default_rng(0)
    found = None
    for k in range(40):
        echoes = [(2.6 + rng.normal(0, 0.001), 0.02)]
        if k < 20:
            echoes.append((1.50 + rng.normal(0, 0.03), 0.01))
        d = 1.70 - 1.9 * 0.04 * (k - 20)
        if k >= 20:
            echoes.append((d + rng.normal(0, 0.001), 0.01))
        mon._commit(0.04 * k, sorted(echoes))
        if found is None and any(tr.speed is not None and abs(tr.speed + 1.9) < 0.2 for tr in mon._tracks):
            found = d
    assert found is not None and found > 1.5


def test_people_walking_past_are_heard_where_they_are_and_raise_no_alert(glass_room, door_room):
    # A person's body echoes where geometry puts it (loudspeaker to body to microphone), only while
    # they are in the room; people walking past (never within 0.6 m) raise nothing through the
    # door, and the glass is still warned in time.
    k = 30
    head, mic = door_room.position_m[k], door_room.mic_m[k]
    t = door_room.written[k] / FS
    side = np.cross([0.0, 0.0, 1.0], door_room.forward[k])[:2]
    person = Passerby(tuple(head[:2] + 1.2 * door_room.forward[k][:2] - 1.5 * t * side), tuple(1.5 * side), 0.2,
                      1.8, 0.7, (t - 0.5, t + 0.5))  # across the way 1.2 m ahead, level with the wearer at pulse k
    heard = with_passersby(door_room, [person])
    echo = heard.responses[k] - door_room.responses[k]
    centre = np.r_[person.at(t), 0.5 * (head[2] + mic[2])]
    point = centre + 0.2 * (0.5 * (head + mic) - centre) / np.linalg.norm(0.5 * (head + mic) - centre)
    path = np.linalg.norm(point - head) + np.linalg.norm(point - mic)
    assert abs(np.argmax(np.abs(echo)) - path / 343.0 * FS) <= 1
    assert 0.02 / path < np.abs(echo).max() < 0.5 / path  # under half a plane's echo at that path (1 / path)
    assert np.array_equal(heard.responses[0], door_room.responses[0]) and door_room.responses[k] is not heard.responses[k]
    for room, closed in ((door_room, False), (glass_room, True)):
        people = passersby(room, 2, np.random.default_rng(3))
        assert len(people) == 2
        for p in people:
            times = room.written / FS
            on = (times >= p.present_s[0]) & (times <= p.present_s[1])
            gaps = np.linalg.norm(np.array([p.at(x) for x in times]) - room.position_m[:, :2], axis=1) - p.radius_m
            assert gaps.min() >= 0.6 and times[on][-1] - times[on][0] >= 1.0  # (on their path, in the room or not)
        walk = record_walk(with_passersby(room, people), np.random.default_rng(4), link=AudioLink(0.03))
        _, alerts, ends = _run(walk)
        if closed:
            at, err, _ = _judged(walk, alerts, ends)
            assert at is not None and at >= 0.5 and err < 0.01
        else:
            assert all(a.level == "clear" for a in alerts)


def test_the_callback_is_sounddevices_and_on_alert_hears_each_change(glass_room):
    import sounddevice as sd  # its CallbackFlags, as a stream passes them
    walk = record_walk(glass_room, np.random.default_rng(1), link=AudioLink(0.02))
    heard = []
    mon = _monitor(on_alert=heard.append)
    played = []
    for i in range(0, len(walk.mic), 256):
        block = walk.mic[i:i + 256, None].astype(np.float32)  # (frames, channels), as sounddevice gives them
        out = np.zeros((len(block), 2), np.float32)
        mon.callback(block, out, len(block), None, sd.CallbackFlags())
        played.append(out)
    levels = [a.level for a in heard]
    assert levels[:2] == ["caution", "stop"] and all(a != b for a, b in zip(levels, levels[1:]))
    assert mon.alert.level == "stop" and heard[-1] is not None
    played = np.concatenate(played)
    assert np.array_equal(played[:, 0], played[:, 1])
    e = mon.schedule.emission(3)
    assert np.allclose(played[e:e + mon.schedule.length, 0], mon.schedule.probe(3), atol=1e-6)


def test_a_surface_is_found_among_dense_stray_peaks():
    # Three pulses, each with 30 stray peaks over the range (two other headsets' pings and their
    # reverberation) and one surface's echo nearing at 1.3 m/s: the surface starts a track with
    # its speed from its three echoes nearly always (a stray line as straight may take one of
    # them: the next pulses find it again), and the stray peaks start a few lines a pulse.
    from vrecho.headset.tracks import initiate

    rng = np.random.default_rng(0)
    times = [0.0, 0.041, 0.083]
    found, stray_lines = 0, 0
    for _ in range(100):
        pulses = []
        for t in times:
            stray = [(float(d), float(a)) for d, a in zip(rng.uniform(0.12, 4.0, 30), rng.exponential(0.01, 30))]
            echo = (1.5 - 1.3 * t + float(rng.normal(0, 0.001)), 0.01)
            pulses.append((t, sorted(stray + [echo]), 31 / 3.88, 0.01))
        tracks = initiate(pulses)
        surface = [tr for tr in tracks if abs(tr.dists[-1] - (1.5 - 1.3 * times[-1])) < 0.003
                   and abs(tr.speed + 1.3) < 0.15 and len(tr.times) == 3]
        found += bool(surface)
        stray_lines += len(tracks) - len(surface)
        assert sum(len(e) for _, e, _, _ in pulses) <= 93 - 2 * len(tracks)  # the echoes taken are no longer free
    assert found >= 90 and stray_lines / 100 < 5.0


def test_a_track_follows_a_wearer_speeding_up():
    # A wearer speeding up at 3 m/s^2 from 0.5 to 2 m/s toward a wall, its echo heard every other
    # pulse meanwhile, among 8 stray peaks a metre: the prediction lags the pace; the filter
    # widens its spread for it (a young track, missed pulses) instead of scoring the echoes as
    # stray. (The fixed alpha-beta filter, weighing every echo against 1 cm, had the track at
    # the score's floor, dropped as stray, and unconfirmed after 0.4 s of steady walking.)
    from vrecho.headset.tracks import Track

    rng = np.random.default_rng(0)

    def dist(t):
        return 2.8 - 0.5 * t - 1.5 * min(t, 0.5) ** 2 - 1.5 * max(t - 0.5, 0.0)

    tr, stray = Track(), []
    for k in range(23):
        t = 0.04 * k
        if 3 <= k <= 12 and k % 2:
            tr.missed()
        else:
            tr.update(t, dist(t) + float(rng.normal(0, 0.002)), 0.012, clutter_per_m=8.0)
        stray.append(tr.stray)
    assert not any(stray) and tr.confirmed and abs(tr.speed + 2.0) < 0.1


def test_a_surface_missed_twice_while_the_wearer_speeds_up_keeps_its_track():
    # A wall 1.9 m off; the wearer starts walking at 0.4 s, speeding up at 3 m/s^2 to 2 m/s, and
    # two pulses hear no echo of it meanwhile (a noise burst); stray peaks scatter about two spots
    # its echo will cross. The prediction lags the pace by some 5 cm after the gap, as the filter's
    # spread says it may: the gate is that spread's, not the steady walk's, and the track keeps
    # the wall's echoes from its first to its last. (A fixed 5 cm gate lost them after the gap on 6
    # of 8 walks, and a new track was confirmed only 0.2 m on: seed 38000's room 16 mirror,
    # cautioned at 0.30 m.)
    def dist(t):
        u = max(t - 0.4, 0.0)
        return 1.9 - 1.5 * min(u, 2 / 3) ** 2 - 2.0 * max(u - 2 / 3, 0.0)

    for seed in range(8):
        mon, rng = _monitor(), np.random.default_rng(seed)
        for k in range(40):
            t = 0.04 * k + float(rng.uniform(0, 0.005))
            d = dist(t)
            echoes = [(2.3 + float(rng.normal(0, 0.001)), 0.02)]
            if k not in (14, 15):
                echoes.append((d + float(rng.normal(0, 0.001)), 0.03))
            echoes += [(c + float(rng.normal(0, 0.008)), 0.015) for c in (1.72, 1.33) if d > c + 0.03]
            mon._commit(t, sorted(echoes))
        own = [tr for tr in mon._tracks if abs(tr.d_hat - d) < 0.01]
        assert len(own) == 1 and own[0].times[0] < 0.01 and own[0].confirmed, (seed, own)


def test_a_side_wall_converged_on_through_a_door_is_not_ahead():
    # A door near a corner, walked through at 8 degrees to its normal at 2 m/s: the wall beside
    # it comes within 0.7 m, closing at 0.27 m/s, a seventh of the wearer's pace (the wall
    # behind recedes at all of it). Its time to contact stays over 2.5 s: nothing to warn of.
    # (By its distance alone, under a metre and nearing, it cautioned at 0.7 m.)
    scene = small_room()
    d = scene.discontinuities[2]
    scene.discontinuities[2] = dataclasses.replace(d, center_u_m=3.6, center_z_m=1.05, height_m=2.1, width_m=1.0)
    origin, u, normal = scene.room.wall_frame(2)
    start, goal = np.array([1.0, 1.0, 1.55]), np.array([0.65, 3.55, 1.55])
    walk = simulate_walk(scene, start, goal, 2.0, _monitor().schedule, (origin, normal), np.random.default_rng(2),
                         stop_m=0.0)
    _, alerts, _ = _run(walk)
    assert all(a.level == "clear" for a in alerts)


def test_a_slow_walk_toward_a_wall_is_told_in_the_way_before_it_is_near():
    # A wearer at 0.55 m/s toward a wall, its echoes scattered 2.5 mm about the truth (noise,
    # another echo's sidelobes): 0.6 s of history is 0.33 m walked, over which a point passed 0.4 m
    # off bends the echoes' line by some 2 mm at a metre: the fit cannot tell. Its spans are
    # stretched for a slow track (Track.in_the_way): the wall is in the way by 0.8 m on every walk,
    # and never read as passed by within 1.2 m; a point passed 0.7 m off is never in the way. (The
    # fixed spans: in the way at 0.53 to 0.66 m, and on 6 of the 8 walks read as passed by as near
    # as 0.8 to 1.2 m; seed 39000's all at once room 13 glass and another simulator's room 7 wall
    # were cautioned at under 0.5 m.)
    from vrecho.headset.tracks import Track

    for seed in range(8):
        rng = np.random.default_rng(seed)
        for a, want in ((0.0, True), (0.7, False)):
            tr, told = Track(), []
            for k in range(80):
                t = 0.04 * k + float(rng.uniform(0, 0.005))
                x = 2.2 - 0.55 * t
                tr.update(t, (x * x + a * a) ** 0.5 + float(rng.normal(0, 0.0025)), 0.02)
                if x > 0.8 and len(tr.times) >= 8:
                    told.append((x, tr.in_the_way(0.4)))
            assert any(way for _, way in told) == want, (seed, a)
            assert a > 0 or all(way is not False for x, way in told if x < 1.2), (seed, told)


def test_the_corner_beside_a_door_nearing_fast_is_passed_by():
    # A door 0.26 m from the room's corner, walked through at 1.8 m/s from a standstill, 0.3 to
    # 0.55 m from the side wall: the corner of the door's wall with the side wall echoes as a point
    # passed 0.5 m off, nearing at 0.7 to 0.85 of the pace, steadily, under a metre away, before
    # the closest-approach fit can tell (seed 17000's room 8). Where the wall behind is heard
    # receding at the pace, the point lies d sqrt(1 - (c/v)^2) off the way: no caution. (Without
    # that, the looming caution took it for a wall ahead on seven walks of these eight.) Where no
    # wall behind gives the pace, the looming caution stays (a wall ahead must not wait for it).
    scene = small_room()
    width = 1.012
    scene.discontinuities[2] = dataclasses.replace(scene.discontinuities[2], center_u_m=4.2 - 0.256 - width / 2,
                                                   center_z_m=1.063, height_m=2.127, width_m=width)
    origin, u, normal = scene.room.wall_frame(2)
    start = np.array([0.3, 1.9, 1.5])
    cautioned = 0
    for seed in range(4, 12):
        walk = simulate_walk(scene, start, start + [0.251, 0.968, 0.0], 1.8, _monitor().schedule, (origin, normal),
                             np.random.default_rng(seed), stop_m=0.0)
        _, alerts, _ = _run(walk)
        cautioned += any(a.level != "clear" for a in alerts)
    assert cautioned <= 1


def test_only_a_surface_beyond_an_alarms_doubt_alerts():
    # Where other headsets' pings crowd the range (15 peaks a metre near the head, the pulse's
    # mean 5), a line of stray peaks can run from 1.3 to 0.2 m within a second and stay confirmed
    # at a score of 5 to 7 (seed 17000's room 5 and 18000's room 7, all at once: stops at 1.04 and
    # 0.89 s while the wearer stood). In the way by the fit, such a track alerts only from a score
    # of 8; a surface's echo scores 20 to 30.
    from vrecho.headset.tracks import CONFIRMED, Track

    mon = _monitor()
    tr = Track()
    for k in range(12):
        tr.update(0.04 * k, 1.0 - 1.3 * 0.04 * k, 0.02)
    tr.ahead, tr.approached_at = True, tr.times[-1]
    mon._tracks, mon._now = [tr], int((tr.times[-1] + 0.05) * FS)
    levels = []
    for score in (CONFIRMED + 1.0, 7.5, 8.5, 25.0):
        tr.score = score
        mon._judge(None, tr.times[-1] + 0.04)
        levels.append(mon._level)
    assert tr.confirmed and levels == ["clear", "clear", "stop", "stop"]


def test_a_weak_track_whose_echoes_scatter_off_a_line_raises_no_alert():
    # Seed 21000's room 14 (other headsets, a walk past a wall): a track of the other headset's
    # pings, 0.52 to 0.23 m off, nearing unevenly (0.7 to 4.5 cm a pulse), scored 9 and stopped
    # the wearer 0.86 s into the walk. A surface's echoes, walked toward, lie on a line within a
    # millimetre or so: under a score of 15 a track alerts only on one within 3 mm.
    times = [0.321, 0.361, 0.402, 0.441, 0.481, 0.602, 0.642, 0.682, 0.722, 0.801]
    uneven = [0.519, 0.5, 0.472, 0.427, 0.42, 0.353, 0.318, 0.31, 0.273, 0.226]
    steady = list(np.interp(times, [times[0], times[-1]], [uneven[0], uneven[-1]]))
    levels = [_level_alone(_track(times, dists, score)) for dists, score in ((uneven, 9.0), (steady, 9.0), (uneven, 20.0))]
    assert levels == ["clear", "stop", "stop"]


def test_sparse_or_scattered_tracks_of_other_headsets_pings_raise_no_alert():
    # Seed 21000's room 16 (other headsets, a door walk at 0.7 m/s): a track of pings taken one
    # pulse in three, on a line within 2.1 mm over a second, scored 12.6 and cautioned 1.70 s in;
    # later one of pings loud enough to score 16 on their strength, 0.17 to 0.39 m off in uneven
    # steps (18 mm off a line), stopped the wearer. A surface within reach of an alert is heard
    # in most pulses, its echoes on a line within a few millimetres.
    sparse_t = [0.522, 0.563, 0.601, 0.64, 0.681, 0.722, 0.923, 1.24, 1.405, 1.484, 1.604, 1.643]
    sparse_d = [1.036, 1.054, 1.017, 1.042, 1.004, 0.929, 0.784, 0.533, 0.388, 0.326, 0.224, 0.196]
    loud_t = [2.121, 2.202, 2.361, 2.403, 2.484, 2.602, 2.761, 2.803, 2.882, 2.923, 3.004, 3.082]
    loud_d = [0.243, 0.167, 0.205, 0.219, 0.269, 0.341, 0.393, 0.344, 0.318, 0.296, 0.269, 0.257]
    assert _level_alone(_track(sparse_t, sparse_d, 12.6)) == "clear"
    assert _level_alone(_track(loud_t, loud_d, 16.0)) == "clear"
    # a surface's line as near, heard every pulse, at either score: a stop
    assert _level_alone(_line_track(0.196 + 0.8 * 0.44, -0.8, 12, 12.6)) == "stop"
    assert _level_alone(_line_track(0.257 + 0.2 * 0.44, -0.2, 12, 16.0)) == "stop"


def test_combs_of_another_headsets_pings_confirm_no_surface():
    # Where another headset's ping overlaps a pulse's window, the envelope holds a comb of peaks
    # some 3 cm apart, and any line through it finds one within 1.5 cm: seed 40000's other
    # headsets, room 15, the floor's track followed such combs down from 1.35 to 0.49 m at the
    # wearer's pace and cautioned 1.7 m before an open door. Weighed at the pulse's mean density of
    # peaks, tracks through combs in seven pulses of ten confirmed in 4 of 8 walks (one scored
    # 15.5); weighed at the density around each echo, none does.
    from vrecho.headset.tracks import CONFIRMED

    for seed in range(8):
        mon, rng = _monitor(), np.random.default_rng(seed)
        for k in range(50):
            echoes = [(2.3 + float(rng.normal(0, 0.001)), 0.02)]  # a wall
            if rng.random() < 0.7:
                comb = np.arange(0.3 + rng.uniform(0, 0.03), 1.6, 0.03)
                echoes += list(zip((comb + rng.normal(0, 0.001, len(comb))).tolist(),
                                   rng.uniform(0.02, 0.03, len(comb)).tolist()))
            mon._commit(0.04 * k + float(rng.uniform(0, 0.005)), sorted(echoes))
            assert all(tr.score < CONFIRMED for tr in mon._tracks if tr.d_hat < 1.7), (seed, k)


def _theil_sen(t, d, a=0.0):
    """The median and newest absolute residual about the Theil-Sen line of d - a (t - mean t)^2 / 2, and its slope."""
    y = d - 0.5 * a * (t - t.mean()) ** 2
    i, j = np.triu_indices(len(t), 1)
    slope = np.median((y[j] - y[i]) / (t[j] - t[i]))
    r = y - slope * t
    r = np.abs(r - np.median(r))
    return np.median(r), r[-1], slope


def test_the_line_a_track_is_judged_by_is_theil_sens():
    # Track.straight (compiled): the median absolute residual about the line of the median pairwise
    # slope, as NumPy reckons it, and the newest echo's own; an outlier moves the line not at all.
    # Where the line leaves a millimetre or more, the curve of an approach speeding up (by up to 3
    # m/s^2, in steps of 0.5) that leaves the least, if under 1.5 mm. Track.steady_speed: the line's slope.
    rng = np.random.default_rng(3)
    for n in (3, 6, 8, 11):
        times = np.sort(rng.uniform(0.0, 0.5, n))
        dists = 2.0 - 1.2 * times + rng.normal(0.0, 0.002, n)
        tr = _track(times, dists, 0.0)
        t, d = times[-8:], dists[-8:]
        line = _theil_sen(t, d)
        curves = [] if line[0] < 0.001 else [_theil_sen(t, d, -a)[:2] for a in np.arange(0.5, 3.01, 0.5)]
        tried = [line[:2]] + [c for c in curves if c[0] < 0.0015]
        assert tr.straight(8) == pytest.approx(min(tried, key=lambda x: x[0]), abs=1e-12)
        assert tr.steady_speed(8) == pytest.approx(line[2], abs=1e-12)
    line = 2.0 - 1.2 * 0.04 * np.arange(8)
    assert _line_track(2.0, -1.2, 8, 0.0).straight(8) == pytest.approx((0.0, 0.0), abs=1e-9)
    bent = _track(0.04 * np.arange(8), np.r_[line[:-1], line[-1] - 0.2], 0.0).straight(8)
    assert bent[0] < 1e-9 and bent[1] == pytest.approx(0.2)


def test_a_wearer_setting_off_near_a_surface_is_cautioned_in_time():
    # Seed 53000's room 11 (every row): a wearer standing 1.4 m from a mirror sets off and is at
    # 2 m/s within 0.6 s. Over eight pulses the echoes bent 8 to 10 mm off a straight line, the
    # track was not "straight" (Track.alerting, the looming rule) while it sped up, and the
    # caution came at 0.38 m. About the curve of a steady acceleration they lie within a
    # millimetre: straight, and a caution before the fit, 0.9 m off.
    times = 0.037 * np.arange(16)  # (the last echo 0.94 m off, nearing at 1.7 m/s)
    dists = 1.4 - 0.5 * 3.0 * times ** 2 + np.random.default_rng(0).normal(0.0, 0.0003, 16)
    tr = _track(times, dists, 25.0)
    assert _theil_sen(times[-8:], dists[-8:])[0] > 0.005  # off the line
    assert tr.straight(8)[0] < 0.001 and tr.alerting
    mon = _monitor()
    tr.approached_at = tr.times[-1]
    mon._tracks, mon._now, mon._pace = [tr], int((tr.times[-1] + 0.02) * FS), 1.3
    mon._behind = 1.3  # (the walls behind recede as fast)
    mon._judge(None, tr.times[-1] + 0.04)
    assert tr.ahead is None and mon._level == "caution"


def _track(times, dists, score: float):
    """A track of those echoes (seconds, metres), of that score."""
    from vrecho.headset.tracks import Track

    tr = Track()
    for t, d in zip(times, dists):
        tr.update(t, d, 0.02)
    tr.score = score
    return tr


def _line_track(d0: float, speed: float, n: int, score: float):
    """A track of ``n`` echoes, one a pulse, from ``d0`` m at ``speed`` m/s, of that score."""
    times = 0.04 * np.arange(n)
    return _track(times, d0 + speed * times, score)


def _level_alone(tr, level: str = "clear") -> str:
    """The level a fresh monitor at ``level`` calls for ``tr`` alone, in the way by the fit and
    approached at its last echo, judged 50 ms after it (the next pulse emitted 40 ms after)."""
    mon = _monitor()
    tr.ahead, tr.approached_at = True, tr.times[-1]
    mon._tracks, mon._now, mon._level = [tr], int((tr.times[-1] + 0.05) * FS), level
    mon._judge(None, tr.times[-1] + 0.04)
    return mon._level


def test_a_receding_surface_starts_no_alert():
    # Seed 19000's room 17 (all at once, a walk past a wall): a track of stray peaks 0.23 to 0.27 m
    # off, receding at 0.17 m/s, in the way by the fit and just over the alert's score, stopped the
    # wearer. A surface that recedes has passed its closest approach: it starts no alert; one that
    # stands or nears at that distance stops, and a stop already called holds while it recedes.
    levels = [_level_alone(_line_track(0.27 - speed * 0.44, speed, 12, 8.3), level)
              for speed, level in ((0.17, "clear"), (0.0, "clear"), (-0.5, "clear"), (0.17, "stop"))]
    assert levels == ["clear", "stop", "stop", "stop"]


def test_a_phantom_speed_behind_does_not_hold_back_a_wall_ahead():
    # Seed 5000's room 7 (block 64): a wall nearing at 1.75 m/s, 0.64 m off, steadily, not yet
    # fitted, while a track that took another surface's echoes after missed pulses read 2.3 m/s
    # receding (the wearer walked at 1.76). Taken for the wearer's pace, it put the wall 0.41 m off
    # the way and the caution came at 0.46 m. No wearer walks faster than 2 m/s: caution now.
    mon = _monitor()
    wall = _line_track(0.64 + 1.75 * 0.44, -1.75, 12, 25.0)
    wall.approached_at = wall.times[-1]
    behind = _line_track(2.1 - 2.3 * 0.44, 2.3, 12, 20.0)
    mon._tracks, mon._now = [wall, behind], int((wall.times[-1] + 0.02) * FS)
    mon._judge(None, wall.times[-1] + 0.04)
    assert wall.ahead is None and max(wall.straight(8)) < 0.005 and mon._level == "caution"
    # Nor does it make a wall in the way read as one met aside (nearing at under half the pace):
    # 2 m off at 1.2 m/s, 1.67 s from contact, it cautions by time (2 s) beside a phantom at 3 m/s.
    wall = _line_track(2.0 + 1.2 * 0.44, -1.2, 12, 25.0)
    wall.ahead, wall.approached_at = True, wall.times[-1]
    behind = _line_track(2.1 - 3.0 * 0.44, 3.0, 12, 20.0)
    mon = _monitor()
    mon._tracks, mon._now = [wall, behind], int((wall.times[-1] + 0.02) * FS)
    mon._judge(None, wall.times[-1] + 0.04)
    assert mon._level == "caution" and mon._pace == 2.0


def test_a_wall_nearing_fast_on_a_long_round_trip_is_cautioned_where_the_wearer_is():
    # A round trip of 250 ms (an ordinary desktop's): the echo heard now left the wall 0.375 m ago
    # at 1.5 m/s. A wall nearing steadily, not yet fitted, whose last echo read 1.2 m, is by now
    # some 0.83 m off, 0.55 s from contact: caution, where reading the echo's own 1.2 m waited a
    # pulse or more (seed 26000's room 3, all at once: 0.48 -> 0.87 m before the wall). With no
    # round trip (the echo as fresh as it is heard), the same track waits.
    levels = []
    for latency_s in (0.25, None):
        mon = _monitor()
        wall = _line_track(1.2 + 1.5 * 0.44, -1.5, 12, 25.0)
        if latency_s is not None:
            mon._lock.delay = latency_s * FS + mon._mic[0] / SPEED_OF_SOUND * FS
        mon._tracks, mon._now = [wall], int((wall.times[-1] + 0.02) * FS)
        mon._judge(None, wall.times[-1] + 0.04)
        levels.append((wall.ahead, mon.latency_s is not None and round(mon.latency_s, 3), mon._level))
    assert levels == [(None, 0.25, "caution"), (None, False, "clear")]


def _among_pings(own: float, ping: float, n_pings: int, seconds: float, seed: int) -> np.ndarray:
    """A stream of the monitor's own pulses (peak ``own``, 5000 samples round trip; 0: muted) among
    ``n_pings`` other headsets' pings (either code, peak up to ``ping``) at random times."""
    rng = np.random.default_rng(seed)
    sch = _monitor().schedule
    n = int(seconds * FS)
    x = 1e-4 * rng.standard_normal(n)
    for k in range(int(seconds / 0.04)):
        e = sch.emission(k) + 5000
        if own and e + sch.length < n:
            x[e:e + sch.length] += own * sch.probe(k)
    for _ in range(n_pings):
        e = int(rng.integers(0, n - sch.length))
        x[e:e + sch.length] += ping * rng.uniform(0.3, 1.0) * sch.probes[int(rng.integers(2))]
    return x


def test_the_round_trip_is_found_among_many_pings_and_never_without_its_own():
    # Other headsets' pings, 600 a second (two or three of them with their reverberation), each up
    # to half as loud as the monitor's own direct sound (its loudspeaker turned away from its
    # microphone): the own pulses are still found within half a second (the search wanted them 20
    # times the stream's median envelope, and did not lock). Muted, the same pings never lock it.
    for seed in range(3):
        _, alerts, ends = _run_stream(_among_pings(0.1, 0.05, 1200, 2.0, seed))
        locked = [e for a, e in zip(alerts, ends) if a.latency_s is not None]
        assert locked and locked[0] / FS < 0.5
        assert abs(alerts[-1].latency_s - (5000 / FS - 0.07 / 343.0)) < 1e-4  # (less the 7 cm's flight)
        _, alerts, _ = _run_stream(_among_pings(0.0, 0.1, 1800, 3.0, seed))
        assert all(a.latency_s is None and a.level == "clear" for a in alerts)
        assert "no_direct_sound" in alerts[-1].flags


def _run_stream(x: np.ndarray):
    mon = _monitor()
    alerts, ends = [], []
    for i in range(0, len(x), 480):
        alerts.append(mon.process(x[i:i + 480]))
        ends.append(i + 480)
    return mon, alerts, ends


def test_a_wall_behind_that_took_a_passers_by_echoes_keeps_its_pace():
    # Seed 5000's room 2 (all at once): the wall behind's track, receding at 1.4 m/s for a second,
    # took a passer-by's echoes as the two crossed and its filter read 2.6 m/s within 0.15 s. As
    # the walls behind's pace it put a mirror nearing at 1.5 m/s, 0.7 m off, 0.46 m beside the way,
    # and the caution waited until 0.18 m. Faster than a wearer walks, a track gives its line's.
    behind = _line_track(1.0, 1.4, 24, 30.0)
    for t, d in ((0.96, 1.0 + 1.4 * 0.96 + 0.06), (1.0, 1.0 + 1.4 * 1.0 + 0.14)):  # the passer-by's, ahead of its line
        behind.update(t, d, 0.02)
    assert behind.speed > 2.0 and behind.steady_speed() == pytest.approx(1.4, abs=0.02)
    times = 0.6 + 0.04 * np.arange(12)  # the mirror's echoes: the last 12 pulses, up to 1.04 s
    mirror = _track(times, 0.7 + 1.5 * (times[-1] - times), 25.0)
    mon = _monitor()
    mon._tracks, mon._now = [mirror, behind], int((mirror.times[-1] + 0.02) * FS)
    mon._judge(None, mirror.times[-1] + 0.04)
    assert mirror.ahead is None and mon._behind == pytest.approx(1.4, abs=0.02) and mon._level == "caution"
    assert mon._pace == pytest.approx(1.5)  # (the mirror's: the wall behind's line is slower)


def test_echoes_are_lent_only_while_the_pace_is_sure():
    # A track nearing at 0.2 m/s takes an echo: lent to the lines at the wearer's pace (1.5 m/s as
    # the walls behind recede) while nothing nears faster than 1.1 times that; not while something
    # nears at 1.8 m/s (a person walking toward the wearer, or walls behind met at an angle).
    def lent(pace):
        slow = _line_track(1.6, -0.2, 12, 20.0)
        mon = _monitor()
        mon._tracks, mon._pace, mon._behind = [slow], pace, 1.5
        mon._commit(0.48, [(slow.predict(0.48), 0.05)])
        return mon._fresh[-1][4]

    assert len(lent(1.6)) == 1 and lent(1.8) == []


def test_a_track_started_on_lent_echoes_cautions_before_the_fit_only_at_the_pace_from_eight_echoes():
    # Near (0.8 m), nearing at the pace the walls behind recede at, beyond doubt (score 20), not yet
    # in the way by the fit: a track started on echoes another track took (a passer-by crossing the
    # way 0.6 m ahead was one, seed 45000's all at once, room 18) cautions on its eighth echo, not
    # its seventh; one started on echoes of its own, on its fifth. Nearing faster than the walls
    # behind recede (met at an angle, they may recede slower than the wearer walks: seed 47000's
    # room 17 door, a wall 34 degrees off the way), only one started on echoes of its own.
    def level(n, lent, speed=1.5):
        times = 0.6 + 0.04 * np.arange(n)
        near = _track(times, 0.8 + speed * (times[-1] - times), 20.0)
        near.lent = lent
        mon = _monitor()
        mon._tracks, mon._now = [near, _line_track(1.0, 1.5, 24, 30.0)], int((times[-1] + 0.02) * FS)
        mon._judge(None, times[-1] + 0.04)
        assert near.ahead is None and mon._behind == pytest.approx(1.5, abs=0.02)
        return mon._level

    assert level(7, True) == "clear" and level(8, True) == "caution"
    assert level(5, False) == "caution" and level(4, False) == "clear"
    assert level(10, True, 1.8) == "clear" and level(10, False, 1.8) == "caution"


def test_a_line_at_the_wearers_pace_starts_a_track_though_the_head_bob_bends_it():
    # A wall walked toward at 1.8 m/s, its echo over three pulses 7.5 mm off a straight line (the
    # head's bob; seed 5000's all at once, room 23), among stray peaks: no track at any pace (6 mm),
    # one at the wearer's pace once the walls behind tell it; a line of stray peaks bent as much at
    # another speed starts none either way.
    from vrecho.headset.tracks import initiate

    def pulses():
        echoes = ([(1.409, 0.05), (0.62, 0.02), (2.7, 0.02)], [(1.344, 0.05), (0.72, 0.02), (2.6835, 0.02)],
                  [(1.264, 0.05), (0.8, 0.02), (2.652, 0.02)])
        return [(0.04 * k, sorted(e), 2.0, 0.03) for k, e in enumerate(echoes)]

    assert initiate(pulses()) == []
    born = initiate(pulses(), pace=1.8)
    assert len(born) == 1 and abs(born[0].speed + 1.8) < 0.15 and abs(born[0].d_hat - 1.264) < 0.01


def test_a_line_at_the_wearers_pace_starts_through_an_echo_another_track_took():
    # A wall walked toward at 1.6 m/s; at the middle pulse its echo fell where a line of stray peaks
    # nearing at 0.2 m/s crossed it, and that track took it. Lent to the lines at the wearer's pace,
    # it starts the wall's track (the echoes it used taken out of their lists); not lent, or the
    # pace not known, no track: the two echoes left make no line.
    from vrecho.headset.tracks import initiate

    def pulses(lend):
        fresh = ([(1.464, 0.05), (0.62, 0.02)], [(0.72, 0.02)], [(1.336, 0.05), (2.652, 0.02)])
        lent = ([], [(1.400, 0.05)], [])
        return [(0.04 * k, sorted(e), 2.0, 0.03, *([list(l)] if lend else [])) for k, (e, l) in enumerate(zip(fresh, lent))]

    assert initiate(pulses(False), pace=1.6) == [] and initiate(pulses(True)) == []
    ps = pulses(True)
    born = initiate(ps, pace=1.6)
    assert len(born) == 1 and abs(born[0].speed + 1.6) < 0.1 and abs(born[0].d_hat - 1.336) < 0.01
    assert list(born[0].dists) == [1.464, 1.400, 1.336]
    assert ps[1][4] == [] and ps[0][1] == [(0.62, 0.02)] and ps[2][1] == [(2.652, 0.02)] and ps[1][1] == [(0.72, 0.02)]


def test_a_track_closing_at_the_wearers_pace_weighs_as_a_surface_ahead():
    # A surface's echoes, among 8 stray peaks a metre: a track closing at the wearer's pace (the walls
    # behind recede at it) gains log(3.2 / (0.2 * pace)) an echo more than where the pace is not
    # known; one closing at half the pace, nothing.
    from vrecho.headset.tracks import Track

    def score(speed, pace):
        tr, rng = Track(), np.random.default_rng(0)
        for k in range(8):
            tr.update(0.04 * k, 2.0 - speed * 0.04 * k + float(rng.normal(0, 0.002)), 0.02, clutter_per_m=8.0, pace=pace)
        return tr.score

    gain = score(1.5, 1.5) - score(1.5, 0.0)
    assert abs(gain - 6 * np.log(3.2 / (0.2 * 1.5))) < 0.01  # (from the third echo on: the speed known)
    assert score(0.75, 1.5) == score(0.75, 0.0)


def test_the_wearers_pace_is_the_walls_behinds_not_a_surface_nearing():
    # A person walking toward the wearer, nearing at 1.3 m/s, among 20 stray peaks a pulse; the
    # wearer, from standing, walks at 0.6 m/s (the wall behind recedes at that). The fastest surface
    # heard is the person, and would be its own pace (seed 44000's all at once, room 4's door: its
    # track's score rose on it to a caution at 0.64 m). The pace the tracks are weighed by is the
    # walls behind's: the person's track scores more only where the wearer walks at 1.3 m/s too.
    def score(pace):
        mon, rng = _monitor(), np.random.default_rng(0)
        for k in range(34):
            t = 0.04 * k
            u = max(t - 0.4, 0.0)
            walked = 1.5 * min(u, pace / 3) ** 2 + pace * max(u - pace / 3, 0.0)  # (3 m/s^2 up to the pace)
            echoes = [(1.2 + walked + float(rng.normal(0, 0.001)), 0.03)]
            if k >= 16:
                echoes.append((3.5 - 1.3 * (t - 0.64) + float(rng.normal(0, 0.001)), 0.03))
            echoes += [(float(d), 0.02) for d in rng.uniform(0.3, 3.9, 20)]
            mon._now = int(t * mon.fs)
            mon._commit(t, sorted(echoes))
            mon._judge(None, t)
        return max(tr.score for tr in mon._tracks if tr.speed is not None and abs(tr.speed + 1.3) < 0.1)

    assert score(1.3) > score(0.6) + 5
