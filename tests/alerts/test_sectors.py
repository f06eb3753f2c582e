"""Sector geometry on hand-made masks."""

import numpy as np
import pytest

from bsn_edge.alerts import SectorConfig, SectorGeometry
from bsn_edge.alerts.sectors import Sector, bearing_deg
from bsn_edge.camera import Intrinsics

K = Intrinsics(100.0, 100.0, 100.0, 50.0, 200, 100)   # 90 degree field of view


def edges(left: float, right: float) -> SectorConfig:
    """The three sectors, split at ``left`` and ``right`` degrees."""
    return SectorConfig(layout=(Sector("LEFT", left), Sector("CENTRE", right), Sector("RIGHT")))


def test_columns_split_by_bearing():
    g = SectorGeometry(K, edges(-10, 10))
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
    with pytest.raises(ValueError, match="must be right of the sector before it"):
        edges(10, -10)


def test_an_off_centre_principal_point_moves_the_sector_edges_with_it():
    """A camera whose principal point sits at 30 % of the width: straight ahead is column 60, not
    100, and the edges lie where tan(edge) * fx from it says (fx = 100: +-10 degrees at 17.6 px)."""
    k = Intrinsics(100.0, 100.0, 60.0, 50.0, 200, 100)
    g = SectorGeometry(k, edges(-10, 10))
    edge_px = 100.0 * np.tan(np.radians(10.0))
    for u in range(200):
        expected = 0 if u < 60 - edge_px else 2 if u > 60 + edge_px else 1
        assert g.column_sector[u] == expected, u
    mask = np.zeros((100, 200), bool)
    mask[60:70, 55:66] = True          # straight ahead of this camera: left of the picture's middle
    left, centre, right = g.read(mask, np.full((100, 200), 8.0, np.float32))
    assert centre.distance_m == pytest.approx(8.0) and left.distance_m is None and right.distance_m is None


def test_blind_spot_pixels_without_depth_give_no_distance():
    """Depth 0 is 'no depth' (the on-disk convention): such pixels are no obstacle at 0 m."""
    g = SectorGeometry(K)
    mask = np.ones((100, 200), bool)
    depth = np.zeros((100, 200), np.float32)
    assert all(r.score == 0 and r.distance_m is None for r in g.read(mask, depth))
    depth[80:90, 150:160] = 6.0        # one patch with depth: only it counts
    left, centre, right = g.read(mask, depth)
    assert right.distance_m == pytest.approx(6.0) and left.distance_m is None and centre.distance_m is None


def test_a_score_never_passes_one_however_much_of_a_sector_is_blind():
    """The whole left sector blind at 1 m: by the formula 1 - 1/30 of every pixel's nearness over 2 % of
    the sector's pixels, 48.3; the bus and the state machine take scores in [0, 1], so 1.0 exactly.
    Just under the cap, the formula's value passes unchanged."""
    g = SectorGeometry(K, SectorConfig(range_m=30.0, full_area=0.02))
    mask = np.zeros((100, 200), bool)
    mask[:, g.column_sector == 0] = True
    left = g.read(mask, np.full((100, 200), 1.0, np.float32))[0]
    assert pytest.approx(48.33, abs=0.01) == (1 - 1 / 30) / 0.02
    assert left.score == 1.0 and left.distance_m == pytest.approx(1.0)
    few = np.zeros((100, 200), bool)
    few[0, np.nonzero(g.column_sector == 0)[0][:3]] = True     # 3 pixels at 15 m: 3 * 0.5 / (0.02 * N)
    part = g.read(few, np.full((100, 200), 15.0, np.float32))[0]
    assert part.score == pytest.approx(1.5 / (0.02 * g.sector_pixels[0])) and part.score < 1


def test_the_layout_sizes_the_geometry_and_the_bus_refuses_a_frame_of_another_count():
    """Four sectors at -30, 0 and 30 degrees: each column falls where its bearing (atan((u - cx) / fx)) says, the
    readings are four, and an encoder of the three-sector bus refuses a four-sector frame."""
    from bsn_edge.alerts import AlertFrame, Level, SectorAlert, SystemState
    from bsn_edge.alerts.can_codec import CanEncoder

    cfg = SectorConfig(layout=[{"name": "FAR_LEFT", "to_deg": -30}, {"name": "LEFT", "to_deg": 0},
                               {"name": "RIGHT", "to_deg": 30}, {"name": "FAR_RIGHT"}])
    assert cfg.names == ("FAR_LEFT", "LEFT", "RIGHT", "FAR_RIGHT") and cfg.edges_deg == (-30.0, 0.0, 30.0)
    g = SectorGeometry(K, cfg)
    for u in range(200):
        b = np.degrees(np.arctan((u - 100.0) / 100.0))
        assert g.column_sector[u] == sum(b >= e for e in (-30, 0, 30)), u
    assert len(g.read(np.zeros((100, 200), bool), np.ones((100, 200)))) == 4
    none = SectorAlert(0.0, Level.NONE, None)
    with pytest.raises(ValueError, match="a frame of 4 sectors for a bus of 3"):
        CanEncoder().encode(AlertFrame(0.0, (none,) * 4, SystemState.OK, 10.0))
