"""localization on bad input (issue 29): nothing but VrechoError escapes, no NaN in any answer,
every argument checked before the work, and no source where no coherent source exists."""

import time
from datetime import timedelta

import numpy as np
import pytest
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st

from localization import Capture, doa, locate, place_sources, separate
from localization.capture import MAX_COORD_M
from localization.locate import MAX_SOURCES, Votes
from vrecho.device import MIC_ARRAYS, DevicePose
from vrecho.errors import VrechoError
from vrecho.signals import SPEED_OF_SOUND

FS = 16000
HEADSET = np.array(MIC_ARRAYS["headset4"].offsets)
BOX = ((0.0, 0.0, 0.0), (4.0, 4.0, 2.5))


def _poses(n: int) -> list[DevicePose]:
    """``n`` poses on an arc of 1.2 m radius around (1.5, 1.5), facing along it."""
    a = np.linspace(0, 0.5 * np.pi, n)
    return [DevicePose([1.5 + 1.2 * np.cos(t), 1.5 + 1.2 * np.sin(t), 1.5], [-np.sin(t), np.cos(t), 0], [0, 0, 1])
            for t in a]


def _noise_captures(n: int, seconds: float, seed: int = 0) -> list[Capture]:
    """Independent Gaussian noise on each of the headset's 4 microphones, at ``n`` poses."""
    rng = np.random.default_rng(seed)
    return [Capture.at_pose(0.01 * rng.standard_normal((4, int(seconds * FS))), FS, p) for p in _poses(n)]


