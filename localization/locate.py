"""Where the sources are: direction of arrival per capture, and world positions across captures.

Two ways, compared side by side in ``benchmarks/bench_localization.py``:

- **Per capture** (:func:`doa`, a pyroomacoustics method: MUSIC, NormMUSIC, SRP, CSSM, WAVES,
  TOPS): each capture gives ``k`` directions on a sphere grid.
- **vrecho's** (:func:`locate`): every capture at once. In each capture, the onset
  time-frequency bins (where the direct sound dominates the room's reverberation) vote for the
  directions whose plane wave explains them (normalised beam power to the 8th power: mixed,
  reverberant or aliased bins count little). A world point's score is the mean, over captures,
  of each capture's votes toward it: a true source gathers the votes of every capture, a
  crossing of two captures' directions only theirs. Sources are taken one at a time: the best
  point on a 10 cm grid, refined to a few millimetres; then each bin gives up its vote as far as
  that source explains it (its weight times the share left unexplained, squared:
  :data:`LEFT_POWER`), and the next map is made, away from the sources found (sources closer than
  0.75 m are one to this array). Without a given count, a next peak weaker than ``min_strength``
  times the first ends the search, as does one that not every capture hears
  (:data:`MIN_SUPPORT`): a source raises each capture's map toward it, what a found source left
  behind or a crossing of some captures' directions only some. Then each source is sought again,
  the whole grid over, with the others explained (:data:`CYCLES`): the first was placed on a map
  the others still voted on, where a crossing of two sources' directions or a hum's grating lobes
  can outvote the truth. A source moves only where the sources together then explain more of the
  captures' clear votes (:meth:`Votes.explained`). Each position's standard error comes from
  triangulating each capture's own best direction near it (least squares); the directions
  reported per capture point at the joint positions.

The strongest peak must stand clear of incoherent noise (:meth:`Votes.null_peak`), or there is
no source at all; later peaks are judged against it as above (the bound is the whole map's, and
the maps a found source has explained are thinner). Where
the microphones hear independent noise, a bin's normalised beam power toward any direction is
Beta(1, M - 1) distributed whatever the array's shape or the frequency, so the map's mean is
known exactly (4 microphones: 0.006) and Chernoff's bound bounds how far the peak of a map of
that many bins can rise above it by chance; a peak under that bound (one chance in a
thousand of noise alone reaching it over the whole grid) is not a source, whatever the count
asked for. Independent noise on every microphone thus gives no source.

What the captures agree on in their own frame rather than in the world is weighed too: a
diffuse field (noise from everywhere, its low frequencies coherent across the array), crosstalk
common to every channel, the array's own response. Those turn with the head; a source stays
put. Each capture's map is turned about the vertical by a random angle of its own
(:data:`SCRAMBLES` seeded draws) and the world map's peak is set against the best peak of the
turned maps: their ratio, ``agreement``, is at most 1 for diffuse noise and crosstalk, 1.1 to
1.5 for the benchmark's rooms up to RT60 0.7 s and 1.2 to 2.4 for a source 0 to 20 dB over a
diffuse field (2 to 8 captures). It is not a gate (in the most reverberant rooms true sources
fall under 1 too) but :func:`localization.place_sources`' confidence. One capture alone cannot
be tested so (NaN).

Positions are in the captures' world frame (metres); directions are unit vectors from each
capture's array centre.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import minimize_scalar

from vrecho.errors import VrechoError, check_count, check_number
from vrecho.signals import SPEED_OF_SOUND

from .capture import FS, MAX_COORD_M, Capture
from .onsets import onset_bins
from .triangulate import triangulate

BAND_HZ = (200.0, 7000.0)
NFFT = 512
"""STFT length for direction finding (32 ms at 16 kHz), hop NFFT / 2."""
MIN_SEPARATION_M = 0.75
CYCLES = 1
"""Rounds in which :func:`locate` searches for each source found again, the others explained
(it moves only where the sources together then explain more of the votes)."""
MIN_RANGE_M = 0.05
"""No source is sought closer than this to a capture's array centre: it has no direction there."""
MAX_SOURCES = 8
"""The most sources :func:`locate` seeks: past a handful the next peaks are the found sources'
reflections and residue, not sources."""
MAX_GRID_POINTS = 5_000_000
"""The most points of the search grid (a 0.1 m grid over a box of 50 x 50 x 20 m): beyond it
the maps would take gigabytes; a coarser ``step_m`` or tighter ``bounds`` keeps under it."""
FALSE_ALARM = 1e-3
"""The chance, over the whole search, that incoherent noise alone gives a source."""
SCRAMBLES = 19
"""How many times each capture's map is turned at random for the agreement test."""
BIN_OVERLAP = 2.0
"""How many onset bins count as one independent draw in the null bound: neighbouring frames
overlap by half and neighbouring frequencies leak into each other through the Hann window."""
MIN_SUPPORT = 1.35
"""Without a given count, a next peak whose captures' maps stand, in the geometric mean over
captures, less than this many times over their own mean toward it (:meth:`Votes.support`) ends
the search."""
LEFT_POWER = 2
"""A bin a found source explains to a score s (the share of its power that source's plane wave
accounts for) keeps (1 - s) ** LEFT_POWER of its vote (:meth:`Votes.explain`). Squared, a bin
that peaks beside the source rather than on it (a hum's broad lobe bent by the room, a crossing
of two directions) gives up most of its vote: with 1 - s^2, as before, such bins left a ridge
just outside the found source's :data:`MIN_SEPARATION_M` that the next search took for a second
source (on 80 tuning walks, seeds 9000 +, the count given: within 0.5 m 138 -> 149 of 210
sources, the 3-D median 0.23 -> 0.18 m; cubed, on the first 40 of them, 70 -> 64 %)."""


