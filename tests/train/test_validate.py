"""The validation figures of a training run, against hand-counted truth."""

import math

import torch

from bsn_edge import semantics as sm
from bsn_edge.train.validation import validate


class ConstantNet(torch.nn.Module):
    """Answers the same depth everywhere and a blind spot nowhere."""

    def __init__(self, depth_m: float) -> None:
        super().__init__()
        self.depth = torch.nn.Parameter(torch.tensor(depth_m))

    def forward(self, image):
        n, _, h, w = image.shape
        return torch.full((n, 1, h, w), -10.0), self.depth.expand(n, 1, h, w), torch.zeros(n, 4, 2, 2)


class OneBatch:
    def __init__(self, batch):
        self.b = batch

    def evenly(self, frames):
        yield self.b


def test_road_depth_is_read_apart_within_its_range():
    # one 2x4 frame: road at 10 m (twice), 20 m and 50 m (beyond the range), a car at 10 m, sky
    sem = torch.tensor([[[sm.ROAD, sm.ROAD, sm.ROAD, sm.ROAD], [sm.CAR, sm.SKY, sm.ROAD, sm.CAR]]])
    depth = torch.tensor([[[[10.0, 10.0, 20.0, 50.0], [10.0, 100.0, 4.0, 40.0]]]])
    batch = {"image": torch.zeros(1, 3, 2, 4), "depth": depth, "semantic": sem,
             "blindspot": torch.zeros(1, 1, 2, 4), "visibility": torch.ones(1, 1, 2, 4),
             "sky": (sem == sm.SKY)[:, None]}
    got = validate(ConstantNet(12.0), OneBatch(batch), 8)
    # road within 5-40 m: 10, 10, 20 (50 and 4 are outside) -> |12-10|/10 twice, |12-20|/20
    assert math.isclose(got["road_abs_rel"], (0.2 + 0.2 + 0.4) / 3, rel_tol=1e-6)
    # every pixel with depth but the sky: 10, 10, 20, 50, 10, 4, 40
    every = (0.2 + 0.2 + 0.4 + 38 / 50 + 0.2 + 2.0 + 28 / 40) / 7
    assert math.isclose(got["abs_rel"], every, rel_tol=1e-6)


def test_no_road_in_range_is_said_not_zero():
    sem = torch.full((1, 2, 2), sm.CAR)
    batch = {"image": torch.zeros(1, 3, 2, 2), "depth": torch.full((1, 1, 2, 2), 10.0), "semantic": sem,
             "blindspot": torch.zeros(1, 1, 2, 2), "visibility": torch.ones(1, 1, 2, 2),
             "sky": (sem == sm.SKY)[:, None]}
    assert math.isnan(validate(ConstantNet(10.0), OneBatch(batch), 8)["road_abs_rel"])
