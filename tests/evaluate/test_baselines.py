"""The paper's baselines against hand-worked geometry: a camera 1.5 m over a flat road, a wall standing 5 m ahead."""

import numpy as np

from bsn_edge import semantics as sm
from bsn_edge.camera import Intrinsics
from bsn_edge.evaluate.baselines import RANGE_M, detection_2d, traversable_hidden

K = Intrinsics(100.0, 100.0, 100.0, 50.0, 200, 100)     # horizon at row 50, looking along the road
HEIGHT_M, WALL_M = 1.5, 5.0


def _scene() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Road below the horizon (its depth is the plane's: z = h fy / (v - cy)), sky above, and a wall across
    columns 80-119 from row 30 to the bottom, 5 m away; the wall's pixels."""
    v = np.arange(K.height, dtype=np.float64)[:, None] * np.ones((1, K.width))
    sem = np.where(v > K.cy, sm.ROAD, sm.SKY).astype(np.uint8)
    with np.errstate(divide="ignore"):
        depth = np.where(v > K.cy, HEIGHT_M * K.fy / (v - K.cy), 0.0)
    wall = np.zeros(sem.shape, bool)
    wall[30:, 80:120] = True
    sem[wall], depth[wall] = sm.BUILDING, WALL_M
    return sem, depth.astype(np.float32), wall


def test_road_behind_a_wall_is_hidden_where_the_ground_it_covers_lies_beyond_it_and_within_range():
    sem, depth, wall = _scene()
    hidden = traversable_hidden(sem, depth, K)
    v, u = np.mgrid[0:K.height, 0:K.width].astype(np.float64)
    with np.errstate(divide="ignore", invalid="ignore"):
        ground_z = np.where(v > K.cy, HEIGHT_M * K.fy / (v - K.cy), np.inf)   # where the pixel's ray meets the road
        ground_x = (u - K.cx) / K.fx * ground_z
    expected = wall & (ground_z > WALL_M + 0.5) & (np.hypot(ground_x, ground_z) <= RANGE_M)
    # the fitted plane is exact to float32: only a pixel on a boundary may differ
    assert (hidden != expected).sum() <= 2, np.argwhere(hidden != expected)
    assert hidden[60, 100] and not hidden[45, 100], "below the horizon behind the wall; above it the sky"
    assert not hidden[90, 100], "a ray meeting the road before the wall hides nothing"
    assert not hidden[:, :80].any() and not hidden[:, 120:].any(), "only the wall hides"


def test_nothing_is_hidden_without_a_road_to_fit_the_plane_to():
    sem, depth, _ = _scene()
    sem[sem == sm.ROAD] = sm.VEGETATION
    assert not traversable_hidden(sem, depth, K).any()


def test_detection_2d_is_the_road_users():
    sem = np.array([[sm.CAR, sm.ROAD, sm.PERSON, sm.BUILDING, sm.SKY]], np.uint8)
    assert detection_2d(sem).tolist() == [[True, False, True, False, False]]
