"""Sector geometry on hand-made masks."""

import numpy as np
import pytest

from bsn_edge.alerts import SectorConfig, SectorGeometry
from bsn_edge.alerts.sectors import bearing_deg
from bsn_edge.camera import Intrinsics

K = Intrinsics(100.0, 100.0, 100.0, 50.0, 200, 100)   # 90 degree field of view


def test_columns_split_by_bearing():
    g = SectorGeometry(K, SectorConfig(left_edge_deg=-10, right_edge_deg=10))
    assert bearing_deg(100.0, K) == 0.0
    for u in range(200):
        b = bearing_deg(u, K)
        assert g.column_sector[u] == (0 if b < -10 else 2 if b > 10 else 1)


def test_scores_and_distances_per_sector():
    g = SectorGeometry(K, SectorConfig(range_m=20, full_area=0.05))
    mask = np.zeros((100, 200), bool)
    depth = np.full((100, 200), 10.0, np.float32)
    mask[60:70, 20:40] = True          # left, at 10 m
    depth[60:70, 20:40] = 5.0
    mask[60:62, 190:195] = True        # right, beyond range
    depth[60:62, 190:195] = 25.0
    left, centre, right = g.read(mask, depth)
    assert left.distance_m == pytest.approx(5.0) and 0 < left.score <= 1
    expected = 200 * (1 - 5.0 / 20) / (0.05 * g.sector_pixels[0])
    assert left.score == pytest.approx(min(expected, 1.0))
    assert centre.score == 0 and centre.distance_m is None
    assert right.score == 0 and right.distance_m is None


def test_nearer_is_more_hazardous():
    g = SectorGeometry(K)
    mask = np.zeros((100, 200), bool)
    mask[50:52, 95:105] = True
    near = g.read(mask, np.full((100, 200), 3.0, np.float32))[1]
    far = g.read(mask, np.full((100, 200), 25.0, np.float32))[1]
    assert near.score > far.score > 0
    assert near.distance_m == pytest.approx(3.0)


def test_config_is_validated():
    with pytest.raises(ValueError):
        SectorConfig(left_edge_deg=10, right_edge_deg=-10)
