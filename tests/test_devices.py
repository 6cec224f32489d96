"""The operating envelope's devices (vrecho.sim.devices): real pyroomacoustics rooms, PyAV's AAC."""

import numpy as np
import pytest

from vrecho.errors import VrechoError
from vrecho.sim.devices import CONDITIONS, Device, echo_frame, random_device


def test_each_condition_draws_what_it_names(tmp_path):
    """Each condition's frame is a finite 1 s frame with headroom, its device and pose as the
    condition names them; an unknown condition is one error."""
    seen = {}
    for k, c in enumerate(CONDITIONS):
        f = echo_frame(np.random.default_rng(k), c, cache=tmp_path)
        assert f.audio.shape == (44100,) and f.audio.dtype == np.float32 and np.all(np.isfinite(f.audio))
        assert 0 < np.abs(f.audio).max() < 0.97 and f.emitted.shape == (4410,)  # never clipped
        assert 0.25 <= f.depth_m <= 3.0 and f.material in ("open", "glass", "mirror") and f.is_open == (f.material == "open")
        assert f.condition == c and len(f.others_m) >= 2
        seen[c] = f
    assert seen["reference"].device == Device()
    assert seen["omni"].device.emitter_p == 1.0
    assert seen["bottom-firing"].device.axis == (0.0, 0.0, -1.0)
    assert 0.1 <= np.linalg.norm(seen["offset"].device.mic_m) <= 0.15
    assert seen["near floor"].height_m <= 0.6 and seen["near ceiling"].ceiling_m <= 0.4
    assert seen["transducer"].device.low_cut_hz >= 200 and seen["limiter"].device.limiter and seen["AAC"].device.aac
    with pytest.raises(VrechoError, match="condition"):
        random_device(np.random.default_rng(0), "underwater")


def test_the_same_seed_gives_the_same_frame(tmp_path):
    a = echo_frame(np.random.default_rng(7), "envelope", cache=tmp_path)
    b = echo_frame(np.random.default_rng(7), "envelope", cache=tmp_path)
    assert np.array_equal(a.audio, b.audio) and a.device == b.device
