"""Reviving dead channels: every channel killed by hand comes back (counted by ``alive_channels``), the
living ones are bit-for-bit what they were, and the revived ones start at their layer's living scale."""

import copy

import torch

from bsn_edge.networks.alive import alive_channels
from bsn_edge.networks.revive import REVIVED_SCALE, UNNORMED_SCALE, revive


def _net() -> torch.nn.Sequential:
    torch.manual_seed(0)
    net = torch.nn.Sequential(torch.nn.Conv2d(3, 8, 3, padding=1), torch.nn.BatchNorm2d(8), torch.nn.ReLU(),
                              torch.nn.Conv2d(8, 8, 3, padding=1, groups=8), torch.nn.BatchNorm2d(8), torch.nn.ReLU(),
                              torch.nn.Conv2d(8, 4, 1))
    with torch.no_grad():
        net[1].weight.copy_(torch.linspace(0.5, 1.2, 8))
        net[4].weight.copy_(torch.linspace(0.8, 1.5, 8))
        for i in (1, 5):                                  # zero weights and a zero scale: Adam + L2's kill
            net[0].weight[i].zero_()
            net[1].weight[i] = 0.0
            net[1].running_var[i] = 1e-6
        net[4].weight[2] = 0.0                            # silenced by its norm alone
        net[6].weight[3].zero_()                          # no norm after it
    return net


def test_every_dead_channel_comes_back_and_no_living_one_moves():
    net = _net()
    before = copy.deepcopy(net)
    assert alive_channels(net).alive == 20 - 4
    assert revive(net, seed=3) == 4
    assert alive_channels(net).alive == alive_channels(net).channels == 20
    living0 = [0, 2, 3, 4, 6, 7]
    assert torch.equal(net[0].weight[living0], before[0].weight[living0])
    assert torch.equal(net[1].weight[living0], before[1].weight[living0])
    assert torch.equal(net[4].weight[[0, 1, 3]], before[4].weight[[0, 1, 3]])
    assert torch.equal(net[6].weight[[0, 1, 2]], before[6].weight[[0, 1, 2]])
    assert torch.equal(net[6].bias, before[6].bias)
    # a revived norm: at the living scales' median, its shift kept, its statistics reset
    assert REVIVED_SCALE == 1.0
    median = float(before[1].weight.detach()[living0].median())
    assert torch.allclose(net[1].weight[[1, 5]], torch.full((2,), REVIVED_SCALE * median))
    assert torch.equal(net[1].bias, before[1].bias)
    assert net[1].running_var[[1, 5]].tolist() == [1.0, 1.0] and net[1].running_mean[[1, 5]].tolist() == [0.0, 0.0]
    # the re-drawn rows have the spread of the living ones (no norm after: UNNORMED_SCALE of it, a tenth)
    assert UNNORMED_SCALE == 0.1
    living_std = float(before[0].weight.detach()[living0].std())
    assert 0.5 * living_std < float(net[0].weight[[1, 5]].std()) < 2.0 * living_std
    assert float(net[6].weight[3].abs().max()) < float(before[6].weight[[0, 1, 2]].abs().max())


def test_a_living_network_is_left_as_it_is_and_the_draw_is_the_seeds():
    net = torch.nn.Sequential(torch.nn.Conv2d(3, 4, 3), torch.nn.BatchNorm2d(4))
    before = copy.deepcopy(net)
    assert revive(net) == 0
    assert all(torch.equal(a, b) for a, b in zip(net.state_dict().values(), before.state_dict().values(), strict=True))
    a, b = _net(), _net()
    revive(a, seed=1), revive(b, seed=1)
    assert torch.equal(a[0].weight, b[0].weight)
