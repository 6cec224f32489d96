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

import torch
from torch import nn
from torch.nn import functional as F

DEPTH_BINS_M = (0.5, 1.0, 1.5, 2.0, 2.5, 3.0)
"""Synthetic-table depth classes: centres 0.5 m apart, each +/- 0.25 m."""
DEPTH_FT_M = (0.3048, 0.6096, 0.9144)
"""Real-scene-table depth classes: 1, 2 and 3 ft."""
HEADS = {"open": 2, "material": 2, "depth_bin": len(DEPTH_BINS_M), "depth_ft": len(DEPTH_FT_M), "depth_m": 1}
"""Output size of each head: open/closed, glass/mirror, the two depth classings, depth in metres."""


class AudioBranch(nn.Module):
    """The paper's audio sub-network: conv 3 x 3, batch normalisation, ReLU, 2 x 2 max-pool, dense."""

    def __init__(self, n_filters: int = 16, hidden: int = 128):
        super().__init__()
        self.conv = nn.Conv2d(1, n_filters, 3, padding=1)
        self.norm = nn.BatchNorm2d(n_filters)
        self.fc = nn.Linear(n_filters * 31 * 12, hidden)
        self.out_features = hidden

    def forward(self, mel: torch.Tensor) -> torch.Tensor:  # (B, 62, 25)
        x = F.max_pool2d(F.relu(self.norm(self.conv(mel[:, None]))), 2)
        return F.relu(self.fc(torch.flatten(x, 1)))


class ImageBranch(nn.Module):
    """Two conv blocks over the 64 x 25 grayscale crop, then dense."""

    def __init__(self, hidden: int = 128):
        super().__init__()
        self.conv1 = nn.Conv2d(1, 16, 3, padding=1)
        self.norm1 = nn.BatchNorm2d(16)
        self.conv2 = nn.Conv2d(16, 32, 3, padding=1)
        self.norm2 = nn.BatchNorm2d(32)
        self.fc = nn.Linear(32 * 16 * 6, hidden)
        self.out_features = hidden

    def forward(self, image: torch.Tensor) -> torch.Tensor:  # (B, 64, 25) in [0, 1]
        x = F.max_pool2d(F.relu(self.norm1(self.conv1(image[:, None]))), 2)
        x = F.max_pool2d(F.relu(self.norm2(self.conv2(x))), 2)
        return F.relu(self.fc(torch.flatten(x, 1)))


