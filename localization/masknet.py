"""The mask network of informed separation (:func:`localization.separate`, ``method="informed"``).

For each located source, every time-frequency bin of a capture (512-point STFT at 16 kHz, 8 ms
hop) gets a share from 0 to 1: how much of microphone 0's bin is that source. The network sees,
per bin, what the geometry says and what the spectrum looks like:

- microphone 0's log power (normalised per capture);
- the bin's coherence with the source's near-field steering vector (from its located position),
  and the largest coherence with any other source's;
- the log power of a linearly constrained beam that passes the source and nulls the other
  sources' direct paths (with the capture's own covariance), and the largest of the others';
- the bin's frequency.

A small U-shaped convolutional network (full frequency resolution at its ends, a quarter of it
in its dilated middle, whose receptive field spans about a second; 32 channels, 333 000
weights) turns them into the share. Its weights ship in ``localization/assets/masknet.pt``
(half precision, 0.7 MB); they were trained on 1 200 simulated walks
(:func:`vrecho.sim.ambient.random_walk`, seeds from 20 000: never the benchmark's 7 000 and
7 300 or the tuning rooms' 7 700; 2 or 3 sources, RT60 0.2-0.8 s, 8 captures each: 24 000
examples), each source's image scaled by up to 5 dB either way and the positions jittered by
12 cm (what :func:`localization.locate` gets wrong), to reproduce the phase-sensitive share of
microphone 0's bin. The loss is the masked magnitude's error in dB of the source's own energy
(with a floor 30 dB under the mixture), so a quiet source counts as much as a loud one. The
shipped weights took 16 epochs of :mod:`vrecho.learn.masknet`, which trains it again.

A second network of the same shape, ``assets/masknet_envelope.pt``, is the first fine-tuned
across the envelope (:data:`vrecho.sim.arrays.TRAINING`: any array of 2 to 7 microphones, the
head turning, 2 to 4 sources 0 to 20 dB apart, a quarter of the positions missed by 0.3 to 1.5 m;
500 walks of seeds 20 000 +, 5 700 examples, 2 epochs from the first's weights at a peak rate of
5e-4: 56 minutes in all on this project's 2-core machine)::

    python3 -m vrecho.learn.masknet --walks envelope --rooms 500 --epochs 2 --lr 5e-4 \
        --init localization/assets/masknet.pt --jobs 2 --data /tmp/masknet-env --out masknet_envelope.pt

Its own shares separate worse (on the envelope's tuning walks, true positions, +1.5 dB SI-SDR in
the median against the first's +3.1), but where the two networks disagree the first is unsure:
:func:`shares_and_doubt` gives each source's disagreement, which informed separation's guard reads
(:data:`localization.separate.GUARD`'s ``doubt``): two networks that learnt from different walks
agree where the mixture is plain and part where the first guesses. Among the tracks the guard's
other bounds keep, the doubt's Spearman correlation with the true gain is -0.47 (the envelope's
tuning walks, seeds 380 000 +, located positions). Its bound was chosen there and on the headset's
tuning rooms (seeds 7 700 +, two sources, RT60 0.4 s), 0.1 to 0.25 tried: at 0.2 the walks' tracks
at or above the microphone 95.5 -> 97.5 % (mean SI-SDR gain +1.81 -> +1.58 dB; true positions
95.5 -> 99.4 %), the headset's 85 -> 97.5 % (mean +2.37 -> +3.23 dB: it gives the microphone for
three hums the other bounds kept at -9 to -17 dB); 0.16 gave the walks 98.1 % but the headset +2.55.
"""

from __future__ import annotations

import functools
from pathlib import Path

import numpy as np

from .capture import FS  # noqa: F401 (the network's sample rate: captures at other rates are resampled to it)

NFFT = 512
WEIGHTS = Path(__file__).resolve().parent / "assets" / "masknet.pt"
SECOND_WEIGHTS = WEIGHTS.with_name("masknet_envelope.pt")


