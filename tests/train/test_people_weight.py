"""``train.people_weight``: the BCE weight of the blind-spot pixels on people and what they ride, and on
nothing else (not their negatives, not a car's positives)."""

import pytest
import torch

from bsn_edge import semantics as sm
from bsn_edge.train.config import MAX_PEOPLE_WEIGHT, TrainConfig
from bsn_edge.train.trainer import bce_weights


def _batch() -> dict[str, torch.Tensor]:
    sem = torch.tensor([[[sm.PERSON, sm.RIDER, sm.BICYCLE, sm.MOTORCYCLE, sm.PERSON, sm.CAR, sm.ROAD, sm.BUS]]])
    blind = torch.tensor([[[[1.0, 1.0, 1.0, 1.0, 0.0, 1.0, 1.0, 1.0]]]])
    return {"semantic": sem, "blindspot": blind}


def test_people_and_cyclists_positives_weigh_people_weight_and_all_else_one():
    w = bce_weights(_batch(), 4.0)
    assert w is not None and w.shape == (1, 1, 1, 8)
    assert w.flatten().tolist() == [4.0, 4.0, 4.0, 4.0, 1.0, 1.0, 1.0, 1.0]


def test_a_weight_of_one_is_the_plain_mean():
    assert bce_weights(_batch(), 1.0) is None


@pytest.mark.parametrize("bad", [0.5, 0.0, -1.0, MAX_PEOPLE_WEIGHT + 1])
def test_a_weight_outside_its_range_is_refused_by_name(bad: float):
    with pytest.raises(ValueError, match=r"train\.people_weight"):
        TrainConfig(people_weight=bad)


def test_revive_without_weights_to_revive_is_refused():
    with pytest.raises(ValueError, match=r"train\.revive"):
        TrainConfig(revive=True)
    assert TrainConfig(revive=True, init="runs/a").revive
