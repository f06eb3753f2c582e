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