def features(X: np.ndarray, A: np.ndarray) -> np.ndarray:
    """The network's input for each source as the target (see the module's docstring).

    One source owns every bin: :func:`source_masks` needs no network for it.

    Parameters
    ----------
    X : numpy.ndarray [shape=(T, F, M), dtype=complex]
        A capture's STFT.
    A : numpy.ndarray [shape=(F, M, K), dtype=complex]
        The steering vectors of K >= 2 sources (:func:`localization.separate.steering`).

    Returns
    -------
    numpy.ndarray [shape=(K, 5, F, T), dtype=float32]
        Per source: microphone 0's log power, the coherence with its steering vector and the
        largest with the others', its beam's log power and the largest of the others' (the log
        powers normalised by microphone 0's mean and standard deviation).
    """
    T, F, M = X.shape
    K = A.shape[-1]
    An = A / np.linalg.norm(A, axis=1, keepdims=True)
    Xn = X / (np.linalg.norm(X, axis=-1, keepdims=True) + 1e-12)
    coherence = np.abs(np.einsum("fmk,tfm->kft", np.conj(An), Xn)) ** 2
    Rx = np.einsum("tfm,tfn->fmn", X, np.conj(X)) / T
    Rx = Rx + 1e-3 * np.trace(Rx, axis1=-2, axis2=-1).real[:, None, None] / M * np.eye(M)
    iRA = np.linalg.solve(Rx, A)
    W = iRA @ np.linalg.inv(np.einsum("fmk,fml->fkl", np.conj(A), iRA) + 1e-6 * np.eye(K))  # LCMV
    beams = np.log(np.abs(np.einsum("fmk,tfm->kft", np.conj(W), X)) ** 2 + 1e-10)
    power = np.log(np.abs(X[..., 0].T) ** 2 + 1e-10)
    mu, sd = power.mean(), power.std() + 1e-5
    power, beams = (power - mu) / sd, (beams - mu) / sd
    out = np.zeros((K, 5, F, T), np.float32)
    for k in range(K):
        others = [j for j in range(K) if j != k]
        out[k, 0] = power
        out[k, 1] = coherence[k]
        out[k, 2] = coherence[others].max(axis=0)
        out[k, 3] = beams[k]
        out[k, 4] = beams[others].max(axis=0)
    return out


def masknet_class():
    """The network's class (made on first use: torch loads only when separation is informed).

    Returns
    -------
    type
        ``MaskNet(ch=32)``, a ``torch.nn.Module`` whose ``forward`` maps features (B, 5, F, T)
        (:func:`features`) to shares (B, F, T) in [0, 1].
    """
    import torch  # heavy (1.7 s to import): only informed separation needs it
    from torch import nn  # heavy (1.7 s to import): only where a model runs

    class Block(nn.Module):
        """A residual dilated 3 x 3 convolution with PReLU.

        Parameters
        ----------
        ch : int
            Channels in and out.
        dt, df : int
            The dilation in time and in frequency.
        """

        def __init__(self, ch: int, dt: int, df: int):
            super().__init__()
            self.conv = nn.Conv2d(ch, ch, 3, padding=(df, dt), dilation=(df, dt))
            self.act = nn.PReLU(ch)

        def forward(self, x):
            """``x`` plus the block's response, (B, ch, F', T) either way."""
            return x + self.act(self.conv(x))

    class MaskNet(nn.Module):
        """The U-shaped mask network (see the module's docstring).

        Parameters
        ----------
        ch : int
            Channels at full frequency resolution (default 32; twice that in the middle).
        """

        DILATIONS = ((1, 1), (2, 1), (4, 2), (8, 1), (16, 4), (32, 1), (1, 2), (2, 1))  # (time, frequency)

        def __init__(self, ch: int = 32):
            super().__init__()
            self.inp = nn.Sequential(nn.Conv2d(6, ch, 3, padding=1), nn.PReLU(ch))
            self.down = nn.Sequential(nn.Conv2d(ch, 2 * ch, (4, 1), stride=(4, 1)), nn.PReLU(2 * ch))
            self.blocks = nn.Sequential(*[Block(2 * ch, dt, df) for dt, df in self.DILATIONS])
            self.up = nn.ConvTranspose2d(2 * ch, ch, (4, 1), stride=(4, 1))
            self.fuse = nn.Sequential(nn.Conv2d(2 * ch, ch, 3, padding=1), nn.PReLU(ch))
            self.out = nn.Conv2d(ch, 1, 1)

        def forward(self, f):  # (B, 5, F, T) -> (B, F, T)
            """Features (B, 5, F, T) float32 (:func:`features`) to shares (B, F, T) in [0, 1]."""
            B, _, F, T = f.shape
            freq = torch.linspace(-1, 1, F, dtype=f.dtype, device=f.device)[None, None, :, None].expand(B, 1, F, T)
            x = torch.cat([f, freq], 1).contiguous(memory_format=torch.channels_last)
            a = self.inp(x)
            u = self.up(self.blocks(self.down(a)))
            u = nn.functional.pad(u, (0, 0, 0, F - u.shape[2]))
            return torch.sigmoid(self.out(self.fuse(torch.cat([a, u], 1))))[:, 0]

    return MaskNet