@dataclass
class Located:
    """What :func:`locate` found: K sources.

    Parameters
    ----------
    positions : numpy.ndarray [shape=(K, 3)]
        World positions in metres.
    uncertainty_m : numpy.ndarray [shape=(K,)]
        Each position's uncertainty in metres: the norm of ``uncertainty_axes_m`` (``inf`` where
        it is unknown: fewer than three captures, or all of them in line with the source).
    uncertainty_axes_m : numpy.ndarray [shape=(K, 3)]
        The same along the world's x, y and z: the triangulation's standard error on each axis,
        widened to half the extent of every other place the map rates nearly as high
        (:data:`AMBIGUOUS_SHARE` of the peak): a flat array at one height hears a source above
        it as one below it, and says so on z until the head's pitch and roll tell them apart.
    strength : numpy.ndarray [shape=(K,)]
        Each source's map power at its position, the sources before it explained, over the
        first's (the first is 1; a source moved by the second look may exceed it).
    agreement : float
        The world map's peak over the best peak of the captures' maps each turned at random
        (the module's docstring; NaN for a single capture or where no source was found).
    directions : numpy.ndarray [shape=(captures, K, 3)]
        Unit vectors from each capture's array centre to each position.
    """

    positions: np.ndarray
    uncertainty_m: np.ndarray
    strength: np.ndarray
    directions: np.ndarray
    agreement: float = float("nan")
    uncertainty_axes_m: np.ndarray | None = None


def check_captures(captures) -> list[Capture]:
    """The captures as a list, checked for direction finding.

    Parameters
    ----------
    captures : Capture or iterable of Capture
        One capture or several.

    Returns
    -------
    list of Capture

    Raises
    ------
    VrechoError
        For no captures, an item that is not a :class:`Capture`, a capture with fewer than 2
        microphones, or captures at different sample rates.
    """
    if isinstance(captures, Capture):
        captures = [captures]
    try:
        captures = list(captures)
    except TypeError:
        raise VrechoError(f"captures: expected a Capture or an iterable of them, got {type(captures).__name__}") from None
    if not captures:
        raise VrechoError("captures: none given")
    for i, c in enumerate(captures):
        if not isinstance(c, Capture):
            raise VrechoError(f"captures[{i}]: expected a localization.Capture, got {type(c).__name__}")
        if c.n_mics < 2:
            raise VrechoError(f"captures[{i}]: {c.n_mics} microphone; direction finding needs at least 2 "
                              "(a single microphone gives only EchoCNN's position head)")
    if len({c.fs for c in captures}) > 1:
        raise VrechoError(f"captures: different sample rates {sorted({c.fs for c in captures})}")
    return captures


