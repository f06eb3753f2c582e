"""The shared-encoder BlindSpotNet: one encoder's cost, B still reading D's depth, D carried over
whole from a two-network run, and an exported graph that agrees with torch."""

import numpy as np
import onnx
import pytest
import torch

from bsn_edge.benchmarks.arch_speed import count_gmacs
from bsn_edge.export import FusedModel, to_onnx
from bsn_edge.modelfile.read import session
from bsn_edge.networks import create_model, get_spec, start_from
from tests.cards import card_for


def test_one_encoder_costs_about_half_of_two():
    two, one = (count_gmacs(create_model(n).eval(), (256, 512)) for n in ("small-light", "shared-light"))
    # a ResNet-18 at 128x256 is about 1.2 GMACs: the second one is nearly all the difference
    assert 1.1 < two - one < 1.3 and one < 0.55 * two


def _shift_depth(model) -> None:
    with torch.no_grad():
        model.depth_net.head.conv.bias.add_(1.0)    # every depth x e


@pytest.mark.parametrize("name, reads_depth", [("shared-light", True), ("shared-light-d", False)])
def test_b_reads_ds_depth_only_when_its_spec_says_so(name, reads_depth):
    torch.manual_seed(0)
    m = create_model(name).eval()
    x = torch.randn(1, 3, 64, 128)
    with torch.no_grad():
        before, depth_before, _ = m(x)
        _shift_depth(m)
        after, depth_after, _ = m(x)
    assert get_spec(name).use_depth is reads_depth
    assert not torch.allclose(depth_before, depth_after)
    assert (not torch.allclose(before, after)) is reads_depth


def test_bs_loss_trains_the_shared_encoder_but_not_ds_decoder():
    torch.manual_seed(0)
    m = create_model("shared-light")
    logits, _, feats = m(torch.randn(2, 3, 64, 128))
    (logits.mean() + feats.mean()).backward()
    assert all(p.grad is None for p in m.depth_net.decoder.parameters())
    assert all(p.grad is None for p in m.depth_net.head.parameters())
    assert any(p.grad is not None and p.grad.abs().sum() > 0 for p in m.depth_net.encoder.parameters())


def test_a_shared_model_takes_d_whole_from_a_two_network_run():
    torch.manual_seed(0)
    source = create_model("small-light").eval()
    torch.manual_seed(1)
    model = create_model("shared-light").eval()
    b_before = {k: v.clone() for k, v in model.blindspot.state_dict().items()}
    assert start_from(model, "shared-light", source, "small-light") == "D"
    x = torch.randn(1, 3, 64, 128)
    with torch.no_grad():
        # D of the source, run alone, is the truth the shared model's depth must reproduce
        torch.testing.assert_close(model(x)[1], source(x)[1], atol=0, rtol=0)
    assert all(torch.equal(v, model.blindspot.state_dict()[k]) for k, v in b_before.items())
    with pytest.raises(ValueError, match="got a 'shared-light' run"):
        start_from(create_model("small-light"), "small-light", model, "shared-light")
    with pytest.raises(ValueError, match="'small'"):
        start_from(model, "shared-light", create_model("small"), "small")


def _plain(model, frame: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The torch model itself on a uint8 BGR frame: F.interpolate, the stem as trained."""
    from bsn_edge.data.dataset import IMAGENET_MEAN, IMAGENET_STD
    x = torch.from_numpy(frame).permute(0, 3, 1, 2).float()[:, [2, 1, 0]] / 255.0
    x = (x - torch.tensor(IMAGENET_MEAN).float()[:, None, None]) / torch.tensor(IMAGENET_STD).float()[:, None, None]
    with torch.no_grad():
        logits, depth, _ = model(x)
    return torch.sigmoid(logits).numpy(), depth.numpy()


def test_the_exported_graph_agrees_with_the_torch_model(tmp_path):
    torch.manual_seed(0)
    model = create_model("shared-light").eval()
    out = tmp_path / "m.onnx"
    to_onnx(model, out, card_for((64, 128), variant="shared-light"))
    frame = np.random.default_rng(0).integers(0, 256, (1, 64, 128, 3), dtype=np.uint8)
    p, d = session(out).run(None, {"frame": frame})
    pt, dt = _plain(model, frame)
    np.testing.assert_allclose(p, pt, atol=1e-4)
    np.testing.assert_allclose(d, dt, rtol=1e-3)


def test_the_exported_graph_reads_blocks_and_upsamples_once_per_head(tmp_path):
    torch.manual_seed(0)
    out = tmp_path / "m.onnx"
    to_onnx(create_model("shared-light").eval(), out, card_for((64, 128), variant="shared-light"))
    g = onnx.load(str(out)).graph
    ops = [n.op_type for n in g.node]
    assert ops.count("DepthToSpace") == 2, "one x8 shuffle per head"
    assert [n.name for n in g.node if n.op_type == "Resize" and "/decoder" not in n.name] == [], "no frame resize"
    weights = {t.name: tuple(t.dims) for t in g.initializer}
    stem = next(n for n in g.node if n.op_type == "Conv" and "/stem/" in n.name)
    assert weights[stem.input[1]] == (64, 12, 4, 4), "the 7x7 stride-2 stem on 2x2 blocks"


@pytest.mark.parametrize("size", [(64, 128), (128, 192)])
def test_the_fused_model_with_blocks_is_the_torch_model(size):
    torch.manual_seed(0)
    model = create_model("shared-light").eval()
    fused = FusedModel(model, size).eval()
    assert fused.blocks
    frame = np.random.default_rng(1).integers(0, 256, (1, *size, 3), dtype=np.uint8)
    with torch.no_grad():
        p, d = (t.numpy() for t in fused(torch.from_numpy(frame)))
    pt, dt = _plain(model, frame)
    np.testing.assert_allclose(p, pt, atol=1e-5)
    np.testing.assert_allclose(d, dt, rtol=1e-5)
    with pytest.raises(ValueError, match=f"reads {size[0]}x{size[1]} frames"):
        fused(torch.zeros(1, size[0] + 64, size[1], 3, dtype=torch.uint8))


def test_d_and_b_split_the_parameters_so_adapt_can_freeze_d():
    """bsn-adapt freezes ``depth_net`` and trains ``blindspot``: in the shared model the encoder must
    be on D's side of that split, and every parameter on exactly one side."""
    m = create_model("shared-light")
    d, b = ({id(p) for p in part.parameters()} for part in (m.depth_net, m.blindspot))
    assert not d & b and d | b == {id(p) for p in m.parameters()}
    assert {id(p) for p in m.depth_net.encoder.parameters()} <= d
