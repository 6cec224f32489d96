"""Real captures (issue 9): pulses found in a phone's recording of the pulse train."""

import numpy as np
import pytest

from vrecho.errors import VrechoError


@pytest.fixture(scope="module")
def ir():
    from vrecho.acoustics import device_impulse_response
    from vrecho.scene import builtin_scene

    scene = builtin_scene()
    return device_impulse_response(scene, scene.poses[0])[0]


@pytest.mark.parametrize("snr_db, clip", [(20, None), (10, 0.3)])
def test_onsets_are_found_to_a_sample_through_noise_clipping_drift_and_a_missing_pulse(ir, snr_db, clip):
    from vrecho.capture import find_onsets, simulate_recording

    rng = np.random.default_rng(4)
    x, truth = simulate_recording(ir, 12, rng, snr_db=snr_db, drift=0.004, clip=clip, dropped=(6,))
    onsets = find_onsets(x, 44100)
    played = truth[~np.isnan(truth)]
    assert len(onsets.samples) == len(played)
    assert np.max(np.abs(onsets.samples - played)) <= 1.0
    assert len(onsets.missing) == 1 and abs(onsets.missing[0] - (truth[5] + truth[7]) / 2) < 0.01 * 44100
    assert abs(onsets.period_s - 1.004) < 1e-4


def test_no_pulses_is_one_clear_error():
    from vrecho.capture import find_onsets

    noise = np.random.default_rng(0).standard_normal(5 * 44100).astype(np.float32) * 0.01
    with pytest.raises(VrechoError, match="no pulse train"):
        find_onsets(noise, 44100)
    with pytest.raises(VrechoError, match="NaN"):
        find_onsets(np.full(44100, np.nan), 44100)


def test_frames_start_at_the_emission_like_the_simulators(ir):
    from vrecho.capture import cut_frames, find_onsets, simulate_recording
    from vrecho.signals import probe

    rng = np.random.default_rng(5)
    x, truth = simulate_recording(ir, 5, rng, snr_db=60)
    frames = cut_frames(x, find_onsets(x, 44100))
    # the steady state of the train, from the emission: what the simulator's frames hold
    n = len(ir)
    expected = np.fft.irfft(np.fft.rfft(ir, n) * np.fft.rfft(probe(), n), n)
    assert frames.shape[1] == n and len(frames) >= 3
    for f in frames[1:]:  # the first has no earlier pulse's tail
        scale = np.dot(f, expected) / np.dot(expected, expected)  # the microphone's sensitivity
        # a twentieth of a sample off shifts 18 kHz by a third of a radian: a few per cent
        assert np.max(np.abs(f / scale - expected)) < 0.08 * np.max(np.abs(expected))
        assert np.corrcoef(f, expected)[0, 1] > 0.999
