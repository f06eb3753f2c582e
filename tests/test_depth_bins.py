"""Depth errors by distance bin, against values worked out by hand."""

import numpy as np
import pytest

from bsn_edge.metrics import DepthBins, depth_by_bin

BINS = ((5, 10), (10, 20), (20, 40))


def test_errors_per_bin_by_hand():
    truth = np.array([6.0, 8.0, 12.0, 15.0, 30.0, 50.0, 3.0])
    pred = np.array([6.6, 7.2, 12.0, 21.0, 0.0, 50.0, 3.0])   # +10 %, -10 %, exact, +40 %, none, out of bins
    got = depth_by_bin(pred, truth, BINS)
    assert set(got) == {"5-10", "10-20"}, "a bin with no predicted point is left out"
    assert got["5-10"] == pytest.approx({"n": 2, "abs_rel": 0.1, "median_ratio": 1.0, "delta_1.25": 1.0})
    assert got["10-20"] == pytest.approx({"n": 2, "abs_rel": 0.2, "median_ratio": 1.2, "delta_1.25": 0.5})
    assert set(depth_by_bin(pred, truth, BINS, min_points=3)) == set()


def test_pooled_over_frames_weighs_every_point_alike():
    pooled = DepthBins(BINS)
    pooled.add(np.full(100, 11.0), np.full(100, 10.0))      # 100 points 10 % long
    pooled.add(np.full(300, 13.0), np.full(300, 10.0))      # 300 points 30 % long
    pooled.add(np.full(5, 7.5), np.full(5, 6.0))            # 5 points 25 % long, the other bin
    assert pooled.abs_rel() == pytest.approx({"5-10": 0.25, "10-20": (100 * 0.1 + 300 * 0.3) / 400, "20-40": None})