@functools.lru_cache(maxsize=2)
def load_masknet(path: Path | None = None):
    """A shipped network (``assets/masknet.pt`` by default, or :data:`SECOND_WEIGHTS`; each loaded
    once), in evaluation mode.

    Parameters
    ----------
    path : path, optional
        The weights (default :data:`WEIGHTS`).

    Returns
    -------
    torch.nn.Module
        The network of :func:`masknet_class`, in single precision.
    """
    import torch  # heavy (1.7 s to import): only informed separation needs it

    state = {k: v.float() for k, v in torch.load(path or WEIGHTS, map_location="cpu", weights_only=True).items()}  # shipped in half precision
    model = masknet_class()(state["inp.0.weight"].shape[0])
    model.load_state_dict(state)
    return model.eval()


def source_masks(X: np.ndarray, A: np.ndarray) -> np.ndarray:
    """Each bin's share of each source.

    Parameters
    ----------
    X : numpy.ndarray [shape=(T, F, M), dtype=complex]
        A 16 kHz capture's STFT (512 points).
    A : numpy.ndarray [shape=(F, M, K), dtype=complex]
        The sources' steering vectors.

    Returns
    -------
    numpy.ndarray [shape=(T, F, K), dtype=float64]
        Shares in [0, 1]; all 1 for a single source.
    """
    return shares_and_doubt(X, A, doubt=False)[0]


def shares_and_doubt(X: np.ndarray, A: np.ndarray, *, doubt: bool = True) -> tuple[np.ndarray, np.ndarray | None]:
    """Each bin's share of each source (:func:`source_masks`), and how far the second network
    (:data:`SECOND_WEIGHTS`) disagrees with it, source by source.

    Parameters
    ----------
    X, A : numpy.ndarray
        The capture's STFT and the sources' steering vectors, as :func:`source_masks` takes them.
    doubt : bool
        Run the second network too (default True); False gives None for the doubt.

    Returns
    -------
    shares : numpy.ndarray [shape=(T, F, K), dtype=float64]
        The first network's shares in [0, 1]; all 1 for a single source.
    doubt : numpy.ndarray [shape=(K,)] or None
        Per source, the two networks' shares' absolute difference weighted by microphone 0's
        power, over the first's share of that power (0 where they agree; 0 for a single source).
    """
    import torch  # heavy (1.7 s to import): only informed separation needs it

    if A.shape[-1] == 1:
        return np.ones(X.shape[:2] + (1,)), (np.zeros(1) if doubt else None)
    with torch.no_grad():
        f = torch.as_tensor(features(X, A))
        masks = load_masknet()(f).numpy()
        if not doubt:
            return masks.transpose(2, 1, 0).astype(np.float64), None
        second = load_masknet(SECOND_WEIGHTS)(f).numpy()
    power = (np.abs(X[..., 0]) ** 2).T  # (F, T)
    parted = np.einsum("ft,kft->k", power, np.abs(masks - second)) / (np.einsum("ft,kft->k", power, masks) + 1e-30)
    return masks.transpose(2, 1, 0).astype(np.float64), parted
