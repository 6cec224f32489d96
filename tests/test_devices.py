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
        rate = f.device.fs
        assert f.audio.shape == (rate,) and f.audio.dtype == np.float32 and np.all(np.isfinite(f.audio))
        assert 0 < np.abs(f.audio).max() < 0.97 and f.emitted.shape == (rate // 10,)  # never clipped
        assert 0.25 <= f.depth_m <= 3.0 and f.material in ("open", "glass", "mirror") and f.is_open == (f.material == "open")
        assert f.condition == c and len(f.paths_m) >= 5 and min(f.paths_m) > 0  # floor, ceiling, walls at least
        seen[c] = f
    assert seen["reference"].device == Device()
    assert abs(seen["reference"].mic_toward_m) <= 0.07 * np.sin(np.radians(10)) + 1e-9  # 7 cm up, tilted 10 degrees at most
    assert abs(seen["offset"].mic_toward_m) <= np.linalg.norm(seen["offset"].device.mic_m) + 1e-9
    assert seen["omni"].device.emitter_p == 1.0
    assert seen["bottom-firing"].device.axis == (0.0, 0.0, -1.0)
    assert 0.1 <= np.linalg.norm(seen["offset"].device.mic_m) <= 0.15
    assert seen["near floor"].height_m <= 0.6 and seen["near ceiling"].ceiling_m <= 0.4
    assert seen["transducer"].device.low_cut_hz >= 200 and seen["limiter"].device.limiter and seen["AAC"].device.aac
    assert seen["48 kHz"].device.fs == 48_000 and seen["reference"].device.fs == 44_100
    with pytest.raises(VrechoError, match="condition"):
        random_device(np.random.default_rng(0), "underwater")


def test_the_same_seed_gives_the_same_frame(tmp_path):
    a = echo_frame(np.random.default_rng(7), "envelope", cache=tmp_path)
    b = echo_frame(np.random.default_rng(7), "envelope", cache=tmp_path)
    assert np.array_equal(a.audio, b.audio) and a.device == b.device


def test_a_walk_keeps_its_room_device_and_probe_and_moves(tmp_path):
    """echo_frames: n frames of one device and probe before one surface, at distances a step
    apart; its first frame is echo_frame's; n below 1 is one error."""
    from vrecho.sim.devices import STEP_M, echo_frames

    walk = echo_frames(np.random.default_rng(3), "reference", 3, cache=tmp_path)
    first = echo_frame(np.random.default_rng(3), "reference", cache=tmp_path)
    assert len(walk) == 3 and np.array_equal(walk[0].audio, first.audio)
    assert all(f.device == walk[0].device and np.array_equal(f.emitted, walk[0].emitted) for f in walk)
    assert len({f.material for f in walk}) == 1
    depths = np.array([f.depth_m for f in walk])
    assert np.all(np.abs(np.diff(depths)) <= STEP_M + 1e-9) and np.all((depths >= 0.25) & (depths <= 3.0))
    assert not np.array_equal(walk[1].audio, walk[2].audio)
    fast = echo_frames(np.random.default_rng(3), "48 kHz", 2, cache=tmp_path)  # the probe resampled once, as sent
    assert [f.emitted.shape for f in fast] == [(4800,), (4800,)] and np.array_equal(fast[0].emitted, fast[1].emitted)
    with pytest.raises(VrechoError, match="n: expected a whole number"):
        echo_frames(np.random.default_rng(3), "reference", 0)


def test_paths_hold_the_rooms_echoes_not_the_surfaces():
    """paths_m (clutter_paths) on a known room: the floor's and the ceiling's echoes are there at
    2 h -+ 7 cm (the microphone 7 cm above the loudspeaker); the pane's own (sqrt(4 d^2 +
    0.07^2), facing it squarely) is not, and is where the pane is not the one asked about."""
    from vrecho.materials import WINDOW_GLASS, Material
    from vrecho.scene import Discontinuity, Room, Scene
    from vrecho.sim.devices import clutter_paths
    from vrecho.sim.scenes import face

    plaster = Material.from_database("plasterboard")
    room = Room([[0, 0], [8, 0], [8, 7], [0, 7]], 3.2, [plaster] * 4, plaster, plaster)
    scene = Scene("paths", room, [Discontinuity(0, 4.0, 1.3, 1.0, 1.0, "glass", WINDOW_GLASS)])
    pose = face(scene, 0, 1.5)  # emitter 1.3 m above the floor, the pane's centre
    mic = pose.emitter + 0.07 * pose.up
    paths = np.array(clutter_paths(scene, 0, pose.emitter, mic))
    h = float(pose.emitter[2])
    assert np.min(np.abs(paths - (2 * h + 0.07))) < 1e-3  # the floor, below the loudspeaker
    assert np.min(np.abs(paths - (2 * (3.2 - h) - 0.07))) < 1e-3  # the ceiling
    assert np.min(np.abs(paths - np.sqrt(4 * 1.5 ** 2 + 0.07 ** 2))) > 0.05  # not the pane's echo
    with_pane = np.array(clutter_paths(Scene("paths", room, [Discontinuity(0, 4.0, 1.3, 1.0, 1.0, "glass", WINDOW_GLASS),
                                                        Discontinuity(2, 4.0, 1.3, 1.0, 1.0, "open")]), 1, pose.emitter, mic))
    assert np.min(np.abs(with_pane - np.sqrt(4 * 1.5 ** 2 + 0.07 ** 2))) < 1e-3  # another's discontinuity index: it is
