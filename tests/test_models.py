import pytest
import torch

from vrecho.models import DEPTH_BINS_M, DEPTH_FT_M, HEADS, EchoCNN


def _batch(n=4):
    return {"mel": torch.randn(n, 62, 25), "image": torch.rand(n, 64, 25),
            "envelope": torch.rand(n, 1323), "bands": -60 * torch.rand(n, 7, 20)}


@pytest.mark.parametrize("inputs, fusion", [(("mel",), "concat"), (("mel", "image"), "concat"),
                                            (("mel", "image"), "mfb"), (("echo",), "concat"),
                                            (("image",), "concat"), (("echo", "image"), "mfb")])
def test_every_variant_has_every_head(inputs, fusion):
    model = EchoCNN(inputs, fusion).eval()
    out = model(_batch())
    assert set(out) == set(HEADS)
    assert out["open"].shape == (4, 2) and out["material"].shape == (4, 2)
    assert out["depth_bin"].shape == (4, len(DEPTH_BINS_M)) and out["depth_ft"].shape == (4, len(DEPTH_FT_M))
    assert out["depth_m"].shape == (4,)


def test_the_paper_audio_network_is_small():
    # one conv layer, two dense layers: well under a million weights
    assert sum(p.numel() for p in EchoCNN(("mel",)).parameters()) < 1_000_000


def test_bad_variant():
    with pytest.raises(ValueError, match="inputs"):
        EchoCNN(("radar",))


@pytest.mark.parametrize("kind", ["knn", "svm"])
def test_classical_baselines_share_the_heads(kind):
    from vrecho.models import FeatureBaseline
    from vrecho.train import metrics

    g = torch.Generator().manual_seed(0)
    n = 200
    is_open = torch.randint(0, 2, (n,), generator=g)
    mel = torch.randn(n, 62, 25, generator=g) + 1.5 * is_open[:, None, None]  # separable by level
    depth = 0.5 + 2.5 * torch.rand(n, generator=g)
    y = {"open": is_open, "material": torch.where(is_open == 1, -100, 0), "depth_bin": torch.zeros(n, dtype=torch.long),
         "depth_ft": torch.full((n,), -100), "depth_m": depth}
    model = FeatureBaseline(kind).fit({"mel": mel[:150]}, {k: v[:150] for k, v in y.items()})
    out = model.predict({"mel": mel[150:]})
    assert set(out) == set(HEADS)
    m = metrics(out, {k: v[150:] for k, v in y.items()})
    assert m["open"] > 0.9
