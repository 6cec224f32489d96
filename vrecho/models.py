"""EchoCNN and its variants (torch).

EchoCNN-A follows the paper: one convolutional layer over the 62 x 25 log-mel spectrogram,
feature normalisation, two dense layers, softmax heads. EchoCNN-AV adds an image branch for the
64 x 25 crop, fused with the audio branch by concatenation or by multi-modal factorised bilinear
pooling (MFB). EchoCNN-E goes beyond the paper: where the emitted sound is known it reads the
impulse response recovered by deconvolution (:func:`vrecho.features.echo_features`), whose echo
delays carry depth to a fraction of a centimetre.

Every variant has the same heads, so one training loop and one table serve them all.
"""

from __future__ import annotations

import numpy as np
import torch
from torch import nn
from torch.nn import functional as F

from .device import MIC_ABOVE_EMITTER_M
from .signals import FS, SPEED_OF_SOUND

DEPTH_BINS_M = (0.5, 1.0, 1.5, 2.0, 2.5, 3.0)
"""Synthetic-table depth classes: centres 0.5 m apart, each +/- 0.25 m."""
DEPTH_FT_M = (0.3048, 0.6096, 0.9144)
"""Real-scene-table depth classes: 1, 2 and 3 ft."""
SRC_GRID_M = ((-6.0, 6.0), (-6.0, 6.0), (-3.0, 3.0))
"""Extent of the source-position grid in the device frame (forward, left, up), in metres."""
SRC_CELL_M = 0.5
SRC_CELLS = tuple(int(round((hi - lo) / SRC_CELL_M)) for lo, hi in SRC_GRID_M)
"""Cells per axis of the 0.5 m source grid (24, 24, 12)."""
HEADS = {"open": 2, "material": 2, "depth_bin": len(DEPTH_BINS_M), "depth_ft": len(DEPTH_FT_M), "depth_m": 1,
         "src_cell": sum(SRC_CELLS), "src_m": 3}
"""Output size of each head: open/closed, glass/mirror, the two depth classings, depth in metres,
the source's 0.5 m grid cell (one softmax per axis, concatenated) and its position in metres."""
CLASS_HEADS = ("open", "material", "depth_bin", "depth_ft")
IGNORE = -100
"""The class target of a head that does not apply to a frame (torch's ``ignore_index``)."""


class AudioBranch(nn.Module):
    """The paper's audio sub-network: conv 3 x 3, batch normalisation, ReLU, 2 x 2 max-pool, dense.

    Parameters
    ----------
    n_filters : int
        Number of convolution filters; 16 by default.
    hidden : int
        Width of the dense layer (``out_features``); 128 by default.
    """

    def __init__(self, *, n_filters: int = 16, hidden: int = 128):
        super().__init__()
        self.conv = nn.Conv2d(1, n_filters, 3, padding=1)
        self.norm = nn.BatchNorm2d(n_filters)
        self.fc = nn.Linear(n_filters * 31 * 12, hidden)
        self.out_features = hidden

    def forward(self, mel: torch.Tensor) -> torch.Tensor:  # (B, 62, 25)
        """Features of log-mel spectrograms.

        Parameters
        ----------
        mel : torch.Tensor, shape (B, 62, 25), float32
            Normalised log-mel spectrograms (:func:`vrecho.features.logmel`).

        Returns
        -------
        torch.Tensor, shape (B, hidden), float32
            Non-negative features (after ReLU).
        """
        x = F.max_pool2d(F.relu(self.norm(self.conv(mel[:, None]))), 2)
        return F.relu(self.fc(torch.flatten(x, 1)))


