import numpy as np
import pytest

from vrecho.errors import VrechoError
from vrecho.signals import FS, HELD_OUT_SOUNDS, SOUNDS, TRAIN_SOUNDS, emitted_sound, probe, pulse_train


def test_sixteen_sounds_split_as_the_paper():
    assert len(SOUNDS) == 16
    assert set(TRAIN_SOUNDS) | set(HELD_OUT_SOUNDS) == set(SOUNDS)
    assert not set(TRAIN_SOUNDS) & set(HELD_OUT_SOUNDS)


@pytest.mark.parametrize("name", SOUNDS)
def test_sound_shape_peak_and_fades(name):
    x = emitted_sound(name, FS, np.random.default_rng(1))
    assert x.shape == (4410,) and x.dtype == np.float32
    assert np.isclose(np.max(np.abs(x)), 0.8, atol=1e-6)
    assert abs(x[0]) < 0.01 and abs(x[-1]) < 0.01


def _peak_hz(x):
    spec = np.abs(np.fft.rfft(x, 1 << 16))
    return np.fft.rfftfreq(1 << 16, 1 / FS)[np.argmax(spec)]


@pytest.mark.parametrize("f", [63, 1000, 16000])
def test_tones_at_their_frequency(f):
    assert abs(_peak_hz(emitted_sound(f"tone_{f}")) - f) < 15


def test_chirp_spans_440_to_1320_hz():
    x = emitted_sound("chirp")
    assert 440 <= _peak_hz(x[:1000]) < 700 and 1000 < _peak_hz(x[-1000:]) <= 1330


def test_noise_colours_fall_off():
    rng = np.random.default_rng(0)
    slopes = []
    for name in ("white_noise", "pink_noise", "brown_noise"):
        p = np.mean([np.abs(np.fft.rfft(emitted_sound(name, FS, rng))) ** 2 for _ in range(20)], axis=0)
        f = np.fft.rfftfreq(4410, 1 / FS)
        band = (f > 200) & (f < 10000)
        slopes.append(np.polyfit(np.log10(f[band]), 10 * np.log10(p[band]), 1)[0])
    assert abs(slopes[0]) < 2 and -13 < slopes[1] < -7 and -24 < slopes[2] < -16  # 0, -10, -20 dB/decade


def test_random_sounds_follow_the_generator():
    a = emitted_sound("voice", FS, np.random.default_rng(5))
    assert np.array_equal(a, emitted_sound("voice", FS, np.random.default_rng(5)))
    assert not np.array_equal(a, emitted_sound("voice", FS, np.random.default_rng(6)))


def test_probe_is_broadband():
    # A logarithmic sweep puts the same energy in every octave from 250 Hz to 16 kHz.
    power = np.abs(np.fft.rfft(probe(), 1 << 16)) ** 2
    f = np.fft.rfftfreq(1 << 16, 1 / FS)
    octaves = [10 * np.log10(power[(f >= fc / np.sqrt(2)) & (f < fc * np.sqrt(2))].sum())
               for fc in (250, 500, 1000, 2000, 4000, 8000, 16000 / np.sqrt(2))]
    assert max(octaves) - min(octaves) < 3.0


def test_pulse_train_periods():
    x = pulse_train(emitted_sound("clap"), 3)
    assert x.shape == (3 * FS,)
    assert np.all(x[4410:FS] == 0) and np.array_equal(x[:4410], x[FS:FS + 4410])


@pytest.mark.parametrize("fs", [0, -44100, 44100.5, float("nan"), "44100", 4000])
def test_bad_sample_rate(fs):
    with pytest.raises(VrechoError, match="fs"):
        emitted_sound("clap", fs)


def test_unknown_sound():
    with pytest.raises(VrechoError, match="unknown emitted sound"):
        emitted_sound("trumpet")


def test_random_probes_span_the_product_band():
    from vrecho.signals import random_probe

    rng = np.random.default_rng(0)
    f = np.fft.rfftfreq(1 << 16, 1 / FS)
    for _ in range(12):
        x = random_probe(rng)
        assert x.shape == (4410,) and np.isclose(np.abs(x).max(), 0.8)
        power = np.abs(np.fft.rfft(x, 1 << 16)) ** 2
        level = 10 * np.log10(power / power.max())
        for lo, hi in ((200, 300), (15000, 16000)):  # both ends of 200 Hz to 16 kHz are excited
            assert level[(f >= lo) & (f < hi)].max() > -45


def test_coherence_reads_each_recording_of_a_batch_on_its_own():
    """A pulse scaled explains its window whole (1), noise little; a batch answers as its rows
    one by one, and a row with samples that are not finite answers 0, not its neighbours'."""
    from vrecho.signals import analytic_envelope, analytic_filter, coherence

    s = probe()
    k, rng = s.size, np.random.default_rng(3)
    x = np.zeros((3, 3 * k))
    x[0, 500:500 + k] = 0.5 * s  # a pulse, alone
    x[1] = rng.standard_normal(3 * k)  # noise
    x[2, 700:700 + k] = 3e3 * s  # a loud pulse (scaled down inside: the ratio is the same)
    n = 1 << int(np.ceil(np.log2(4 * k)))
    env = analytic_envelope(x, analytic_filter(s.astype(np.float64), n), n)[:, :2 * k + 1] / np.linalg.norm(s)
    both = coherence(x, env, k)
    rows = np.stack([coherence(x[i], env[i], k) for i in range(3)])
    np.testing.assert_allclose(both, rows)
    assert both[0].max() > 0.99 and int(np.argmax(both[0])) == 500
    assert both[1].max() < 0.2
    assert both[2].max() > 0.99 and int(np.argmax(both[2])) == 700
    bad = x.copy()
    bad[1, 10] = np.nan
    out = coherence(bad, env, k)
    assert not out[1].any() and np.allclose(out[[0, 2]], both[[0, 2]])
