"""Every registry entry: shapes and gradient flow on tiny inputs."""

import pytest
import torch

from bsn_edge.networks import MODELS, create_model, create_teacher
from bsn_edge.networks.resnet import ResNetEncoder


@pytest.mark.parametrize("name", list(MODELS))
def test_shapes_and_gradients(name):
    torch.manual_seed(0)
    m = create_model(name)
    x = torch.randn(2, 3, 64, 128)
    given = torch.rand(2, 1, 64, 128) * 50 if m.oracle_depth else None    # ground-truth depth, for an oracle
    logits, depth, feats = m(x, given)
    assert logits.shape == (2, 1, 64, 128) and depth.shape == (2, 1, 64, 128)
    assert feats.ndim == 4 and feats.shape[0] == 2
    assert (depth > 0).all()
    (logits.mean() + depth.log().mean() + feats.mean()).backward()
    for part in (m.blindspot, m.depth_net):
        grads = [p.grad for p in part.parameters() if p.requires_grad]
        assert all(g is not None and torch.isfinite(g).all() for g in grads), name
        assert any(g.abs().sum() > 0 for g in grads), name


def test_unknown_model_lists_the_valid_names():
    with pytest.raises(ValueError, match="small-light"):
        create_model("tiny")


def test_encoders_publish_their_channels():
    assert ResNetEncoder(18).out_channels == (64, 128, 256, 512)
    assert ResNetEncoder(50).out_channels == (256, 512, 1024, 2048)
    feats = ResNetEncoder(18, in_channels=4, output_stride=32)(torch.randn(1, 4, 64, 128))
    assert [f.shape[1] for f in feats] == [64, 128, 256, 512]
    assert [f.shape[2] for f in feats] == [16, 8, 4, 2]


def test_depth_input_is_used_only_when_asked():
    assert create_model("small").blindspot.encoder.in_channels == 4
    assert create_model("small-d").blindspot.encoder.in_channels == 3


def test_teacher_outputs_cityscapes_classes():
    logits, feats = create_teacher("resnet18", 32)(torch.randn(1, 3, 64, 128))
    assert logits.shape == (1, 19, 64, 128) and feats.shape[1] == 32
