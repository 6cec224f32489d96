import pytest
import torch

from vrecho.models import DEPTH_BINS_M, DEPTH_FT_M, HEADS, SRC_CELLS, EchoCNN


def _batch(n=4):
    return {"mel": torch.randn(n, 62, 25), "image": torch.rand(n, 64, 25),
            "envelope": torch.rand(n, 1323), "bands": -60 * torch.rand(n, 7, 20), "wave": torch.randn(n, 11025),
            "self_envelope": torch.rand(n, 1323), "self_bands": -60 * torch.rand(n, 7, 20)}


@pytest.mark.parametrize("inputs, fusion", [(("mel",), "concat"), (("mel", "image"), "concat"),
                                            (("mel", "image"), "mfb"), (("echo",), "concat"),
                                            (("image",), "concat"), (("echo", "image"), "mfb"),
                                            (("wave",), "concat"), (("self",), "concat"),
                                            (("self", "image"), "concat")])
def test_every_variant_has_every_head(inputs, fusion):
    model = EchoCNN(inputs, fusion=fusion).eval()
    out = model(_batch())
    assert set(HEADS) <= set(out)
    assert out["open"].shape == (4, 2) and out["material"].shape == (4, 2)
    assert out["depth_bin"].shape == (4, len(DEPTH_BINS_M)) and out["depth_ft"].shape == (4, len(DEPTH_FT_M))
    assert out["depth_m"].shape == (4,)
    assert out["src_cell"].shape == (4, sum(SRC_CELLS)) and out["src_m"].shape == (4, 3)


def test_echo_branch_reads_depth_from_the_echo_delay():
    """Untrained, the echo branch already points at the strongest echo past the direct sound."""
    from vrecho.models import SPEED_OF_SOUND

    model = EchoCNN(("echo",)).eval()
    env = torch.full((3, 1323), 1e-3)
    env[:, :20] = 1.0  # direct sound
    depths = torch.tensor([0.4, 1.3, 2.6])
    for i, d in enumerate(depths):
        k = int(round(float(torch.sqrt((2 * d) ** 2 + 0.07 ** 2)) / SPEED_OF_SOUND * 44100))
        env[i, k - 3:k + 4] = 0.3
    with torch.no_grad():
        out = model({"envelope": env, "bands": torch.zeros(3, 7, 20)})
    assert torch.allclose(out["depth_m"], depths, atol=0.06)


def test_the_echo_branch_width_is_stored_and_older_bundles_load_at_24():
    from vrecho.models import build

    narrow = EchoCNN(("echo",), echo_channels=16)
    assert narrow.branches["echo"].score.in_channels == 16
    again = build(narrow.config)
    again.load_state_dict(narrow.state_dict())  # fails on any shape that differs
    older = {k: v for k, v in narrow.config.items() if k != "echo_channels"}  # bundles before the key
    assert build(older).branches["echo"].score.in_channels == 24


def test_the_paper_audio_network_is_small():
    # one conv layer, two dense layers: well under a million weights
    assert sum(p.numel() for p in EchoCNN(("mel",)).parameters()) < 1_000_000


def test_bad_variant():
    with pytest.raises(ValueError, match="inputs"):
        EchoCNN(("radar",))
    with pytest.raises(ValueError, match="not both echo and self"):
        EchoCNN(("echo", "self"))


@pytest.mark.parametrize("kind", ["knn", "svm"])
def test_classical_baselines_share_the_heads(kind):
    from vrecho.models import FeatureBaseline
    from vrecho.learn.train import metrics

    g = torch.Generator().manual_seed(0)
    n = 200
    is_open = torch.randint(0, 2, (n,), generator=g)
    mel = torch.randn(n, 62, 25, generator=g) + 1.5 * is_open[:, None, None]  # separable by level
    depth = 0.5 + 2.5 * torch.rand(n, generator=g)
    y = {"open": is_open, "material": torch.where(is_open == 1, -100, 0), "depth_bin": torch.zeros(n, dtype=torch.long),
         "depth_ft": torch.full((n,), -100), "depth_m": depth, "src_cell": torch.full((n, 3), -100),
         "src_m": torch.full((n, 3), float("nan"))}
    model = FeatureBaseline(kind).fit({"mel": mel[:150]}, {k: v[:150] for k, v in y.items()})
    out = model.predict({"mel": mel[150:]})
    assert set(out) == set(HEADS)
    assert out["src_cell"].shape == (50, sum(SRC_CELLS))
    m = metrics(out, {k: v[150:] for k, v in y.items()})
    assert m["open"] > 0.9
