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
