"""Sound sources across the operating envelope (issue 26): other arrays, walks and rooms
(vrecho.sim.arrays, real pyroomacoustics simulations), and informed separation that does no harm."""

import numpy as np
import pytest

from vrecho.errors import VrechoError


def test_random_arrays_span_the_envelope():
    from vrecho.sim.arrays import random_array

    rng = np.random.default_rng(0)
    for _ in range(50):
        a = random_array(rng)
        p = np.asarray(a.offsets)
        d = np.linalg.norm(p[:, None] - p[None], axis=-1)
        assert 2 <= a.n_mics <= 8
        assert 0.05 - 1e-3 <= d.max() <= 0.25 + 1e-3
        assert d[np.triu_indices(a.n_mics, 1)].min() >= 0.01 - 1e-3
    flat = np.asarray(random_array(rng, 6, flat=True).offsets)
    assert np.ptp(flat[:, 0]) < 1e-9  # all in the forward-facing plane


@pytest.mark.parametrize("condition", ["flat 9x5", "two mics", "head turning", "44.1/48 kHz", "tv and fan", "now and then"])
def test_envelope_walks_are_what_their_condition_says(condition):
    from vrecho.sim.arrays import FLAT_9X5, envelope_walk

    w = envelope_walk(np.random.default_rng(5), condition)
    caps = w.sim.captures
    assert len(caps) == len(w.sim.poses) and w.sim.images.shape[:2] == (len(caps), len(w.sim.sources))
    assert all(c.n_mics == w.array.n_mics and np.all(np.isfinite(c.audio)) for c in caps)
    lo, hi = w.bounds
    for s in w.sim.sources:
        assert np.all(s.position > lo) and np.all(s.position < hi)
    if condition == "flat 9x5":
        assert w.array is FLAT_9X5
    if condition == "two mics":
        assert w.array.n_mics == 2
    if condition == "head turning":  # the head nods and tilts: not every pose is upright
        assert max(abs(p.up[2] - 1) for p in w.sim.poses) > 0.01
    if condition == "44.1/48 kHz":
        assert caps[0].fs in (44_100, 48_000)
    if condition == "tv and fan":
        assert {s.name for s in w.sim.sources} <= {"tv", "fan"}
    if condition == "now and then":  # the talker pauses: whole stretches of silence
        talker = [s for s in w.sim.sources if s.name == "now_and_then"]
        assert all(np.mean(np.abs(s.signal) < 1e-9) > 0.2 for s in talker)


def test_polygon_rooms_reverberate_within_the_envelope():
    """PROTOCOL.md's rooms reverberate 0.2 to 1.0 s: every polygon room's materials are drawn for
    it (Eyring's time within the range asked), and the simulator's own decay of one, image
    sources and ray tracing (pyroomacoustics), lies within the envelope too."""
    from pyroomacoustics.experimental import measure_rt60

    from vrecho.scene import Scene
    from vrecho.sim.acoustics import Simulation, impulse_responses
    from vrecho.sim.arrays import eyring_rt60, polygon_room

    rng = np.random.default_rng(3)
    times = [eyring_rt60(polygon_room(rng)) for _ in range(50)]
    assert 0.2 <= min(times) and max(times) <= 0.8
    assert all(0.2 <= eyring_rt60(polygon_room(rng, (0.2, 1.0))) <= 1.0 for _ in range(20))
    with pytest.raises(VrechoError, match="reverberation time of 0.05 to 0.1 s"):
        polygon_room(rng, (0.05, 0.1), tries=5)
    room = polygon_room(np.random.default_rng(1))
    lo, hi = room.footprint.min(axis=0), room.footprint.max(axis=0)
    points = np.c_[rng.uniform(lo, hi, (200, 2)), np.full(200, 1.5)]
    points = points[room.contains(points, margin_m=0.3)]
    source, mic = points[0], points[np.argmax(np.linalg.norm(points - points[0], axis=1))]
    h = impulse_responses(Scene("t", room), source, mic, 16_000, sim=Simulation(length_s=1.5), cache=False)[0]
    assert 0.2 <= measure_rt60(h, 16_000, decay_db=20) <= 1.0


def test_unknown_condition_is_one_error():
    from vrecho.sim.arrays import envelope_walk

    with pytest.raises(VrechoError, match="condition: expected one of"):
        envelope_walk(np.random.default_rng(0), "underwater")


