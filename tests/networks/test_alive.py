"""Alive channels, against channels killed by hand: a convolution's row of zeros, a batch-norm scale of
zero (or under the epsilon), a batch norm of another width that is not the convolution's."""

import torch

from bsn_edge.networks.alive import SCALE_EPS, alive_channels


def test_dead_channels_are_counted_where_they_were_killed():
    torch.manual_seed(0)
    net = torch.nn.Sequential(torch.nn.Conv2d(3, 6, 3), torch.nn.BatchNorm2d(6), torch.nn.ReLU(),
                              torch.nn.Conv2d(6, 6, 3, groups=6), torch.nn.ReLU(),
                              torch.nn.Conv2d(6, 4, 1), torch.nn.BatchNorm2d(4))
    with torch.no_grad():
        net[0].weight[1].zero_()                  # weights all zero
        net[1].weight[2] = 0.0                    # silenced by its norm
        net[1].weight[3] = 0.5 * SCALE_EPS        # under the epsilon
        net[1].weight[4] = -2.0 * SCALE_EPS       # over it, negative: alive
        net[3].weight[5].zero_()                  # a depthwise channel
        net[5].weight[0, :3] = 0.0                # some weights zero, not all: alive
    a = alive_channels(net)
    assert [(la.name, la.channels, la.alive) for la in a.layers] == [("0", 6, 3), ("3", 6, 5), ("5", 4, 4)]
    assert (a.alive, a.channels) == (12, 16) and a.share == 0.75 and a.weak == ()
    assert a.line() == "alive channels 75.0 % (12 of 16; 0 of 3 convolutions under 50 % alive)"
    with torch.no_grad():
        net[5].weight[1:].zero_()
    assert [la.name for la in alive_channels(net).weak] == ["5"]


def test_a_norm_of_another_width_is_not_taken_for_the_convolutions():
    net = torch.nn.Sequential(torch.nn.Conv2d(3, 4, 1), torch.nn.BatchNorm2d(5))
    with torch.no_grad():
        net[1].weight.zero_()
    assert alive_channels(net).alive == 4


def test_weights_walking_to_zero_behind_a_norm_are_dead_before_fp16_rounds_them_to_zero():
    """Adam with L2 shrinks a convolution's row behind a batch norm while the norm's scale stays: the norm
    divides the row's size out, so only the row's size tells. Under 1e-6 it is dead, in fp32 already."""
    torch.manual_seed(0)
    net = torch.nn.Sequential(torch.nn.Conv2d(3, 4, 3), torch.nn.BatchNorm2d(4))
    with torch.no_grad():
        net[0].weight[1] *= 1e-7 / net[0].weight[1].abs().max()     # every weight at most 1e-7
        net[0].weight[2] *= 2e-6 / net[0].weight[2].abs().max()     # its largest at 2e-6: alive
    assert alive_channels(net).alive == 3
    assert net[0].weight[1].half().eq(0).any()                      # fp16 storage rounds such a row away
    assert alive_channels(net.half()).alive == 3


def test_a_channel_the_norm_saw_vary_by_nothing_is_dead():
    """Where a channel's running variance is under a hundredth of the norm's epsilon, the norm passes on
    under a tenth of what it varies by: checked on the norm itself, against a channel of healthy variance."""
    from bsn_edge.networks.alive import VAR_SHARE

    net = torch.nn.Sequential(torch.nn.Conv2d(3, 3, 1, bias=False), torch.nn.BatchNorm2d(3)).eval()
    eps = net[1].eps
    with torch.no_grad():
        net[0].weight.copy_(torch.eye(3).view(3, 3, 1, 1))
        net[1].running_var.copy_(torch.tensor([1.0, 0.5 * VAR_SHARE * eps, 2.0 * VAR_SHARE * eps]))
    assert [la.alive for la in alive_channels(net).layers] == [2]
    x = torch.zeros(1, 3, 1, 1)
    x[0, :, 0, 0] = torch.sqrt(net[1].running_var)                   # one standard deviation of each
    gain = net(x)[0, :, 0, 0] / (x[0, :, 0, 0] / torch.sqrt(net[1].running_var))
    assert gain[0] > 0.99 and gain[1] < 0.1 < gain[2]