class ImageBranch(nn.Module):
    """Two conv blocks over the 64 x 25 grayscale crop, then dense.

    Each block is conv 3 x 3 (16, then 32 filters), batch normalisation, ReLU, 2 x 2 max-pool.

    Parameters
    ----------
    hidden : int
        Width of the dense layer (``out_features``); 128 by default.
    """

    def __init__(self, *, hidden: int = 128):
        super().__init__()
        self.conv1 = nn.Conv2d(1, 16, 3, padding=1)
        self.norm1 = nn.BatchNorm2d(16)
        self.conv2 = nn.Conv2d(16, 32, 3, padding=1)
        self.norm2 = nn.BatchNorm2d(32)
        self.fc = nn.Linear(32 * 16 * 6, hidden)
        self.out_features = hidden

    def forward(self, image: torch.Tensor) -> torch.Tensor:  # (B, 64, 25) in [0, 1]
        """Features of grayscale crops.

        Parameters
        ----------
        image : torch.Tensor, shape (B, 64, 25), float32
            Crops with values in [0, 1].

        Returns
        -------
        torch.Tensor, shape (B, hidden), float32
            Non-negative features (after ReLU).
        """
        x = F.max_pool2d(F.relu(self.norm1(self.conv1(image[:, None]))), 2)
        x = F.max_pool2d(F.relu(self.norm2(self.conv2(x))), 2)
        return F.relu(self.fc(torch.flatten(x, 1)))