def test_analysis_and_synthesis_give_every_sample_back():
    from localization.separate import analysis, synthesis

    x = np.random.default_rng(0).standard_normal((3, 16_001))
    for nfft in (256, 512, 1024):
        assert np.abs(synthesis(analysis(x, nfft), x.shape[1], nfft) - x).max() < 1e-9


@pytest.mark.parametrize("fs", [16_000, 48_000])
def test_a_lone_source_is_the_microphone_itself(fs):
    """Nothing to separate it from: its track is microphone 0, sample for sample, at any rate
    (the mixture at 16 kHz and back lost everything above 8 kHz and the STFT's edges before)."""
    from localization import Capture, separate
    from localization.separate import informed

    rng = np.random.default_rng(1)
    mics = np.array([[1.0, 1.0, 1.5], [1.1, 1.0, 1.5], [1.0, 1.1, 1.5], [1.0, 1.0, 1.6]])
    cap = Capture(rng.standard_normal((4, fs)), fs, mics)
    y = separate(cap, 1, positions=[[3.0, 2.0, 1.0]])
    assert y.shape == (1, fs) and np.abs(y[0] - cap.audio[0]).max() < 1e-9
    assert informed(cap, np.array([[3.0, 2.0, 1.0]])).separated.tolist() == [True]


def _flat_walk(pitch_deg: float):
    """A flat horizontal 4-microphone array (10 cm square) walked at 1.5 m past a voice 0.8 m above
    it: 4 poses, the head turning and, where ``pitch_deg``, nodding."""
    from localization.capture import FS
    from vrecho.device import MicArray
    from vrecho.sim.ambient import AmbientSource, Shoebox, simulate_walk_capture
    from vrecho.sim.arrays import head_pose
    from vrecho.sim.sounds import ambient_sound

    rng = np.random.default_rng(7)
    flat = MicArray("flat", ((0.05, 0.05, 0.0), (0.05, -0.05, 0.0), (-0.05, -0.05, 0.0), (-0.05, 0.05, 0.0)))
    poses = [head_pose(np.array([1.5 + 0.5 * k, 1.2, 1.43]), np.radians(70 - 30 * k), np.radians(pitch_deg * (-1) ** k), 0.0)
             for k in range(4)]
    source = AmbientSource(np.array([2.6, 3.0, 2.3]), ambient_sound("speech", 4.2, FS, rng), "speech")
    sim = simulate_walk_capture(Shoebox((4.5, 4.5, 2.8), 0.3), [source], poses, rng, array=flat, segment_s=1.0)
    return sim, ((0, 0, 0), (4.5, 4.5, 2.8))


@pytest.mark.slow
def test_a_flat_array_says_it_cannot_tell_up_from_down():
    """Level, the array hears the voice 0.8 m above it as well as 0.8 m below: z's uncertainty
    says so (more than half of 1.6 m, twice x's and y's at least); nodding 25 degrees either way tells them
    apart, and the uncertainty on z falls."""
    from localization import locate

    sim, bounds = _flat_walk(0.0)
    level = locate(sim.captures, 1, bounds=bounds)
    assert level.uncertainty_axes_m.shape == (1, 3)
    assert level.uncertainty_axes_m[0, 2] > 0.5 and level.uncertainty_axes_m[0, 2] > 2 * level.uncertainty_axes_m[0, :2].max()
    assert np.isclose(level.uncertainty_m[0], np.linalg.norm(level.uncertainty_axes_m[0]))
    sim, bounds = _flat_walk(25.0)
    nodding = locate(sim.captures, 1, bounds=bounds)
    assert np.linalg.norm(nodding.positions[0] - sim.sources[0].position) < 0.35
    assert nodding.uncertainty_axes_m[0, 2] < 0.4