class EchoBranch(nn.Module):
    """The recovered impulse response: a 1-D CNN over its first 30 ms (log envelope, sample
    resolution kept in the first layers so echo delays stay readable), and a dense layer over the
    octave-band energy decay (7 x 20)."""

    def __init__(self, hidden: int = 128, length: int = 1323):
        super().__init__()
        self.convs = nn.ModuleList()
        self.norms = nn.ModuleList()
        channels = (1, 16, 32, 32, 64)
        for c_in, c_out in zip(channels[:-1], channels[1:]):
            self.convs.append(nn.Conv1d(c_in, c_out, 7, padding=3))
            self.norms.append(nn.BatchNorm1d(c_out))
        n = length
        for _ in self.convs:
            n //= 2
        self.fc_env = nn.Linear(channels[-1] * n, hidden)
        self.fc_bands = nn.Linear(7 * 20, hidden // 2)
        self.out_features = hidden + hidden // 2

    def forward(self, envelope: torch.Tensor, bands: torch.Tensor) -> torch.Tensor:
        x = torch.log10(envelope.clamp_min(1e-4))[:, None] / 4.0  # 80 dB of range to [-1, 0]
        for conv, norm in zip(self.convs, self.norms):
            x = F.max_pool1d(F.relu(norm(conv(x))), 2)
        e = F.relu(self.fc_env(torch.flatten(x, 1)))
        b = F.relu(self.fc_bands(torch.flatten(bands, 1) / 60.0))
        return torch.cat([e, b], dim=1)


class MFB(nn.Module):
    """Multi-modal factorised bilinear pooling: z_i = 1^T (U_i^T x o V_i^T y), with k factors
    per output, then power and L2 normalisation."""

    def __init__(self, x_features: int, y_features: int, out_features: int = 128, k: int = 5, dropout: float = 0.1):
        super().__init__()
        self.u = nn.Linear(x_features, out_features * k)
        self.v = nn.Linear(y_features, out_features * k)
        self.k, self.out_features = k, out_features
        self.dropout = nn.Dropout(dropout)

    def forward(self, x: torch.Tensor, y: torch.Tensor) -> torch.Tensor:
        z = self.dropout(self.u(x) * self.v(y)).view(-1, self.out_features, self.k).sum(dim=2)
        z = torch.sign(z) * torch.sqrt(torch.abs(z) + 1e-8)
        return F.normalize(z, dim=1)


class EchoCNN(nn.Module):
    """EchoCNN with the inputs of its variant and every head of :data:`HEADS`.

    Parameters
    ----------
    inputs : tuple of {"mel", "image", "echo"}
        ``("mel",)``: EchoCNN-A; ``("mel", "image")``: EchoCNN-AV; ``("echo",)``: EchoCNN-E
        (emitted sound known); ``("image",)``: the visual-only baseline.
    fusion : {"concat", "mfb"}
        How two branches meet (ignored with one).
    hidden : int
        Width of each branch's dense layer and of the shared dense layer.
    """

    def __init__(self, inputs: tuple[str, ...] = ("mel",), fusion: str = "concat", hidden: int = 128,
                 dropout: float = 0.3):
        super().__init__()
        if not inputs or not set(inputs) <= {"mel", "image", "echo"}:
            raise ValueError(f"inputs: expected some of mel, image, echo; got {inputs!r}")
        if fusion not in ("concat", "mfb"):
            raise ValueError(f"fusion: expected concat or mfb, got {fusion!r}")
        self.inputs, self.fusion = tuple(inputs), fusion
        self.branches = nn.ModuleDict()
        if "mel" in inputs:
            self.branches["mel"] = AudioBranch(hidden=hidden)
        if "echo" in inputs:
            self.branches["echo"] = EchoBranch(hidden=hidden)
        if "image" in inputs:
            self.branches["image"] = ImageBranch(hidden=hidden)
        sizes = [b.out_features for b in self.branches.values()]
        if fusion == "mfb" and len(sizes) == 2:
            self.mfb = MFB(sizes[0], sizes[1], hidden)
            fused = hidden
        else:
            fused = sum(sizes)
        self.shared = nn.Linear(fused, hidden)
        self.dropout = nn.Dropout(dropout)
        self.heads = nn.ModuleDict({name: nn.Linear(hidden, size) for name, size in HEADS.items()})

    def forward(self, batch: dict[str, torch.Tensor]) -> dict[str, torch.Tensor]:
        feats = []
        for name, branch in self.branches.items():
            if name == "echo":
                feats.append(branch(batch["envelope"], batch["bands"]))
            else:
                feats.append(branch(batch[name]))
        if hasattr(self, "mfb"):
            z = self.mfb(*feats)
        else:
            z = torch.cat(feats, dim=1)
        h = self.dropout(F.relu(self.shared(self.dropout(z))))
        out = {name: head(h) for name, head in self.heads.items()}
        out["depth_m"] = out["depth_m"].squeeze(1)
        return out


class FeatureBaseline:
    """The paper's classical baselines, kNN or a linear SVM, with EchoCNN's heads.

    One scikit-learn estimator per head over the flattened, standardised inputs; ``predict``
    returns scores shaped like EchoCNN's outputs (class scores per head, ``depth_m`` in metres),
    so one metrics function serves both.

    Parameters
    ----------
    kind : {"knn", "svm"}
    inputs : tuple of {"mel", "image", "envelope", "bands"}
        Input arrays to flatten and concatenate.
    n_neighbors : int
        For kNN.
    C : float
        Inverse regularisation, for the SVM.
    """

    def __init__(self, kind: str = "knn", inputs: tuple[str, ...] = ("mel",), n_neighbors: int = 5, C: float = 0.1):
        if kind not in ("knn", "svm"):
            raise ValueError(f"kind: expected knn or svm, got {kind!r}")
        self.kind, self.inputs, self.n_neighbors, self.C = kind, tuple(inputs), n_neighbors, C

    def _features(self, x: dict):
        import numpy as np

        return np.concatenate([np.asarray(x[k], dtype=np.float32).reshape(len(x[k]), -1) for k in self.inputs], axis=1)

    def fit(self, x: dict, y: dict) -> "FeatureBaseline":
        import numpy as np
        from sklearn.dummy import DummyClassifier
        from sklearn.neighbors import KNeighborsClassifier, KNeighborsRegressor
        from sklearn.pipeline import make_pipeline
        from sklearn.preprocessing import StandardScaler
        from sklearn.svm import LinearSVC, LinearSVR

        from .train import IGNORE

        X = self._features(x)
        self.models_ = {}
        for head in HEADS:
            t = np.asarray(y[head])
            keep = t != IGNORE if head != "depth_m" else np.ones(len(t), bool)
            if not keep.any():  # nothing to learn this head from: it will answer nothing
                self.models_[head] = None
                continue
            if head == "depth_m":
                est = KNeighborsRegressor(self.n_neighbors) if self.kind == "knn" else LinearSVR(C=self.C, max_iter=5000)
            elif len(np.unique(t[keep])) == 1:
                est = DummyClassifier(strategy="most_frequent")
            else:
                est = KNeighborsClassifier(self.n_neighbors) if self.kind == "knn" else LinearSVC(C=self.C, max_iter=5000)
            self.models_[head] = make_pipeline(StandardScaler(), est).fit(X[keep], t[keep])
        return self

    def predict(self, x: dict) -> dict:
        import numpy as np

        X = self._features(x)
        out = {}
        for head, model in self.models_.items():
            if model is None:
                out[head] = torch.zeros((len(X),) if head == "depth_m" else (len(X), HEADS[head]))
                continue
            if head == "depth_m":
                out[head] = torch.as_tensor(model.predict(X), dtype=torch.float32)
                continue
            scores = np.zeros((len(X), HEADS[head]), np.float32)  # one-hot of the predicted class
            scores[np.arange(len(X)), model.predict(X).astype(int)] = 1.0
            out[head] = torch.as_tensor(scores)
        return out