def stft(audio: np.ndarray, *, nfft: int = NFFT) -> np.ndarray:
    """Short-time spectra, Hann window, hop nfft / 2.

    Parameters
    ----------
    audio : numpy.ndarray [shape=(M, N)]
        The samples, one row per microphone.
    nfft : int
        Frame length in samples (default :data:`NFFT`, 512).

    Returns
    -------
    numpy.ndarray [shape=(M, nfft // 2 + 1, T), dtype=complex128]
        One frame per hop that fits wholly in the samples.
    """
    hop = nfft // 2
    n = audio.shape[1]
    n_frames = max(1, 1 + (n - nfft) // hop)
    idx = np.arange(nfft)[None] + hop * np.arange(n_frames)[:, None]
    frames = audio[:, idx] * np.hanning(nfft)
    return np.fft.rfft(frames, axis=-1).transpose(0, 2, 1)


def band_bins(fs: int, nfft: int = NFFT) -> np.ndarray:
    """Which of an ``nfft``-point STFT's bins at ``fs`` lie in :data:`BAND_HZ` (and under 0.45 ``fs``).

    Parameters
    ----------
    fs : int
        The sample rate in Hz.
    nfft : int
        The STFT's length (default :data:`NFFT`).

    Returns
    -------
    numpy.ndarray [shape=(nfft // 2 + 1,), dtype=bool]
    """
    f = np.fft.rfftfreq(nfft, 1 / fs)
    return (f >= BAND_HZ[0]) & (f <= min(BAND_HZ[1], 0.45 * fs))


def grid_points(lo: np.ndarray, hi: np.ndarray, step: float) -> np.ndarray:
    """The points of a regular grid over a box.

    Parameters
    ----------
    lo, hi : numpy.ndarray [shape=(3,)]
        The box's low and high corners in metres.
    step : float
        The grid's spacing in metres; each axis runs from ``lo`` up to ``hi`` inclusive.

    Returns
    -------
    numpy.ndarray [shape=(P, 3)]
        The points, in metres.
    """
    axes = [np.arange(a, b + 1e-9, step) for a, b in zip(lo, hi)]
    return np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, 3)


def search_box(captures: list[Capture], *, bounds=None) -> tuple[np.ndarray, np.ndarray]:
    """Where sources are sought: ``bounds`` if given (the reconstructed room), else the captures'
    extent grown by 4 m across, 2 m down and 1.5 m up.

    Parameters
    ----------
    captures : list of Capture
        The captures; their array centres set the default box.
    bounds : tuple of two array_like [shape=(3,)], optional
        The box's (low corner, high corner) in metres.

    Returns
    -------
    lo, hi : numpy.ndarray [shape=(3,)]
        The box's corners in metres.

    Raises
    ------
    VrechoError
        For ``bounds`` that are not two finite 3-vectors within :data:`MAX_COORD_M` of the
        origin with low < high on every axis.
    """
    if bounds is not None:
        try:
            lo, hi = (np.asarray(b, dtype=float) for b in bounds)
        except (TypeError, ValueError):
            lo = hi = np.zeros(0)
        if lo.shape != (3,) or hi.shape != (3,) or not np.all(np.isfinite([lo, hi])) or np.any(hi <= lo) \
                or np.max(np.abs([lo, hi])) > MAX_COORD_M:
            raise VrechoError(f"bounds: expected (low corner, high corner), each 3 finite numbers within {MAX_COORD_M:g} m "
                              f"of the origin with low < high, got {bounds!r}")
        return lo, hi
    centers = np.array([c.center for c in captures])
    return centers.min(0) - np.array([4.0, 4.0, 2.0]), centers.max(0) + np.array([4.0, 4.0, 1.5])


def _power(votes: "Votes", points: np.ndarray, found) -> np.ndarray:
    """The world map at ``points``, ``-inf`` within ``MIN_SEPARATION_M`` of a source ``found``
    and within ``MIN_RANGE_M`` of a capture's array centre."""
    p = votes.power(points)
    for y, r in [(y, MIN_SEPARATION_M) for y in found] + [(c.center, MIN_RANGE_M) for c in votes.captures]:
        p[np.linalg.norm(points - y, axis=1) < r] = -np.inf
    return p