def test_two_low_tones_on_a_small_array_give_the_microphone_flagged():
    """Below 500 Hz a 9 x 5 cm array hears every direction alike: informed separation cannot tell
    the two tones apart by where they are, so each track is microphone 0 itself (no worse than it),
    and place_sources says so."""
    from localization import informed, place_sources
    from localization.capture import FS
    from vrecho.sim.ambient import AmbientSource, Shoebox, simulate_walk_capture
    from vrecho.sim.arrays import FLAT_9X5, head_pose
    from vrecho.sim.sounds import ambient_sound

    rng = np.random.default_rng(2)
    poses = [head_pose(np.array([1.5 + 0.4 * k, 1.5, 1.5]), np.radians(40 * k), 0.0, 0.0) for k in range(3)]
    sources = [AmbientSource(np.array([3.5, 3.0, 1.0]), ambient_sound("tone_125", 4.6, FS, rng), "tone_125"),
               AmbientSource(np.array([0.7, 3.4, 1.8]), ambient_sound("tone_250", 4.6, FS, rng), "tone_250")]
    sim = simulate_walk_capture(Shoebox((4.5, 4.5, 2.7), 0.3), sources, poses, rng, array=FLAT_9X5, segment_s=1.5)
    cap = sim.captures[1]
    sep = informed(cap, np.array([s.position for s in sources]))
    assert not sep.separated.any() and np.all(sep.distinct < 0.05)
    assert np.array_equal(sep.signals, np.repeat(cap.audio[:1], 2, axis=0))
    kept = informed(cap, np.array([s.position for s in sources]), guard=False)
    assert kept.separated.all() and not np.array_equal(kept.signals[0], cap.audio[0])
    placed = place_sources(sim.captures, 2, bounds=((0, 0, 0), (4.5, 4.5, 2.7)))
    assert placed and all(p.flags and p.flags[0].startswith("not separated in") for p in placed)


def test_a_track_the_separation_cannot_take_back_out_of_its_own_remix_is_the_microphone():
    """Informed separation with both sources where they are keeps both tracks (each better than
    the microphone); told the music is 3 m from where it plays, the voice's track would come out
    worse than the microphone, and the remix says so: separated again from a mixture of its own
    tracks, the voice's comes back only a few dB over it, so microphone 0 is given instead."""
    from localization import informed
    from localization.capture import FS
    from localization.separate import GUARD, si_sdr
    from vrecho.sim.ambient import AmbientSource, Shoebox, simulate_walk_capture
    from vrecho.sim.arrays import head_pose
    from vrecho.sim.sounds import ambient_sound

    rng = np.random.default_rng(3)
    poses = [head_pose(np.array([1.5 + 0.4 * k, 1.5, 1.5]), np.radians(40 * k), 0.0, 0.0) for k in range(3)]
    sources = [AmbientSource(np.array([3.5, 3.0, 1.2]), ambient_sound("speech", 4.6, FS, rng), "speech"),
               AmbientSource(np.array([0.7, 3.4, 1.6]), ambient_sound("music", 4.6, FS, rng), "music")]
    sim = simulate_walk_capture(Shoebox((4.5, 4.5, 2.7), 0.3), sources, poses, rng, segment_s=1.5)
    cap, ref = sim.captures[1], sim.images[1, :, 0]

    def gains(sep):
        return [si_sdr(ref[j], sep.signals[j]) - si_sdr(ref[j], cap.audio[0]) for j in range(2)]
    right = informed(cap, np.array([s.position for s in sources]))
    assert right.separated.all() and np.all(right.remixed >= GUARD["remixed_db"]) and min(gains(right)) > 1.0
    wrong = np.array([sources[0].position, [3.8, 0.6, 2.2]])
    unguarded = informed(cap, wrong, guard=False)
    assert gains(unguarded)[0] < 0.0  # what the voice's track would have been
    guarded = informed(cap, wrong)
    assert guarded.remixed[0] < GUARD["remixed_db"] and not guarded.separated[0]
    assert np.array_equal(guarded.signals[0], cap.audio[0])
    # A kept track comes mixed with microphone 0 as the remix allows, and is better for it here.
    raw = informed(cap, np.array([s.position for s in sources]), guard=False)
    assert np.all((right.weight > 0.5) & (right.weight < 1)) and np.array_equal(raw.weight, right.weight)
    assert np.allclose(right.signals, cap.audio[0] + right.weight[:, None] * (raw.signals - cap.audio[0]))
    assert np.mean(gains(right)) > np.mean(gains(raw))
    # Two sources' positions given with their uncertainty: the guard does not read it (track_weights: three or more).
    unsure = informed(cap, np.array([s.position for s in sources]), uncertainty_m=[0.2, GUARD["uncertainty_m"] + 1])
    assert np.array_equal(unsure.signals, right.signals)