def _play(mics: np.ndarray, position: np.ndarray, n: int, fs: int, rng, snr_db: float) -> np.ndarray:
    """Bursts of white noise (100 ms on, 100 ms off) played at ``position`` in free field (exact
    fractional delays, 1/r), ``n`` samples at each of ``mics`` over independent microphone noise
    ``snr_db`` down."""
    pad = fs // 8  # the 20 m of travel the FFT's circular delay may wrap
    gate = (np.arange(n + pad) // (fs // 10)) % 2
    src = np.fft.rfft(rng.standard_normal(n + pad) * gate)
    f = np.fft.rfftfreq(n + pad, 1 / fs)
    r = np.maximum(np.linalg.norm(mics - position, axis=1), 0.01)
    heard = np.fft.irfft(src[None] * np.exp(-2j * np.pi * f[None] * r[:, None] / SPEED_OF_SOUND) / r[:, None],
                         n + pad)[:, pad:]
    return heard + rng.standard_normal(heard.shape) * heard.std() * 10 ** (-snr_db / 20)


def _point_source(position, n_captures: int, seconds: float, snr_db: float, seed: int = 0) -> list[Capture]:
    """:func:`_play` at ``position``, heard by the headset at ``n_captures`` poses."""
    rng = np.random.default_rng(seed)
    mics = [pose.microphones(MIC_ARRAYS["headset4"]) for pose in _poses(n_captures)]
    return [Capture(_play(m, position, int(seconds * FS), FS, rng, snr_db), FS, m) for m in mics]


# -- regression tests, one per failure the issue names -------------------------------------------


def test_independent_noise_gives_no_source():
    """Issue 29: independent noise on each microphone gave 4 "sources" with confidence up to 1."""
    caps = _noise_captures(3, 0.5)
    found = locate(caps, bounds=BOX)
    assert found.positions.shape == (0, 3) and found.strength.shape == (0,) and found.directions.shape == (3, 0, 3)
    assert place_sources(caps, 2, bounds=BOX) == []  # not even when 2 are asked for
    assert locate(caps[:1], 1).positions.shape == (0, 3)  # one capture alone, the default box


@pytest.mark.parametrize("n_mics", [2, 4, 9])
def test_noise_stays_under_the_null_bound(n_mics):
    """The analytic bound (Chernoff, Beta(1, M - 1) votes) sits above what simulated incoherent
    noise reaches, for arrays of 2 to 9 microphones, short captures and unequal levels."""
    rng = np.random.default_rng(n_mics)
    mics = rng.uniform(-0.1, 0.1, (n_mics, 3)) + [2.0, 2.0, 1.5]
    audio = rng.standard_normal((n_mics, int(0.3 * FS))) * rng.uniform(0.2, 2.0, (n_mics, 1))
    votes = Votes([Capture(audio, FS, mics)])
    assert votes.maps[0].max() < votes.null_peak(1) < votes.null_peak(10 ** 6) < 1


def test_a_real_source_is_still_found():
    """A coherent source 10 dB over the microphones' noise stands clear of the bound: found where
    it is, from a few short captures and from a single one."""
    where = np.array([3.0, 3.2, 1.2])
    caps = _point_source(where, 3, 0.4, 10.0)
    found = locate(caps, bounds=BOX)
    assert len(found.positions) >= 1 and np.linalg.norm(found.positions[0] - where) < 0.3
    assert np.all(np.isfinite(found.uncertainty_m)) and np.isclose(found.strength[0], 1.0)
    one = locate(caps[:1], 1, bounds=BOX)  # one capture: a direction, not a range
    assert len(one.positions) == 1 and one.uncertainty_m[0] == np.inf
    u = (where - caps[0].center) / np.linalg.norm(where - caps[0].center)
    assert np.degrees(np.arccos(one.directions[0, 0] @ u)) < 10


def _diffuse(mics: np.ndarray, n: int, rng, n_waves: int = 300) -> np.ndarray:
    """A diffuse field: ``n_waves`` independent white-noise plane waves from random directions
    (exact fractional delays), ``n`` samples at each of ``mics``, RMS 0.01."""
    f = np.fft.rfftfreq(n, 1 / FS)
    spec = np.zeros((len(mics), len(f)), complex)
    for _ in range(n_waves):
        u = rng.standard_normal(3)
        spec += np.fft.rfft(rng.standard_normal(n))[None] * np.exp(
            2j * np.pi * f[None] * (mics @ (u / np.linalg.norm(u)))[:, None] / SPEED_OF_SOUND)
    x = np.fft.irfft(spec, n)
    return 0.01 * x / x.std()


def test_what_the_array_hears_in_its_own_frame_gets_no_confidence():
    """Diffuse noise (coherent across the array at low frequencies) and crosstalk (one signal on
    every channel) were each placed as a source of confidence 1 (the independent-noise bound sat
    at a tenth of their peak); they turn with the head, a source stays put: confidence 0. A
    source 0 dB over the same diffuse field is found, with confidence."""
    rng = np.random.default_rng(0)
    n = int(1.0 * FS)
    mics = [p.microphones(MIC_ARRAYS["headset4"]) for p in _poses(4)]
    hiss = 1e-4 * rng.standard_normal((4, n))
    diffuse = [Capture(_diffuse(m, n, rng) + hiss, FS, m) for m in mics]
    common = rng.standard_normal(n) * 0.01
    crosstalk = [Capture(common + hiss, FS, m) for m in mics]
    for caps in (diffuse, crosstalk):
        assert locate(caps, bounds=BOX).agreement <= 1.0
        assert all(s.confidence == 0.0 for s in place_sources(caps, 1, bounds=BOX))
    where = np.array([3.0, 3.2, 1.2])
    played = [_play(m, where, n, FS, rng, 40) for m in mics]
    heard = [Capture(0.01 * x / x.std() + c.audio, FS, c.mics) for x, c in zip(played, diffuse)]
    found = locate(heard, bounds=BOX)
    assert len(found.positions) >= 1 and np.linalg.norm(found.positions[0] - where) < 0.5
    assert found.agreement > 1.2
    assert place_sources(heard, 1, bounds=BOX)[0].confidence > 0.6


def test_separation_position_on_a_microphone():
    """Issue 29: a source position on a microphone returned 47 360 NaN samples."""
    cap = _point_source(np.array([3.0, 3.2, 1.2]), 1, 0.25, 10.0)[0]
    for positions in ([cap.mics[0], [3.0, 3.2, 1.2]], [cap.mics[1] + [0.0005, 0, 0], cap.mics[2]]):
        y = separate(cap, 2, method="informed", positions=np.array(positions))
        assert y.shape == (2, cap.audio.shape[1]) and np.all(np.isfinite(y))


def test_checks_come_before_the_work():
    """Issue 29: place_sources(n_sources=100) failed after 80 s; every check now comes first."""
    caps = _noise_captures(2, 0.5)
    cases = [
        (lambda: place_sources(caps, n_sources=100), r"n_sources: expected a whole number from 1 to 4"),
        (lambda: place_sources(caps, n_sources=0), "from 1 to 4"),
        (lambda: place_sources(caps, n_sources=2.5), "whole number"),
        (lambda: place_sources(caps, method="nmf"), "place_sources separates with"),
        (lambda: place_sources(caps, bounds=((0, 0, 0), (np.nan, 1, 1))), "bounds"),
        (lambda: place_sources(caps, bounds=((0, 0, 0), (-1, 1, 1))), "bounds"),
        (lambda: place_sources(caps, bounds=((0, 0, 0), (1e9, 1e9, 1e9))), "bounds"),
        (lambda: place_sources(caps, bounds="room"), "bounds"),
        (lambda: locate(caps, n_sources=100), f"from 1 to {MAX_SOURCES}"),
        (lambda: locate(caps, n_sources=-5), f"from 1 to {MAX_SOURCES}"),
        (lambda: locate(caps, max_sources=0), "max_sources"),
        (lambda: locate(caps, min_strength=float("nan")), "min_strength"),
        (lambda: locate(caps, step_m=0.0), "step_m"),
        (lambda: locate(caps, step_m=0.01, bounds=((0, 0, 0), (100, 100, 10))), "points"),
        (lambda: locate(caps, step_m="fine"), "step_m"),
        (lambda: locate(42), "captures"),
        (lambda: locate([caps[0], "capture"]), r"captures\[1\]"),
        (lambda: separate(caps[0], 2, method="auxiva", n_iter=-3), "n_iter"),
        (lambda: separate(caps[0], 2, method="informed", positions=[[0, 0, 0], [np.inf, 0, 0]]), "positions"),
        (lambda: separate(caps[0], 2, method="informed", positions=[[0, 0, 0]]), "positions"),
        (lambda: separate(caps[0], 2, method="informed", positions=[["a", 0, 0], [0, 0, 0]]), "positions"),
        (lambda: separate(caps[0], 2, method="informed", positions=[[1, 0, 0], [0, 1, 0]], uncertainty_m=[0.1]), "uncertainty_m"),
        (lambda: separate(caps[0], 2, method="informed", positions=[[1, 0, 0], [0, 1, 0]], uncertainty_m=[0.1, -1]),
         "uncertainty_m"),
        (lambda: separate(caps[0], 2, method="informed", positions=[[1, 0, 0], [0, 1, 0]], uncertainty_m=[np.nan, 0.1]),
         "uncertainty_m"),
        (lambda: separate(caps[0], 2, method="informed", positions=[[1, 0, 0], [0, 1, 0]], uncertainty_m="sure"),
         "uncertainty_m"),
        (lambda: separate(caps[0], 200, method="nmf"), "n_sources"),
        (lambda: separate(caps[0], None, method="nmf"), "n_sources"),
        (lambda: doa(caps[0], 1, method="SRP", n_grid=1), "n_grid"),  # was qhull's error
        (lambda: doa(caps[0], 1, method="TOPS", n_freq=1), "n_freq"),  # was pyroomacoustics' ValueError
        (lambda: doa(caps[0], "2"), "n_sources"),
    ]
    for call, match in cases:
        t = time.perf_counter()
        with pytest.raises(VrechoError, match=match):
            call()
        assert time.perf_counter() - t < 1.0, match


def test_capture_arrays():
    """Dtype, shape, finite samples, silence, a dead microphone, too short for the STFT, geometry."""
    rng = np.random.default_rng(0)
    x = rng.standard_normal((4, 8000))
    mics = HEADSET + [1, 1, 1.5]
    bad = [
        (x > 0, mics, "real numbers"),
        (x + 1j * x, mics, "real numbers"),
        (x.astype(str), mics, "real numbers"),
        ([x[0], "noise", x[2], x[3]], mics, "different lengths|real numbers"),
        (x[0], mics, "channels, samples"),
        (x[None], mics, "channels, samples"),
        (np.zeros((0, 8000)), np.zeros((0, 3)), "at least one channel"),
        (np.where(np.arange(8000) == 7, np.inf, x), mics, "NaN or infinite"),
        (np.zeros((4, 8000)), mics, "silent"),
        (np.vstack([x[:3], np.zeros((1, 8000))]), mics, "channel 3 is silent"),
        (x[:, :300], mics, "under 0.25 s"),  # shorter than every STFT window localization uses
        (x * 1e300, mics, "within"),
        (x, mics[[0, 1, 2, 2]], "same position"),
        (x, mics + [0, 0, np.nan], "finite"),
        (x, mics + 1e9, "within"),
        (x, mics[:, :2], "one per channel"),
        (x, "headset", "real numbers"),
    ]
    for audio, m, match in bad:
        with pytest.raises(VrechoError, match=match):
            Capture(audio, FS, m)
    with pytest.raises(VrechoError, match="start_s"):
        Capture(x, FS, mics, start_s=float("nan"))
    with pytest.raises(VrechoError, match="pose"):
        Capture.at_pose(x, FS, "standing")
    with pytest.raises(VrechoError, match="at least 2"):
        locate([Capture(x[:1], FS, mics[:1])])
    assert Capture(np.round(x * 1000).astype(np.int16), FS, mics).audio.dtype == np.float64  # int16 is fine


# -- properties: only VrechoError, no NaN, bounded time ------------------------------------------

def _finite(*arrays):
    for a in arrays:
        assert np.all(np.isfinite(np.asarray(a, dtype=float))), a


def _answer(call, limit_s: float = 20.0):
    """``call()``'s answer, or None where it raised VrechoError (anything else fails the test),
    within ``limit_s`` seconds either way."""
    t = time.perf_counter()
    try:
        return call()
    except VrechoError as e:
        event(f"refused: {str(e).split(':')[0]}")
        return None
    finally:
        assert time.perf_counter() - t < limit_s


COUNTS = st.none() | st.integers(1, 4) | st.integers(-5, 200)  # mostly in range, so the work is done
FAST = settings(max_examples=50, deadline=timedelta(seconds=20), derandomize=True, database=None,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])


