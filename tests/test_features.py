import numpy as np
import pytest

from vrecho.errors import VrechoError
from vrecho.features import echo_features, echo_response, logmel, self_features
from vrecho.signals import FS, emitted_sound, probe


def _frame(delays_gains, sound):
    h = np.zeros(FS)
    for k, g in delays_gains:
        h[k] = g
    return np.fft.irfft(np.fft.rfft(h) * np.fft.rfft(sound, FS), FS).astype(np.float32)


def test_logmel_shape_and_normalisation():
    x = _frame([(9, 1.0), (300, 0.3)], emitted_sound("clap"))
    x += 1e-3 * np.random.default_rng(0).standard_normal(FS).astype(np.float32)  # a microphone's noise floor
    s = logmel(x, FS)
    assert s.shape == (62, 25) and s.dtype == np.float32
    assert abs(s.mean()) < 1e-4 and abs(s.std() - 1) < 1e-3
    batch = logmel(np.stack([x, 0.5 * x]), FS)
    assert batch.shape == (2, 62, 25) and np.allclose(batch[0], batch[1], atol=1e-3)  # level-invariant


def test_other_rates_are_resampled():
    x = _frame([(9, 1.0)], emitted_sound("white_noise"))
    import librosa

    x48 = librosa.resample(x, orig_sr=FS, target_sr=48000)[:48000]
    assert np.abs(logmel(x48, 48000) - logmel(x, FS)).mean() < 0.1


@pytest.mark.parametrize("audio, fs, message", [
    (np.zeros(1000), FS, "a frame is 1 s"),
    (np.full(FS, np.nan), FS, "NaN"),
    (np.zeros(FS), -1, "fs"),
    (np.zeros((2, 3, FS)), FS, "1-D frame or a 2-D batch"),
])
def test_bad_frames(audio, fs, message):
    with pytest.raises(VrechoError, match=message):
        logmel(audio, fs)


def test_echo_response_recovers_delays_with_a_broadband_sound():
    sound = probe()
    x = _frame([(9, 1.0), (257, 0.2), (700, 0.05)], sound)
    h = echo_response(x, sound, FS)
    assert h.shape == (1323,)
    for lo, hi, k in ((0, 100, 9), (100, 500, 257), (500, 1323, 700)):
        assert lo + np.argmax(np.abs(h[lo:hi])) == k
    assert np.isclose(h[257] / h[9], 0.2, atol=0.01)
    f = echo_features(x, sound, FS)
    assert f.envelope.shape == (1323,) and f.bands.shape == (7, 20)
    assert np.isclose(f.envelope[257], 0.2, atol=0.03)


def test_echo_response_needs_a_sound():
    with pytest.raises(VrechoError, match="silent"):
        echo_response(np.zeros(FS), np.zeros(4410), FS)


def test_a_planes_echo_is_the_frames_own_whatever_its_batch():
    """plane_echo reads each frame alone: the same features whether the frame is asked about
    by itself or beside a frame asked about a plane 9 m away."""
    from vrecho.planes import plane_echo
    from vrecho.signals import probe

    frame = np.zeros(44_100, np.float32)
    frame[:4410] += probe()
    frame[600:5010] += 0.3 * probe()
    frame += 1e-3 * np.random.default_rng(0).standard_normal(44_100).astype(np.float32)
    alone = plane_echo(frame, probe(), 2.3)
    beside = plane_echo(np.stack([frame, frame]), probe(), [2.3, 9.0])
    assert np.allclose(alone.features[0], beside.features[0], atol=1e-6) and alone.depth_m[0] == beside.depth_m[0]
    assert alone.features[0, 0] > 20


def test_the_farthest_plane_is_read_whatever_the_microphones_distance():
    """A plane at the farthest distance allowed, with the widest tolerance, and a direct sound as
    late as plane_echo looks for it (the microphone 0.68 m off, or a frame that starts early):
    its window and the echoes around it lie within the envelope read (an IndexError before)."""
    from vrecho.planes import DIRECT_S, MAX_SURFACE_M, plane_echo
    from vrecho.signals import probe

    frame = np.zeros(44_100, np.float32)
    lag = int(DIRECT_S * 44_100) - 1
    frame[lag:lag + 4410] += probe()
    echo = plane_echo(np.stack([frame, frame]), probe(), [MAX_SURFACE_M, 1.0], tolerance_m=0.5)
    assert np.all(np.isfinite(echo.features)) and echo.features.shape == (2, 6)

@pytest.mark.parametrize("sound", ["clap", "white_noise", "probe"])
def test_self_features_find_an_echo_without_the_emitted_sound(sound):
    """The recording as its own reference: the echo 291 samples after the direct sound (itself
    9 samples after emission, the reference device's 7 cm) stands where the emitted sound's
    deconvolution puts it, sample 300, whatever the broadband sound and its level."""
    s = probe() if sound == "probe" else emitted_sound(sound, rng=np.random.default_rng(3))
    x = _frame([(9, 1.0), (300, 0.3), (520, 0.1)], s)
    x += 1e-4 * np.random.default_rng(0).standard_normal(FS).astype(np.float32)
    f = self_features(np.stack([x, 0.01 * x]))
    assert f.envelope.shape == (2, 1323) and f.bands.shape == (2, 7, 20)
    assert np.allclose(f.envelope[0], f.envelope[1], atol=1e-3)  # level-invariant
    env = f.envelope[0]
    assert int(np.argmax(env[60:])) + 60 == 300 and 0.15 < env[300] < 0.45
    assert env[520] > 3 * np.median(env[60:])  # the weaker, later echo stands out too
    with pytest.raises(VrechoError, match="1 s"):
        self_features(x[:1000])