def test_a_kept_track_weighs_against_the_microphone_as_its_remix_says():
    """track_weights: 0 where the guard gives the microphone (a position placed less surely than
    its bound among them), 1 for a lone source, and between them rising with the remix's reading."""
    from localization.separate import GUARD, mix_back, track_weights

    ok = np.ones(4)
    w = track_weights(ok, ok, np.array([GUARD["remixed_db"] - 0.1, GUARD["remixed_db"], 20.0, np.inf]))
    assert w[0] == 0.0 and w[3] == 1.0 and 0.6 < w[1] < w[2] < 1.0
    assert np.isclose(w[1], 1 / (1 + 10 ** (-(GUARD["remixed_db"] - GUARD["mix_back_db"]) / GUARD["mix_back_width_db"])))
    assert track_weights(np.array([0.0]), np.ones(1), np.array([30.0]))[0] == 0.0  # not distinct: the microphone
    unsure = np.array([0.0, GUARD["uncertainty_m"], GUARD["uncertainty_m"] + 0.01, np.inf])  # (inf: unknown, not read)
    assert (track_weights(ok, ok, np.full(4, 20.0), None, unsure) > 0).tolist() == [True, True, False, True]
    assert np.all(track_weights(ok[:2], ok[:2], np.full(2, 20.0), None, unsure[1:3]) > 0)  # two sources: not read
    doubt = np.array([0.0, GUARD["doubt"] - 0.01, GUARD["doubt"], 5.0])  # the two mask networks parting: the microphone
    assert (track_weights(ok, ok, np.full(4, 20.0), None, None, doubt) > 0).tolist() == [True, True, False, False]
    mic, tracks = np.arange(3.0), np.array([[5.0, 5, 5], [1, 1, 1], [2, 4, 6]])
    mixed = mix_back(mic, tracks, np.array([0.0, 1.0, 0.5]))  # what informed gives: each track with the microphone
    assert np.array_equal(mixed, [mic, tracks[1], [1, 2.5, 4]]) and np.array_equal(mix_back(mic, tracks[2], 0.5), mixed[2])


def test_a_track_whose_sound_points_at_another_source_is_told_by_its_spatial_fit():
    """spatial_fit: two sources' sounds through their own steering vectors, each bin given to the
    one that is loudest there; read at the right positions each track points at its own (fit
    near +1), with the positions swapped at the other's (near -1); and the guard's bound on it
    gives the microphone."""
    from localization.separate import GUARD, covariances, spatial_fit, track_weights

    rng = np.random.default_rng(0)
    mics = np.array([[0.0, 0, 0], [0.09, 0, 0], [0, 0.05, 0], [0.09, 0.05, 0]])
    sources = np.array([[2.0, 1.0, 0.3], [-1.0, 2.0, -0.2]])
    freqs = np.linspace(0, 8000, 129)
    dist = np.linalg.norm(mics[:, None] - sources[None], axis=-1)  # (M, K)
    A = (dist[:1] / dist)[None] * np.exp(-2j * np.pi * freqs[:, None, None] * (dist - dist[:1])[None] / 343.0)
    S = rng.normal(size=(200, 129, 2)) + 1j * rng.normal(size=(200, 129, 2))  # each source's spectrum
    S *= np.where(rng.random((200, 129, 2)) < 0.5, 1.0, 0.05)  # sparse: each bin mostly one source's
    X = np.einsum("fmk,tfk->tfm", A, S) + 0.01 * (rng.normal(size=(200, 129, 4)) + 1j * rng.normal(size=(200, 129, 4)))
    share = np.abs(S) ** 2 / np.sum(np.abs(S) ** 2, axis=-1, keepdims=True)
    covs = covariances(X, share)
    right, swapped = spatial_fit(covs, A, freqs), spatial_fit(covs, A[..., ::-1], freqs)
    assert np.all(right > 0.5) and np.all(swapped < -0.5)
    ok = np.ones(2)
    assert np.all(track_weights(ok, ok, np.full(2, 20.0), right) > 0)
    assert np.all(track_weights(ok, ok, np.full(2, 20.0), swapped) == 0)  # the microphone
    assert swapped.max() < GUARD["spatial"] < right.min()