def _refine(votes: "Votes", x: np.ndarray, lo, hi, step: float, found=()) -> np.ndarray:
    """Climb from grid point ``x`` on ever finer grids, where :func:`_power` allows."""
    for s in (step / 2, step / 4, step / 8, step / 16):
        pts = np.clip(grid_points(x - 2 * s, x + 2 * s, s), lo, hi)
        p = _power(votes, pts, found)
        if np.isfinite(p.max()):
            x = pts[int(np.argmax(p))]
    return x


def _sphere(n: int) -> np.ndarray:
    """``n`` near-uniform unit vectors (Fibonacci lattice)."""
    i = np.arange(n) + 0.5
    z = 1 - 2 * i / n
    phi = np.pi * (1 + 5 ** 0.5) * i
    r = np.sqrt(1 - z * z)
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], -1)


AMBIGUOUS_SHARE = 0.9
"""The share of a source's map peak from which another place of the map (nearer to it than to
any other source found) counts as where it might be (:attr:`Located.uncertainty_axes_m`)."""


def _pose_direction(votes: "Votes", k: int, x: np.ndarray, sphere: np.ndarray, cone_deg: float = 12.0) -> np.ndarray:
    """Capture ``k``'s own best direction among ``sphere``'s unit vectors within ``cone_deg`` of
    the point ``x``."""
    c = votes.captures[k].center
    u0 = (x - c) / np.linalg.norm(x - c)
    dirs = sphere[sphere @ u0 > np.cos(np.radians(cone_deg))]
    return dirs[int(np.argmax(votes.lookup(k, dirs)))]


