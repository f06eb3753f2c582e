"""The teacher benchmark's scoring on label maps whose answer is known."""

import numpy as np
import torch

from bsn_edge import semantics as sm
from bsn_edge.benchmarks.bench_realteacher import KINDS, labels, outside, score, summary


def _masks(ids: np.ndarray) -> dict[str, np.ndarray]:
    masks = {k: np.isin(ids, v) for k, v in KINDS.items()}
    masks["view"] = np.ones(ids.shape, bool)
    return masks


def test_a_box_is_seen_from_its_kind_and_labels_outside_the_boxes_are_counted():
    ids = np.full((100, 200), sm.ROAD, np.uint8)
    ids[0:10, 0:20] = sm.CAR                 # all of the car's box
    ids[50:60, 100:120] = sm.CAR             # a car where a person is boxed: not the person
    ids[50:52, 150:170] = sm.BICYCLE         # 40 of the cyclist's 200 px: 20 %
    ids[0:10, 100:110] = sm.BUILDING
    ids[95:100, 190:200] = sm.PERSON         # 50 px of a person outside every box
    ids[20:30, 0:10] = sm.TRUCK              # 100 px of a truck outside every box
    boxes = [{"box": [0, 0, 20, 10], "class": "car", "near": True},
             {"box": [100, 50, 120, 60], "class": "person", "near": False},
             {"box": [150, 50, 170, 60], "class": "cyclist", "near": True},
             {"box": [100, 0, 120, 10], "class": "open_road"}]
    masks = _masks(ids)
    rows = score(masks, boxes)
    assert [r["share"] for r in rows] == [1.0, 0.0, 0.2, 0.5]
    assert [r.get("seen") for r in rows] == [True, False, True, None]
    # the car under the person's box is inside a box: not counted outside
    assert outside(masks, boxes) == (150, 20000)
    s = summary(rows, [outside(masks, boxes)])
    assert s["near"] == [2, 2] and s["all"] == [2, 3] and s["near_mean_share"] == 0.6
    assert s["groups"]["people"] == {"near": [0, 0], "all": [0, 1]}
    assert s["open_road_labelled_road"] == 0.5 and s["objects_outside_boxes"] == 0.0075


class _Halves(torch.nn.Module):
    """A teacher that calls the left half of what it sees road and the right half car."""

    def forward(self, x):
        logits = torch.zeros(x.shape[0], sm.NUM_CLASSES, *x.shape[2:])
        w = x.shape[3]
        logits[:, sm.ROAD, :, : w // 2] = 1
        logits[:, sm.CAR, :, w // 2:] = 1
        return logits, None


def test_labels_come_back_at_the_model_frames_size_from_the_teachers_scale():
    seen = []

    class Spy(_Halves):
        def forward(self, x):
            seen.append(tuple(x.shape))
            return super().forward(x)

    ids = labels(Spy(), 0.5, np.zeros((64, 128, 3), np.uint8))
    assert seen == [(1, 3, 32, 64)] and ids.shape == (64, 128)
    assert (ids[:, :64] == sm.ROAD).all() and (ids[:, 64:] == sm.CAR).all()
