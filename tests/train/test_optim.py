"""Training's optimizer: the fused Adam is the same update as the per-tensor one, and either resumes
the other's state."""

import torch

from bsn_edge.train.config import TrainConfig
from bsn_edge.train.optim import Optimizer


def _net() -> torch.nn.Module:
    torch.manual_seed(0)
    return torch.nn.Sequential(torch.nn.Conv2d(3, 8, 3), torch.nn.ReLU(), torch.nn.Conv2d(8, 2, 1))


def _steps(net: torch.nn.Module, optim: Optimizer, n: int, seed: int) -> None:
    g = torch.Generator().manual_seed(seed)
    for _ in range(n):
        x = torch.rand(4, 3, 12, 12, generator=g)
        optim.step((net(x) ** 2).mean())


def test_the_fused_adam_takes_the_per_tensor_adams_steps_and_resumes_its_state():
    t = TrainConfig()
    plain, fused, mixed = _net(), _net(), _net()
    o_plain = Optimizer(plain.parameters(), 1e-2, 20, t)
    o_fused = Optimizer(fused.parameters(), 1e-2, 20, t, fused=True)
    _steps(plain, o_plain, 10, seed=1)
    _steps(fused, o_fused, 10, seed=1)
    for a, b, start in zip(plain.parameters(), fused.parameters(), _net().parameters(), strict=True):
        assert not torch.allclose(a, start)                 # the steps moved every parameter
        assert torch.allclose(a, b, rtol=1e-5, atol=1e-6)
    # five per-tensor steps, then the fused optimizer resumes from that state: the same ten steps
    o_mixed = Optimizer(mixed.parameters(), 1e-2, 20, t)
    g = torch.Generator().manual_seed(1)
    xs = [torch.rand(4, 3, 12, 12, generator=g) for _ in range(10)]
    for x in xs[:5]:
        o_mixed.step((mixed(x) ** 2).mean())
    resumed = Optimizer(mixed.parameters(), 1e-2, 20, t, fused=True)
    resumed.load_state_dict(o_mixed.state_dict())
    for x in xs[5:]:
        resumed.step((mixed(x) ** 2).mean())
    for a, b in zip(plain.parameters(), mixed.parameters(), strict=True):
        assert torch.allclose(a, b, rtol=1e-5, atol=1e-6)


class _HalfIdle(torch.nn.Module):
    """A convolution and its batch norm, four of whose eight channels the head never reads: they get no
    gradient of their own, only what the weight decay gives them."""

    def __init__(self) -> None:
        super().__init__()
        torch.manual_seed(0)
        self.conv = torch.nn.Conv2d(3, 8, 3, bias=False)
        self.bn = torch.nn.BatchNorm2d(8)
        self.head = torch.nn.Conv2d(8, 1, 1)
        self.register_buffer("read", torch.tensor([1.0] * 4 + [0.0] * 4).view(1, 8, 1, 1))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.head(torch.relu(self.bn(self.conv(x))) * self.read)


def _train_half_idle(t: TrainConfig, steps: int = 300) -> _HalfIdle:
    net = _HalfIdle()
    optim = Optimizer(net.parameters(), 1e-2, 10 * steps, t)
    g = torch.Generator().manual_seed(1)
    for _ in range(steps):
        x = torch.rand(4, 3, 12, 12, generator=g)
        optim.step(((net(x) - x.mean()) ** 2).mean())
    return net


def test_the_old_adam_with_l2_kills_channels_without_gradient_and_the_default_keeps_them():
    """Adam normalises L2's gradient like any other: an idle channel's batch-norm scale walks from 1 to 0 at
    the learning rate's pace (100 steps at 1e-2) and stays there. Decoupled decay on weights only leaves
    the scale alone and shrinks the weights by lr x decay of themselves a step (0.9999**300 = 0.97)."""
    from bsn_edge.networks.alive import alive_channels

    old = _train_half_idle(TrainConfig(optimizer="adam", weight_decay=5e-4))
    assert old.bn.weight[4:].abs().max() < 1e-3 and old.conv.weight[4:].abs().max() < 1e-6
    assert alive_channels(old).layers[0].alive == 4
    new = _train_half_idle(TrainConfig())
    assert torch.equal(new.bn.weight[4:].detach(), torch.ones(4))
    start = _HalfIdle().conv.weight[4:].detach()
    assert torch.allclose(new.conv.weight[4:].detach(), start * (1 - 1e-2 * 1e-2) ** 300, rtol=0.02)
    assert alive_channels(new).layers[0].alive == 8


def test_decoupled_decay_reaches_weights_only_in_every_group_keeping_its_learning_rate():
    from bsn_edge.train.optim import param_groups

    net = torch.nn.Sequential(torch.nn.Conv2d(3, 4, 3), torch.nn.BatchNorm2d(4), torch.nn.Conv2d(4, 2, 1))
    groups = param_groups(net, net[0], 1e-3, 0.5)
    opt = Optimizer(groups, 1e-3, 10, TrainConfig()).opt
    assert isinstance(opt, torch.optim.AdamW)
    seen = {}
    for g in opt.param_groups:
        for p in g["params"]:
            seen[id(p)] = (g["weight_decay"], g["lr"])
    named = dict(net.named_parameters())
    assert seen[id(named["0.weight"])] == (1e-2, 5e-4)        # the encoder's share of the rate kept
    assert seen[id(named["0.bias"])] == (0.0, 5e-4)
    assert seen[id(named["1.weight"])] == (0.0, 1e-3) and seen[id(named["1.bias"])] == (0.0, 1e-3)
    assert seen[id(named["2.weight"])] == (1e-2, 1e-3) and seen[id(named["2.bias"])] == (0.0, 1e-3)
    assert len(seen) == len(named)


def test_a_state_of_the_other_optimizer_is_refused_naming_the_settings_that_resume_it():
    import pytest

    net = _HalfIdle()
    old = Optimizer(net.parameters(), 1e-2, 10, TrainConfig(optimizer="adam", weight_decay=5e-4))
    with pytest.raises(ValueError, match=r'train\.optimizer = "adam"'):
        Optimizer(net.parameters(), 1e-2, 10, TrainConfig()).load_state_dict(old.state_dict())