class Votes:
    """Each capture's onset time-frequency bins, each voting for the directions that explain it.

    A bin's score for a direction is its normalised beam power |a^H x|^2 / (M |x|^2), 1 when one
    plane wave from there explains the bin exactly. Only onsets vote
    (:func:`~localization.onsets.onset_bins`: a bin louder than the same frequency over the
    previous frames): there the direct sound dominates, where a few metres away the room's
    reverberation dominates the steady state. A bin's vote is its score raised to ``GAMMA``, so a bin where sources mix, or a
    narrowband bin whose grating lobes are nearly as good as the truth, counts little. A
    capture's direction map is the sum of its bins' votes; the world map at a point is the mean
    over captures of each one's map toward that point.

    Parameters
    ----------
    captures : list of Capture
        Checked captures (:func:`check_captures`), at one sample rate.

    Attributes
    ----------
    dirs : numpy.ndarray [shape=(D, 3)]
        The directions voted for: unit vectors on a grid of ``AZ_STEP`` degrees in azimuth and
        ``EL_STEP`` in elevation, up to ``EL_MAX`` either way.
    votes : list of numpy.ndarray [shape=(bins, D), dtype=float32]
        Each capture's onset bins' votes.
    weights : list of numpy.ndarray [shape=(bins,), dtype=float32]
        What is left of each bin's vote (1 until :meth:`explain` withdraws some).
    maps : list of numpy.ndarray [shape=(D,)]
        Each capture's direction map: its bins' weighted votes, over their count.
    """

    AZ_STEP, EL_STEP, EL_MAX = 4.0, 4.0, 84.0
    GAMMA = 8

    def __init__(self, captures: list[Capture]):
        self.captures = captures
        self.az = np.radians(np.arange(0.0, 360.0, self.AZ_STEP))
        self.el = np.radians(np.arange(-self.EL_MAX, self.EL_MAX + 1e-9, self.EL_STEP))
        A, E = np.meshgrid(self.az, self.el, indexing="ij")
        self.dirs = np.stack([np.cos(E) * np.cos(A), np.cos(E) * np.sin(A), np.sin(E)], -1).reshape(-1, 3)
        band = band_bins(FS) & (np.fft.rfftfreq(NFFT, 1 / FS) <= 0.45 * captures[0].fs)  # (an 8 kHz capture: to 3.6 kHz)
        freqs = np.fft.rfftfreq(NFFT, 1 / FS)[band]
        self.votes, self.weights = [], []
        for c in captures:
            # at localization's own rate, whatever the capture's: the band fits, and a bin keeps its
            # width and a frame its 32 ms (at 48 kHz NFFT samples were 11 ms and 94 Hz)
            X = stft(c.audio_at(FS))[:, band].astype(np.complex64)  # (M, F, T)
            energy = (np.abs(X) ** 2).sum(axis=0)  # (F, T)
            keep = onset_bins(energy)
            delays = self.dirs @ (c.mics - c.center).T / SPEED_OF_SOUND  # (D, M)
            rows = []
            for f in np.flatnonzero(keep.any(axis=1)):
                xf = X[:, f, keep[f]]  # (M, T_f)
                steer = np.exp(2j * np.pi * freqs[f] * delays).astype(np.complex64)
                beam = np.abs(np.conj(steer) @ xf) ** 2 / (c.n_mics * energy[f, keep[f]])
                rows.append((np.minimum(beam, 1.0) ** self.GAMMA).T.astype(np.float32))
            votes = np.concatenate(rows) if rows else np.zeros((0, len(self.dirs)), np.float32)
            self.votes.append(votes)
            self.weights.append(np.ones(len(votes), dtype=np.float32))
        self._best = [v.max(axis=1) for v in self.votes]  # each bin's best vote (explained)
        self._maps()

    def _maps(self):
        self.maps = [(w @ v) / max(len(w), 1) for v, w in zip(self.votes, self.weights)]

    def explained(self, points) -> float:
        """How much of the captures' clear votes sources at ``points`` account for together
        (whatever their order: each bin keeps the product of what each leaves it, as
        :meth:`explain` does): the sum over captures of the mean over bins of the bin's best vote
        times the share of it withdrawn.

        Parameters
        ----------
        points : list of numpy.ndarray [shape=(3,)]

        Returns
        -------
        float
        """
        total = 0.0
        for k in range(len(self.captures)):
            if not len(self.votes[k]):
                continue
            left = np.ones(len(self.votes[k]), dtype=np.float32)
            for x in points:
                left *= self._left(k, x)
            total += float(np.mean(self._best[k] * (1.0 - left)))
        return total

    def reset(self):
        """Every bin's whole vote back (undo :meth:`explain`)."""
        self.weights = [np.ones(len(v), dtype=np.float32) for v in self.votes]
        self._maps()

    def null_peak(self, n_points: int) -> float:
        """The world map's value that incoherent noise reaches anywhere on ``n_points`` points
        with a chance of at most :data:`FALSE_ALARM` (see the module's docstring).

        Under independent noise on a capture's M microphones a bin's score s toward any
        direction is Beta(1, M - 1) distributed, its vote V = s^GAMMA. The world map at a point
        is X = sum over captures k of the mean of its n_k votes, over K; counting a capture's
        bins as n_k / BIN_OVERLAP independent draws, Chernoff's bound with the votes' exact
        moment generating function, P(X >= t) <= exp(log E[exp(lam X)] - lam t) for every
        lam > 0, and a union bound over the points give the smallest t whose chance is under
        FALSE_ALARM / n_points. Unequal levels on the microphones, or noise with more of its
        power at some frequencies, give less.

        Parameters
        ----------
        n_points : int
            How many points the search looks at.

        Returns
        -------
        float
            The map's value; ``inf`` where no capture has a voting bin.
        """
        k = len(self.captures)
        n = np.array([len(w) / BIN_OVERLAP for w in self.weights])
        m = np.array([c.n_mics for c in self.captures])[n > 0]
        n = n[n > 0]
        if not len(n):
            return float("inf")
        # Beta(1, M - 1) on s = 1 - u: density (M - 1) u^(M - 2), nodes dense near u = 0 where
        # e^(theta s^GAMMA) peaks; trapezoid weights on the geometric nodes
        u = np.concatenate([[0.0], np.geomspace(1e-9, 1.0, 3000)])
        du = np.diff(u)
        w = np.concatenate([[du[0] / 2], (du[:-1] + du[1:]) / 2, [du[-1] / 2]])
        log_density = np.log(m[:, None] - 1.0) + (m[:, None] - 2.0) * np.log(np.maximum(u, 1e-300)) + np.log(w)
        log_density[:, 0] = np.where(m == 2, np.log(w[0]), -np.inf)  # u^0 = 1 at u = 0 only for M = 2
        v = (1.0 - u) ** self.GAMMA

        def log_mgf(lam: float) -> float:  # log E[exp(lam X)], X the map at one point
            theta = lam / (k * n)
            e = log_density + theta[:, None] * v
            top = e.max(axis=1)
            return float(np.sum(n * (top + np.log(np.exp(e - top[:, None]).sum(axis=1)))))

        log_p = np.log(max(n_points, 1) / FALSE_ALARM)
        best = minimize_scalar(lambda r: (log_mgf(np.exp(r)) + log_p) / np.exp(r), bounds=(-5.0, 25.0),
                               method="bounded", options={"xatol": 1e-4})
        return float(min(best.fun, 1.0))

    def lookup(self, k: int, u: np.ndarray) -> np.ndarray:
        """Capture ``k``'s map toward unit vectors, bilinear in azimuth and elevation.

        Parameters
        ----------
        k : int
            The capture's index.
        u : numpy.ndarray [shape=(N, 3)]
            Unit vectors (world frame); elevations beyond ``EL_MAX`` read the map's edge.

        Returns
        -------
        numpy.ndarray [shape=(N,)]
        """
        az = np.mod(np.arctan2(u[:, 1], u[:, 0]), 2 * np.pi) / np.radians(self.AZ_STEP)
        el = (np.clip(np.arcsin(np.clip(u[:, 2], -1, 1)), -np.radians(self.EL_MAX), np.radians(self.EL_MAX))
              + np.radians(self.EL_MAX)) / np.radians(self.EL_STEP)
        i0, j0 = np.floor(az).astype(int), np.minimum(np.floor(el).astype(int), len(self.el) - 2)
        fa, fe = az - i0, el - j0
        m = self.maps[k].reshape(len(self.az), len(self.el))
        i0, i1 = i0 % len(self.az), (i0 + 1) % len(self.az)
        return ((1 - fa) * (1 - fe) * m[i0, j0] + fa * (1 - fe) * m[i1, j0] + (1 - fa) * fe * m[i0, j0 + 1]
                + fa * fe * m[i1, j0 + 1])

    def power(self, points: np.ndarray) -> np.ndarray:
        """The world map at ``points``: the mean over captures of each one's map toward them.

        Parameters
        ----------
        points : numpy.ndarray [shape=(N, 3)]
            World points in metres.

        Returns
        -------
        numpy.ndarray [shape=(N,)]
        """
        return np.mean(self._toward(points), axis=0)

    def _toward(self, points: np.ndarray) -> np.ndarray:
        """Each capture's map toward world ``points``: shape (captures, N)."""
        out = []
        for k, c in enumerate(self.captures):
            d = points - c.center
            out.append(self.lookup(k, d / np.maximum(np.linalg.norm(d, axis=1, keepdims=True), 1e-9)))
        return np.array(out)

    def explain(self, point: np.ndarray):
        """Withdraw from every bin the share of its vote a source at ``point`` accounts for.

        Each bin's weight is multiplied by (1 - score) ** :data:`LEFT_POWER`, its score being
        its normalised beam power toward the grid direction nearest the point; the maps are made
        again.

        Parameters
        ----------
        point : numpy.ndarray [shape=(3,)]
            The source's world position in metres.
        """
        for k in range(len(self.captures)):
            self.weights[k] *= self._left(k, point)
        self._maps()

    def support(self, point: np.ndarray) -> float:
        """How far every capture's map toward ``point`` stands over its own mean: the geometric
        mean over captures (those with a voting bin) of each one's map toward the point over that
        map's mean, on the votes left. A source raises each capture's map toward it; a found
        source's residue, or a crossing of some captures' directions, only some.

        Parameters
        ----------
        point : numpy.ndarray [shape=(3,)]
            A world position in metres.

        Returns
        -------
        float
            0 where no capture has a voting bin.
        """
        means = np.array([m.mean() for m in self.maps])
        voting = means > 0
        if not voting.any():
            return 0.0
        ratios = self._toward(np.asarray(point, float)[None])[voting, 0] / means[voting]
        return float(np.exp(np.mean(np.log(np.maximum(ratios, 1e-30)))))

    def _left(self, k: int, point: np.ndarray) -> np.ndarray:
        """The share of each of capture ``k``'s bins' votes a source at ``point`` leaves them:
        (1 - score) ** :data:`LEFT_POWER`, the score toward the grid direction nearest it."""
        u = (point - self.captures[k].center) / np.linalg.norm(point - self.captures[k].center)
        score = self.votes[k][:, int(np.argmax(self.dirs @ u))] ** (1.0 / self.GAMMA)
        return (1.0 - score) ** LEFT_POWER  # (the votes are clipped at 1: so is the score)


