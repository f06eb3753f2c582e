"""The real-box benchmark's scoring on masks whose answer is known, and its box file."""

import json

import numpy as np

from bsn_edge.benchmarks.bench_realboxes import BOXES, MARKED_SHARE, OCCLUDERS, score, summary


def test_a_box_is_marked_from_the_share_of_its_pixels_and_open_road_is_pixel_weighted():
    mask = np.zeros((100, 200), bool)
    mask[0:10, 0:20] = True              # 200 px: all of box a
    mask[50:53, 100:110] = True          # 30 px of box b's 200: 15 %
    mask[90:91, 0:10] = True             # 10 px of the big open road's 2,000
    boxes = [{"box": [0, 0, 20, 10], "class": "car", "near": True},
             {"box": [100, 50, 120, 60], "class": "person", "near": False},
             {"box": [150, 50, 170, 60], "class": "cyclist", "near": True},
             {"box": [0, 80, 100, 100], "class": "open_road"},
             {"box": [180, 0, 200, 10], "class": "open_road"}]
    rows = score(mask, boxes)
    assert [r.get("marked") for r in rows] == [True, MARKED_SHARE <= 0.15, False, None, None]
    s = summary(rows)
    assert s["near"] == [1, 2] and s["all"] == [2, 3]
    assert s["groups"]["people"] == {"near": [0, 0], "all": [1, 1]}
    assert s["groups"]["cyclists"] == {"near": [0, 1], "all": [0, 1]}
    assert s["open_road_flagged"] == round(10 / 2200, 4) and s["open_road_boxes_over_2pct"] == [0, 2]


def test_the_box_file_is_well_formed():
    spec = json.loads(BOXES.read_text())
    for f in spec["frames"]:
        w, h = f["size"]
        for b in f["boxes"]:
            x0, y0, x1, y1 = b["box"]
            assert 0 <= x0 < x1 <= w and 0 <= y0 < y1 <= h, (f, b)
            assert b["class"] in (*OCCLUDERS, "open_road")
            assert ("near" in b) == (b["class"] != "open_road")