@st.composite
def arrays(draw):
    """2 to 10 microphones' offsets within 15 cm, a third of the time all at one height."""
    rng = np.random.default_rng(draw(st.integers(0, 2 ** 16)))
    offsets = rng.uniform(-0.15, 0.15, (draw(st.sampled_from([2, 3, 4, 4, 9, 10])), 3))
    if draw(st.integers(0, 2)) == 0:
        offsets[:, 2] = 0.0
    return offsets


@st.composite
def walks(draw, most: int = 3):
    """1 to ``most`` captures of one array at one rate (:func:`captures`), those refused left out."""
    array, fs = draw(arrays()), draw(st.sampled_from([FS, FS, 8000, 24000]))
    return [c for c in draw(st.lists(captures(array, fs), min_size=1, max_size=most)) if c is not None]


DEFECTS = ("silent", "dead", "nan", "inf", "short", "1-D", "3-D", "rows", "bool", "complex", "object", "coincident",
           "mic nan", "mic far", "one mic", "fs")


@st.composite
def captures(draw, array=None, fs=None):
    """A capture, or None where the arguments drawn are refused (as they must be): 2 to 10
    microphones (``array``'s offsets, or a random array, sometimes flat) somewhere in the room,
    0.25 to 0.5 s at ``fs`` (or 8, 16 or 24 kHz) of noise, a point source, a tone on every
    microphone or clipped noise, at any level and in several dtypes, a third of the time with
    one defect of ``DEFECTS``."""
    rng = np.random.default_rng(draw(st.integers(0, 2 ** 16)))
    defect = draw(st.sampled_from(("none",) * 2 * len(DEFECTS) + DEFECTS))
    if array is None:
        array = draw(arrays())
    mics = array[:1] if defect == "one mic" else array
    mics = rng.uniform(0.5, 3.5, 3) + mics
    m = len(mics)
    fs = fs or draw(st.sampled_from([FS, FS, 8000, 24000]))
    n = int(draw(st.sampled_from([0.25, 0.3, 0.5])) * fs)
    content = draw(st.sampled_from(["noise", "source", "tone", "clipped"]))
    if content == "source":
        audio = _play(mics, rng.uniform([0, 0, 0], [4, 4, 2.5]), n, fs, rng, 10.0)
    else:
        audio = rng.standard_normal((m, n)) * rng.uniform(0.3, 3, (m, 1))
        if content == "tone":  # the same tone on every microphone: coherent, from no direction
            audio = 1e-3 * audio + np.sin(2 * np.pi * 1000 * np.arange(n) / fs)
        elif content == "clipped":
            audio = np.clip(audio, -0.2, 0.2)
    audio = audio * draw(st.sampled_from([1.0, 1e-5, 1e5, 1e10]))
    dtype = draw(st.sampled_from([np.float64, np.float32, np.int32]))
    audio = audio.astype(dtype) if dtype != np.int32 else np.round(audio / np.abs(audio).max() * 2e9).astype(dtype)
    if defect in ("silent", "dead"):
        audio[-1 if defect == "dead" else slice(None)] = 0
    elif defect in ("nan", "inf"):
        audio = audio.astype(float)
        audio.flat[rng.integers(audio.size)] = np.nan if defect == "nan" else -np.inf
    elif defect == "short":
        audio = audio[:, :draw(st.sampled_from([0, 1, 511, int(0.25 * fs) - 1]))]
    elif defect in ("1-D", "3-D", "rows"):
        audio = {"1-D": audio[0], "3-D": audio[None], "rows": audio[:-1]}[defect]
    elif defect in ("bool", "complex", "object"):
        audio = audio > 0 if defect == "bool" else audio.astype(complex if defect == "complex" else object)
    elif defect == "coincident":
        mics[-1] = mics[0] + draw(st.floats(0, 9e-4))
    elif defect == "mic nan":
        mics[rng.integers(m), rng.integers(3)] = draw(st.sampled_from([np.nan, np.inf]))
    elif defect == "mic far":
        mics = mics + draw(st.sampled_from([2e6, 1e300]))
    elif defect == "fs":
        fs = draw(st.sampled_from([0, 7999, -16000, 16000.5, float("nan")]))
    try:
        return Capture(audio, fs, mics)
    except VrechoError:
        assert defect != "none", "a valid capture refused"
        return None