def locate(captures, n_sources: int | None = None, *, bounds=None, step_m: float = 0.1,
           max_sources: int = 4, min_strength: float = 0.04) -> Located:
    """World positions of the sources heard across ``captures`` (see the module's docstring).

    Parameters
    ----------
    captures : Capture or iterable of Capture
        The walk's captures, at one sample rate, each with at least 2 microphones; heard at
        16 kHz (:data:`~localization.capture.FS`) whatever their rate, so that the answer does
        not depend on it.
    n_sources : int, optional
        The most sources to find, 1 to :data:`MAX_SOURCES` (None: estimated, at most
        ``max_sources``; a next peak weaker than ``min_strength`` times the first is not a
        source). Fewer come back where fewer peaks stand clear of incoherent noise.
    bounds : tuple of two array_like [shape=(3,)], optional
        The search box's (low corner, high corner) in metres (:func:`search_box`).
    step_m : float
        The search grid's spacing in metres, 0.01 to 1 (default 0.1), before refinement.
    max_sources : int
        The most sources an estimated count gives, 1 to :data:`MAX_SOURCES` (default 4).
    min_strength : float
        The share of the first source's map peak below which an estimated count stops, 0 to 1
        (default 0.04: with :data:`MIN_SUPPORT`, 50 % of 80 tuning walks, seeds 9000 +, counted
        right, against 34 % at 0.1 alone and 36 % at 0.25 before :data:`LEFT_POWER`; a lone
        voice's residue reaches 0.078 of it in the tests' small room, and only its captures'
        support, 1.21, keeps it one source).

    Returns
    -------
    Located
        The positions, their standard errors, strengths and directions from each capture, and
        the first peak's agreement; no source at all (K = 0) where no peak stands clear of
        incoherent noise (the module's docstring).

    Raises
    ------
    VrechoError
        Before any work: for bad captures (:func:`check_captures`), an ``n_sources`` that is
        neither None nor a whole number from 1 to :data:`MAX_SOURCES`, bad ``bounds``, a
        ``step_m``, ``max_sources`` or ``min_strength`` out of its range, or a search grid of
        more than :data:`MAX_GRID_POINTS` points.
    """
    captures = check_captures(captures)
    if n_sources is not None:
        check_count(n_sources, "n_sources", MAX_SOURCES)
    check_count(max_sources, "max_sources", MAX_SOURCES)
    min_strength = check_number(min_strength, "min_strength", lo=0.0, hi=1.0)
    step_m = check_number(step_m, "step_m", lo=0.01, hi=1.0)
    lo, hi = search_box(captures, bounds=bounds)
    n_points = int(np.prod(np.floor((hi - lo) / step_m + 1e-9) + 1))
    if n_points > MAX_GRID_POINTS:
        raise VrechoError(f"step_m: a {step_m} m grid over the box {lo.tolist()} to {hi.tolist()} m has {n_points:,} points "
                          f"(at most {MAX_GRID_POINTS:,}): give a coarser step_m or tighter bounds")
    grid = grid_points(lo, hi, step_m)
    votes = Votes(captures)
    every_vote = votes.maps  # kept for each capture's own direction once the sources are found
    floor = votes.null_peak(len(grid))
    found, strength, agreement = [], [], float("nan")
    limit = n_sources or max_sources
    while len(found) < limit:
        p = _power(votes, grid, found)  # two sources closer than MIN_SEPARATION_M are one to this array
        if not found:  # the first pass's map is the whole one, which the uncertainty below reads
            whole = p
        best = int(np.argmax(p))
        # The strongest peak must stand clear of incoherent noise; later ones are judged against it, on
        # maps that explain() has thinned (the floor, made for the whole map, is not theirs)
        if (not found and not p[best] > floor) or (n_sources is None and found and p[best] < min_strength * strength[0]):
            break
        if not found and len(captures) > 1:
            agreement = float(p[best]) / _turned_peak(votes, grid)
        x = _refine(votes, grid[best], lo, hi, step_m, found)
        if n_sources is None and found and votes.support(x) < MIN_SUPPORT:
            break  # not every capture hears it: a found source's residue, or a crossing
        found.append(x)
        strength.append(_claim(votes, x))
    if len(found) >= 2:
        found, strength = _cycle(votes, grid, lo, hi, step_m, found)
    votes.maps = every_vote
    centers = np.array([c.center for c in captures])
    positions = np.array(found).reshape(-1, 3)
    unc = np.full((len(found), 3), np.inf)
    if len(captures) >= 3 and len(found):
        sphere = _sphere(40000)
        owner = np.argmin(np.linalg.norm(grid[:, None] - positions[None], axis=-1), axis=1)
        for i, x in enumerate(positions):
            rays = np.array([_pose_direction(votes, k, x, sphere) for k in range(len(captures))])
            near = grid[(owner == i) & (whole >= AMBIGUOUS_SHARE * float(votes.power(x[None])[0]))]
            spread = np.abs(near - x).max(axis=0) / 2 if len(near) else np.zeros(3)
            unc[i] = np.hypot(triangulate(centers, rays, axes=True)[1], spread)
    d = positions[None] - centers[:, None]
    return Located(positions, np.linalg.norm(unc, axis=1), np.array(strength) / max(strength[:1], default=1.0),
                   d / np.linalg.norm(d, axis=-1, keepdims=True), agreement, unc)


