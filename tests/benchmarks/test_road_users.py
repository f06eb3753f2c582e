"""Road-user boxes drawn from a synthetic frame's semantics and depth, against a frame built by hand."""

import numpy as np
import pytest

from bsn_edge import semantics as sm
from bsn_edge.benchmarks.bench_realboxes import score, summary
from bsn_edge.benchmarks.road_users import MIN_PIXELS, NEAR_M, road_users


def scene() -> tuple[np.ndarray, np.ndarray]:
    sem = np.full((80, 160), sm.BUILDING, np.uint8)
    depth = np.full(sem.shape, 50.0, np.float32)
    sem[40:, :] = sm.ROAD
    sem[40:, 120:] = sm.SIDEWALK
    sem[30:50, 10:40] = sm.CAR                  # near car standing on the road
    depth[30:50, 10:40] = 0.5 * NEAR_M
    sem[30:45, 40:60] = sm.CAR                  # a farther car right behind it: a depth edge parts them
    depth[30:45, 40:60] = 1.5 * NEAR_M
    sem[25:45, 125:130] = sm.PERSON             # a person on the sidewalk
    depth[25:45, 125:130] = 8.0
    sem[20:44, 80:86] = sm.RIDER                # a rider on a bicycle: one cyclist
    sem[32:48, 78:90] = np.where(sem[32:48, 78:90] == sm.RIDER, sm.RIDER, sm.BICYCLE)
    depth[20:48, 78:90] = 12.0
    sem[5:15, 60:80] = sm.CAR                   # a car on a billboard: it touches no road
    depth[5:15, 60:80] = 9.0
    sem[45:49, 100:104] = sm.PERSON             # too small to draw
    depth[45:49, 100:104] = 6.0
    return sem, depth


def test_each_road_user_that_stands_on_road_or_sidewalk_gets_its_box_cut_at_depth_edges():
    boxes = sorted(road_users(*scene()), key=lambda b: b["box"])
    assert MIN_PIXELS > 4 * 4              # the small person is below the size drawn
    assert boxes == [
        {"class": "car", "box": [10, 30, 40, 50], "near": True},
        {"class": "car", "box": [41, 30, 60, 45], "near": False},   # less the column behind the edge
        {"class": "cyclist", "box": [78, 20, 90, 48], "near": True},
        {"class": "person", "box": [125, 25, 130, 45], "near": True},
    ]


def test_unseen_pixels_draw_no_box_and_mismatched_sizes_are_refused():
    sem, depth = scene()
    seen = np.ones(sem.shape, bool)
    seen[:, 100:] = False
    assert {b["class"] for b in road_users(sem, depth, seen)} == {"car", "cyclist"}
    with pytest.raises(ValueError, match="differ in size"):
        road_users(sem, depth[:, :-1])


def test_the_boxes_score_as_the_real_ones_do():
    sem, depth = scene()
    mask = np.zeros(sem.shape, bool)
    mask[30:50, 10:40] = True                   # the whole near car
    mask[25:28, 125:130] = True                 # 15 of the person's 100 px
    s = summary(score(mask, road_users(sem, depth)))
    assert s["near"] == [2, 3] and s["all"] == [2, 4]
    assert s["groups"]["people"] == {"near": [1, 1], "all": [1, 1]}
    assert s["groups"]["cyclists"] == {"near": [0, 1], "all": [0, 1]}