class EchoBranch(nn.Module):
    """The recovered impulse response, read the way physics says: where is the echo?

    Over the log envelope of the first 30 ms (half sample rate after a strided convolution,
    0.78 cm of depth per step, 0.39 cm per sample before it) a stack of dilated residual
    convolutions scores every delay; a softmax over the delays of the range of interest (past
    the direct sound) is an attention trained to point at the true echo delay; its peak, refined
    by a soft-argmax over the neighbouring steps and mapped through the echo geometry (emitter,
    surface, microphone 7 cm above the emitter), is the depth. What it reads there and the
    octave-band energy decay (7 x 20) feed the shared layers. The depth thus comes from an echo
    delay, not from memorised spectra, and carries over to rooms and probes never seen.

    Parameters
    ----------
    hidden : int
        Width of the echo features' dense layer; the band energies get half of it.
        ``out_features`` is ``hidden + hidden // 2``. 128 by default.
    length : int
        Samples of the envelope (30 ms at 44.1 kHz: 1323 by default); the delay steps number
        ``length // 2``.
    channels : int
        Channels of the convolutions; 24 by default.
    dilations : tuple of int
        Dilation of each residual convolution; (1, 2, 4, 8, 16, 32) by default.

    Attributes
    ----------
    depth_at : torch.Tensor, shape (length // 2,), float32
        Emitter-to-plane depth in metres of each delay step; only steps of 0.15 m or more are
        scored.
    """

    REFINE_STEPS = 3

    def __init__(self, *, hidden: int = 128, length: int = 1323, channels: int = 24,
                 dilations: tuple[int, ...] = (1, 2, 4, 8, 16, 32)):
        super().__init__()
        self.stem = nn.Conv1d(1, channels, 8, stride=2, padding=3)
        self.convs = nn.ModuleList(nn.Conv1d(channels, channels, 5, padding=2 * d, dilation=d) for d in dilations)
        self.norms = nn.ModuleList(nn.BatchNorm1d(channels) for _ in dilations)
        self.score = nn.Conv1d(channels, 1, 1)
        # Scores start as the envelope itself, sharpened: the attention begins as peak picking
        # (the strongest echo past the direct sound) and learns what to discount.
        self.sharpness = nn.Parameter(torch.tensor(40.0))
        t = (torch.arange(length // 2) * 2 + 0.5) / FS  # delay at each step's centre
        path = SPEED_OF_SOUND * t  # emitter -> surface -> microphone
        self.register_buffer("depth_at", torch.sqrt(torch.clamp(path ** 2 - MIC_ABOVE_EMITTER_M ** 2, min=0)) / 2)
        self.register_buffer("valid", self.depth_at >= 0.15)
        self.fc_bands = nn.Linear(7 * 20, hidden // 2)
        self.fc = nn.Linear(3 * channels + 2, hidden)
        self.out_features = hidden + hidden // 2

    def forward(self, envelope: torch.Tensor, bands: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """Features, depth in metres and the delay scores of impulse responses.

        Parameters
        ----------
        envelope : torch.Tensor, shape (B, length), float32
            :attr:`vrecho.features.EchoFeatures.envelope`: the first 30 ms, direct sound 1.
        bands : torch.Tensor, shape (B, 7, 20), float32
            :attr:`vrecho.features.EchoFeatures.bands`, in dB.

        Returns
        -------
        features : torch.Tensor, shape (B, out_features), float32
        depth : torch.Tensor, shape (B,), float32
            Emitter to the surface's plane, in metres.
        scores : torch.Tensor, shape (B, steps), float32
            The delay scores (steps = ``length // 2``, -1e4 before 0.15 m), which training holds
            against the true echo delay (see :func:`vrecho.learn.train.loss_fn`).
        """
        x = torch.log10(envelope.clamp_min(1e-4))[:, None] / 4.0  # 80 dB of range to [-1, 0]
        h = F.relu(self.stem(x))
        for conv, norm in zip(self.convs, self.norms):
            h = F.relu(norm(conv(h)), inplace=True) + h  # (a sum keeps its first term's memory layout: classifier.FastConv1d's passes on)
        n = self.depth_at.shape[0]
        h = h[..., :n].contiguous()  # (what follows reduces over steps: fastest with them adjacent)
        level_at = F.max_pool1d(x, 2)[:, 0, :n]
        scores = (self.score(h)[:, 0] + self.sharpness * level_at).masked_fill(~self.valid, -1e4)
        # The echo: the best-scoring delay, refined to a fraction of a step by a soft-argmax over
        # its neighbourhood (a global expectation would average in the floor's echo).
        peak = scores.argmax(1, keepdim=True)
        near = (torch.arange(n, device=scores.device)[None] - peak).abs() <= self.REFINE_STEPS
        w = torch.softmax(scores.masked_fill(~near, -1e4), dim=1)
        depth = (w * self.depth_at).sum(1)
        level = (w * level_at).sum(1, keepdim=True)
        z = torch.cat([(w[:, None] * h).sum(2), h.amax(2), h.mean(2), level, depth[:, None]], dim=1)
        e = F.relu(self.fc(z))
        b = F.relu(self.fc_bands(torch.flatten(bands, 1) / 60.0))
        return torch.cat([e, b], dim=1), depth, scores


class SoundNetBranch(nn.Module):
    """A SoundNet-style 1-D CNN over the raw waveform (11.025 kHz, 1 s): strided convolutions with
    SoundNet's kernel sizes (64, 32, 16, 8, 4, ...), max-pooling by 8 after the first two, then
    global average and max pooling. ``n_layers`` is 5 or 8; trained from scratch (SoundNet's
    pretrained weights cannot be had offline). A quarter of the sample rate keeps training within
    minutes per epoch on two cores; the global pooling discards echo timing anyway.

    Parameters
    ----------
    n_layers : {5, 8}
        Number of convolutions; 8 by default.
    hidden : int
        Width of the dense layer (``out_features``); 128 by default.

    Raises
    ------
    ValueError
        If ``n_layers`` is neither 5 nor 8.
    """

    def __init__(self, *, n_layers: int = 8, hidden: int = 128):
        super().__init__()
        if n_layers not in (5, 8):
            raise ValueError(f"n_layers: expected 5 or 8, got {n_layers!r}")
        kernels = (64, 32, 16, 8, 4, 4, 4, 4)[:n_layers]
        channels = (1, 16, 32, 64, 128, 256, 256, 256, 256)[:n_layers + 1]
        self.convs = nn.ModuleList(nn.Conv1d(a, b, k, stride=2, padding=k // 2)
                                   for a, b, k in zip(channels[:-1], channels[1:], kernels))
        self.norms = nn.ModuleList(nn.BatchNorm1d(b) for b in channels[1:])
        self.fc = nn.Linear(2 * channels[-1], hidden)
        self.out_features = hidden

    def forward(self, wave: torch.Tensor) -> torch.Tensor:  # (B, 11025)
        """Features of waveforms, each first scaled to a peak of 1.

        Parameters
        ----------
        wave : torch.Tensor, shape (B, 11025), float32
            1 s frames at 11.025 kHz.

        Returns
        -------
        torch.Tensor, shape (B, hidden), float32
            Non-negative features (after ReLU).
        """
        x = wave[:, None] / wave.abs().amax(dim=1, keepdim=True)[:, None].clamp_min(1e-6)
        for i, (conv, norm) in enumerate(zip(self.convs, self.norms)):
            x = F.relu(norm(conv(x)))
            if i < 2:
                x = F.max_pool1d(x, 8)
        return F.relu(self.fc(torch.cat([x.mean(2), x.amax(2)], dim=1)))


class MFB(nn.Module):
    """Multi-modal factorised bilinear pooling: z_i = 1^T (U_i^T x o V_i^T y), with k factors
    per output, then power and L2 normalisation.

    Parameters
    ----------
    x_features, y_features : int
        Widths of the two inputs.
    out_features : int
        Width of the output; 128 by default.
    k : int
        Factors per output; 5 by default.
    dropout : float
        Dropout probability on the products before summing; 0.1 by default.
    """

    def __init__(self, x_features: int, y_features: int, *, out_features: int = 128, k: int = 5, dropout: float = 0.1):
        super().__init__()
        self.u = nn.Linear(x_features, out_features * k)
        self.v = nn.Linear(y_features, out_features * k)
        self.k, self.out_features = k, out_features
        self.dropout = nn.Dropout(dropout)

    def forward(self, x: torch.Tensor, y: torch.Tensor) -> torch.Tensor:
        """The fused features of two inputs.

        Parameters
        ----------
        x : torch.Tensor, shape (B, x_features), float32
            Features of the first branch.
        y : torch.Tensor, shape (B, y_features), float32
            Features of the second branch.

        Returns
        -------
        torch.Tensor, shape (B, out_features), float32
            Signed square roots, scaled to unit L2 norm per row.
        """
        z = self.dropout(self.u(x) * self.v(y)).view(-1, self.out_features, self.k).sum(dim=2)
        z = torch.sign(z) * torch.sqrt(torch.abs(z) + 1e-8)
        return F.normalize(z, dim=1)


INPUTS = ("mel", "image", "echo", "self", "wave")


class EchoCNN(nn.Module):
    """EchoCNN with the inputs of its variant and every head of :data:`HEADS`.

    Parameters
    ----------
    inputs : tuple of {"mel", "image", "echo", "self", "wave"}
        ``("mel",)``: the paper's EchoCNN-A; ``("mel", "image")``: its EchoCNN-AV;
        ``("self",)``: EchoCNN-A reading echo delays off the recording's own autocorrelation
        (emitted sound unknown, :func:`vrecho.features.self_features`), and ``("self",
        "image")`` with the camera; ``("echo",)``: EchoCNN-E (emitted sound known);
        ``("echo", "image")``: EchoCNN-EV; ``("image",)``: the visual-only baseline;
        ``("wave",)``: the SoundNet-style baseline. "echo" and "self" share one
        :class:`EchoBranch` design and exclude each other. ``("mel",)`` by default.
    fusion : {"concat", "mfb"}
        How two branches meet (ignored with one; "mfb" only with exactly two); "concat" by
        default.
    hidden : int
        Width of each branch's dense layer and of the shared dense layer; 128 by default.
    dropout : float
        Dropout probability before and after the shared dense layer; 0.3 by default.
    wave_layers : {5, 8}
        Depth of the SoundNet branch; 8 by default.
    echo_channels : int
        Channels of the echo branch's convolutions (:class:`EchoBranch`); 24 by default.
    open_temperature : float
        What the open/closed head's logits are divided by when the classifier answers
        (:mod:`vrecho.classifier`; training and :meth:`forward` never use it): 1 as trained, a
        temperature fitted after training where frames of other devices say the head is over-
        or underconfident (:func:`vrecho.learn.devices.open_temperature`); 1 by default.

    Attributes
    ----------
    config : dict
        The parameters above, as checkpoints store them (see :func:`build`).

    Raises
    ------
    ValueError
        If ``inputs`` is empty, names an unknown input or both "echo" and "self", or ``fusion``
        is unknown.

    Examples
    --------
    >>> model = EchoCNN(("mel",)).eval()
    >>> out = model({"mel": torch.zeros(2, 62, 25)})
    >>> out["open"].shape, out["depth_m"].shape
    (torch.Size([2, 2]), torch.Size([2]))
    """

    def __init__(self, inputs: tuple[str, ...] = ("mel",), *, fusion: str = "concat", hidden: int = 128,
                 dropout: float = 0.3, wave_layers: int = 8, echo_channels: int = 24, open_temperature: float = 1.0):
        super().__init__()
        if not inputs or not set(inputs) <= set(INPUTS) or {"echo", "self"} <= set(inputs):
            raise ValueError(f"inputs: expected some of {', '.join(INPUTS)} (not both echo and self); got {inputs!r}")
        if fusion not in ("concat", "mfb"):
            raise ValueError(f"fusion: expected concat or mfb, got {fusion!r}")
        self.inputs, self.fusion = tuple(inputs), fusion
        self.config = {"inputs": list(inputs), "fusion": fusion, "hidden": hidden, "dropout": dropout,
                       "wave_layers": wave_layers, "echo_channels": echo_channels, "open_temperature": open_temperature}
        self.branches = nn.ModuleDict()
        if "mel" in inputs:
            self.branches["mel"] = AudioBranch(hidden=hidden)
        for name in ("echo", "self"):
            if name in inputs:
                self.branches[name] = EchoBranch(hidden=hidden, channels=echo_channels)
        if "wave" in inputs:
            self.branches["wave"] = SoundNetBranch(n_layers=wave_layers, hidden=hidden)
        if "image" in inputs:
            self.branches["image"] = ImageBranch(hidden=hidden)
        sizes = [b.out_features for b in self.branches.values()]
        if fusion == "mfb" and len(sizes) == 2:
            self.mfb = MFB(sizes[0], sizes[1], out_features=hidden)
            fused = hidden
        else:
            fused = sum(sizes)
        self.shared = nn.Linear(fused, hidden)
        self.dropout = nn.Dropout(dropout)
        self.heads = nn.ModuleDict({name: nn.Linear(hidden, size) for name, size in HEADS.items()})
        self.register_buffer("depth_bins", torch.tensor(DEPTH_BINS_M), persistent=False)
        self.register_buffer("depth_ft", torch.tensor(DEPTH_FT_M), persistent=False)

    def forward(self, batch: dict[str, torch.Tensor]) -> dict[str, torch.Tensor]:
        """Every head's output for a batch.

        With the echo branch, ``depth_m`` is the depth of the echo delay it reads (the shared
        layers' depth head unused: a learned correction of a few centimetres, tried, took the
        product protocol's median error on closed surfaces from 0.4 to 1.3 cm for EchoCNN-EV
        and to 3.4 cm for EchoCNN-E trained on other devices' frames too), and the depth
        classes are scored by the distance of that depth to each class's centre.

        Parameters
        ----------
        batch : dict of str to torch.Tensor
            The variant's inputs, float32: ``mel`` (B, 62, 25), ``image`` (B, 64, 25) in
            [0, 1], ``envelope`` (B, 1323) and ``bands`` (B, 7, 20) for ``echo``
            (``self_envelope`` and ``self_bands`` for ``self``), ``wave`` (B, 11025). Other keys
            are ignored.

        Returns
        -------
        dict of str to torch.Tensor
            Class scores (logits) per head of :data:`HEADS`, (B, size): ``open``, ``material``,
            ``depth_bin``, ``depth_ft``, ``src_cell``; ``depth_m`` (B,) and ``src_m`` (B, 3) in
            metres. With the echo branch also ``delay_scores`` (B, 661) and ``depth_at`` (661,),
            in metres (see :class:`EchoBranch`).
        """
        feats, echo_depth = [], None
        for name, branch in self.branches.items():
            if name in ("echo", "self"):
                key = "" if name == "echo" else "self_"
                f, echo_depth, delay_scores = branch(batch[key + "envelope"], batch[key + "bands"])
                feats.append(f)
                out_at = branch.depth_at
            else:
                feats.append(branch(batch[name]))
        if hasattr(self, "mfb"):
            z = self.mfb(*feats)
        else:
            z = torch.cat(feats, dim=1)
        h = self.dropout(F.relu(self.shared(self.dropout(z))))
        out = {name: head(h) for name, head in self.heads.items()}
        out["depth_m"] = out["depth_m"].squeeze(1)
        if echo_depth is not None:  # the echo delay read by the echo branch: physics, not a regression
            out["depth_m"] = echo_depth
            # Depth classes are the classes of that measured depth (nearest centre), not a guess of
            # their own: for an echo read to a centimetre a separate classifier only adds errors.
            for head, centres in (("depth_bin", self.depth_bins), ("depth_ft", self.depth_ft)):
                out[head] = -(out["depth_m"][:, None] - centres[None]).abs() / 0.1
            out["delay_scores"] = delay_scores
            out["depth_at"] = out_at
        return out


def build(config: dict) -> EchoCNN:
    """An EchoCNN from its ``config`` (as stored in checkpoints).

    Parameters
    ----------
    config : dict
        :attr:`EchoCNN.config`: ``inputs``, ``fusion``, ``hidden``, ``dropout`` and, optionally,
        ``wave_layers`` (8 when absent), ``echo_channels`` (24 when absent) and
        ``open_temperature`` (1 when absent).

    Returns
    -------
    EchoCNN
        A new model with fresh weights (load a state dict into it).
    """
    return EchoCNN(tuple(config["inputs"]), fusion=config["fusion"], hidden=config["hidden"], dropout=config["dropout"],
                   wave_layers=config.get("wave_layers", 8), echo_channels=config.get("echo_channels", 24),
                   open_temperature=config.get("open_temperature", 1.0))


class FeatureBaseline:
    """The paper's classical baselines, kNN or a linear SVM, with EchoCNN's heads.

    One scikit-learn estimator per head over the flattened, standardised inputs; ``predict``
    returns scores shaped like EchoCNN's outputs (class scores per head, ``depth_m`` in metres),
    so one metrics function serves both.

    Parameters
    ----------
    kind : {"knn", "svm"}
        k nearest neighbours or a linear SVM; "knn" by default.
    inputs : tuple of {"mel", "image", "envelope", "bands"}
        Input arrays to flatten and concatenate; ``("mel",)`` by default.
    n_neighbors : int
        For kNN; 5 by default.
    C : float
        Inverse regularisation, for the SVM; 0.1 by default.

    Raises
    ------
    ValueError
        If ``kind`` is neither "knn" nor "svm".
    """

    def __init__(self, kind: str = "knn", inputs: tuple[str, ...] = ("mel",), *, n_neighbors: int = 5, C: float = 0.1):
        if kind not in ("knn", "svm"):
            raise ValueError(f"kind: expected knn or svm, got {kind!r}")
        self.kind, self.inputs, self.n_neighbors, self.C = kind, tuple(inputs), n_neighbors, C

    def _features(self, x: dict):
        return np.concatenate([np.asarray(x[k], dtype=np.float32).reshape(len(x[k]), -1) for k in self.inputs], axis=1)

    def _estimator(self, regression: bool):
        # scikit-learn is heavy (1.7 s to import): only the baselines need it
        from sklearn.multioutput import MultiOutputRegressor  # heavy (1.7 s to import): only the baselines need it
        from sklearn.neighbors import (  # heavy (1.7 s to import): only the baselines need it
            KNeighborsClassifier,
            KNeighborsRegressor,
        )
        from sklearn.svm import LinearSVC, LinearSVR  # heavy (1.7 s to import): only the baselines need it

        if self.kind == "knn":
            return KNeighborsRegressor(self.n_neighbors) if regression else KNeighborsClassifier(self.n_neighbors)
        # the primal problems (dual=False): samples outnumber features, and this is minutes faster
        if regression:
            return MultiOutputRegressor(LinearSVR(C=self.C, dual=False, loss="squared_epsilon_insensitive"))
        return LinearSVC(C=self.C, dual=False)

    def fit(self, x: dict, y: dict) -> "FeatureBaseline":
        """Fit one standardised estimator per head, each on the rows where that head applies.

        A class head with a single class in its rows gets a most-frequent dummy; a head with no
        rows gets no estimator (:meth:`predict` then answers zeros for it).

        Parameters
        ----------
        x : dict of str to numpy.ndarray
            The arrays of ``inputs``, each (N, ...).
        y : dict of str to numpy.ndarray
            Targets: ``open``, ``material``, ``depth_bin``, ``depth_ft`` (N,) int, :data:`IGNORE`
            where a head does not apply; ``depth_m`` (N,) in metres, used where finite and the
            surface is closed (``open`` 0); ``src_m`` (N, 3) in metres, used in rows without
            NaN, with ``src_cell`` (N, 3) int, the grid cell per axis.

        Returns
        -------
        FeatureBaseline
            Itself, fitted (``models_``).
        """
        # scikit-learn is heavy (1.7 s to import): only the baselines need it
        from sklearn.dummy import DummyClassifier  # heavy (1.7 s to import): only the baselines need it
        from sklearn.pipeline import make_pipeline  # heavy (1.7 s to import): only the baselines need it
        from sklearn.preprocessing import StandardScaler  # heavy (1.7 s to import): only the baselines need it

        X = self._features(x)
        self.models_ = {}
        tasks = {head: (np.asarray(y[head]), y[head] != IGNORE) for head in CLASS_HEADS}
        depth = np.asarray(y["depth_m"])
        tasks["depth_m"] = (depth[:, None], np.isfinite(depth) & (np.asarray(y["open"]) == 0))
        src = np.asarray(y["src_m"])
        src_rows = np.isfinite(src).all(axis=1)
        tasks["src_m"] = (src, src_rows)
        for axis in range(3):
            tasks[f"src_cell{axis}"] = (np.asarray(y["src_cell"])[:, axis], src_rows)
        for name, (t, keep) in tasks.items():
            keep = np.asarray(keep)
            if not keep.any():  # nothing to learn this task from: it will answer nothing
                self.models_[name] = None
                continue
            regression = name in ("depth_m", "src_m")
            if not regression and len(np.unique(t[keep])) == 1:
                est = DummyClassifier(strategy="most_frequent")
            else:
                est = self._estimator(regression)
            self.models_[name] = make_pipeline(StandardScaler(), est).fit(X[keep], t[keep])
        return self

    def predict(self, x: dict) -> dict:
        """Scores shaped like EchoCNN's outputs.

        Parameters
        ----------
        x : dict of str to numpy.ndarray
            The arrays of ``inputs``, each (N, ...).

        Returns
        -------
        dict of str to torch.Tensor
            One-hot class scores (N, size) float32 per class head of :data:`CLASS_HEADS` and
            ``src_cell`` (N, 60) (one block per axis); ``depth_m`` (N,) and ``src_m`` (N, 3) in
            metres. A head fitted on no rows answers zeros (class 0 for a class head).
        """
        X = self._features(x)
        n = len(X)

        def run(name, width):
            model = self.models_[name]
            if model is None:
                return np.zeros((n, width), np.float32)
            return np.asarray(model.predict(X), np.float32).reshape(n, -1)

        def one_hot(labels, width):
            scores = np.zeros((n, width), np.float32)
            scores[np.arange(n), labels.astype(int).ravel()] = 1.0
            return scores

        out = {head: torch.as_tensor(one_hot(run(head, 1), HEADS[head])) for head in CLASS_HEADS}
        out["depth_m"] = torch.as_tensor(run("depth_m", 1)[:, 0])
        out["src_m"] = torch.as_tensor(run("src_m", 3))
        out["src_cell"] = torch.as_tensor(np.concatenate([one_hot(run(f"src_cell{a}", 1), SRC_CELLS[a]) for a in range(3)],
                                                         axis=1))
        return out