def _cycle(votes: "Votes", grid: np.ndarray, lo, hi, step_m: float, found: list) -> tuple[list, list]:
    """Each source searched for again with the others explained (:data:`CYCLES` rounds), the
    whole grid over: the greedy search placed the first source on a map the others still voted
    on (a crossing of two sources' directions, or a hum's grating lobes, can outvote the
    truth there) and each later one on what its predecessors' explanation left. Returns the
    positions and their strengths, taken in order as the greedy search takes them."""
    found = list(found)
    explained = votes.explained(found)
    for _ in range(CYCLES):
        for i in range(len(found)):
            others = found[:i] + found[i + 1:]
            votes.reset()
            for y in others:
                votes.explain(y)
            p = _power(votes, grid, others)
            if np.isfinite(p.max()):
                x = _refine(votes, grid[int(np.argmax(p))], lo, hi, step_m, others)
                moved = votes.explained(others + [x])  # (order-free: what found explains once x is in it)
                if moved > explained:
                    found[i], explained = x, moved
    votes.reset()
    return found, [_claim(votes, x) for x in found]


def _claim(votes: "Votes", x: np.ndarray) -> float:
    """A source found at ``x``: its strength on the votes left, which it then explains."""
    strength = float(votes.power(x[None])[0])
    votes.explain(x)
    return strength


def _turned_peak(votes: "Votes", grid: np.ndarray) -> float:
    """The best world-map peak over :data:`SCRAMBLES` draws of each capture's map turned about
    the vertical by its own random angle (at least an eighth of a turn), seeded: what the
    captures agree on in their own frame reaches it."""
    maps = votes.maps
    n_az, n_el = len(votes.az), len(votes.el)
    rng = np.random.default_rng(20261124)
    best = 0.0
    try:
        for _ in range(SCRAMBLES):
            votes.maps = [np.roll(m.reshape(n_az, n_el), int(rng.integers(n_az // 8, n_az - n_az // 8)), axis=0).ravel()
                          for m in maps]
            best = max(best, float(_power(votes, grid, []).max()))
    finally:
        votes.maps = maps
    return max(best, 1e-30)