@FAST
@given(caps=walks(), n_sources=COUNTS,
       bounds=st.sampled_from([None, BOX, BOX, ((0, 0, 0), (0, 0, 0)), ((-1e7, 0, 0), (1e7, 1, 1)), "box"]))
def test_locate_property(caps, n_sources, bounds):
    if not caps:
        return
    found = _answer(lambda: locate(caps, n_sources, bounds=bounds))
    if found is None:
        return
    k = len(found.positions)
    event(f"{k} sources")
    assert found.positions.shape == (k, 3) and found.directions.shape == (len(caps), k, 3)
    assert k <= (n_sources or 4)
    _finite(found.positions, found.strength, found.directions)
    assert not np.any(np.isnan(found.uncertainty_m))


@settings(FAST, max_examples=100)
@given(cap=captures(), n_sources=COUNTS, method=st.sampled_from(["informed", "auxiva", "nmf", "ilrma", "x"]),
       where=st.sampled_from(["mic", "near", "nan", "outside", "far", "room"]), seed=st.integers(0, 2 ** 16))
def test_separate_property(cap, n_sources, method, where, seed):
    if cap is None:
        return
    n_sources = 2 if n_sources is None else n_sources
    rng = np.random.default_rng(seed)
    k = max(1, min(n_sources, 4))
    positions = rng.uniform(0, 4, (k, 3))
    if where == "mic":
        positions[0] = cap.mics[rng.integers(cap.n_mics)]
    elif where == "near":
        positions[0] = cap.mics[0] + rng.uniform(-1e-3, 1e-3, 3)
    elif where == "nan":
        positions[-1, 1] = np.nan
    elif where == "outside":
        positions *= 100
    elif where == "far":
        positions[0] = [MAX_COORD_M * 2, 0, 0]
    y = _answer(lambda: separate(cap, n_sources, method=method, positions=positions, n_iter=5))
    if y is None:
        return
    event("separated")
    assert y.shape == (n_sources, cap.audio.shape[1])
    _finite(y)


@settings(FAST, max_examples=20)
@given(caps=walks(2), n_sources=COUNTS, method=st.sampled_from(["informed", "auxiva"]))
def test_place_sources_property(caps, n_sources, method):
    if not caps:
        return
    placed = _answer(lambda: place_sources(caps, n_sources, bounds=BOX, method=method), 30.0)
    if placed is None:
        return
    event(f"{len(placed)} sources")
    for p in placed:
        _finite(p.position, p.signal, [p.confidence])
        assert 0 <= p.confidence <= 1 and (p.uncertainty_m is None or np.isfinite(p.uncertainty_m))
