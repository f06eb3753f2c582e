"""The warp into the model camera against geometry computed by hand and OpenCV's projectPoints."""

import math

import cv2
import numpy as np
import pytest

from bsn_edge.camera import Intrinsics
from bsn_edge.mounting import INVERSE_BAND_ROWS, Mounting, inverse_maps, warp_maps

RAW = Intrinsics(1150.0, 1150.0, 650.0, 370.0, 1280, 720)
DIST = (-0.24, 0.05, 0.001, -0.0005, 0.0)
MODEL = Intrinsics.from_fov(256, 128, 80.0)


def test_angles_turn_the_optical_axis_the_documented_way():
    fwd = np.array([0.0, 0.0, 1.0])
    # looking down by p: the level horizon is above the image centre, at cy - fy tan(p)
    d = Mounting(1.3, pitch_deg=4.0).rotation() @ fwd
    v = RAW.cy + RAW.fy * d[1] / d[2]
    assert v == pytest.approx(RAW.cy - RAW.fy * math.tan(math.radians(4.0)))
    # turned right by y: straight ahead appears left of centre
    d = Mounting(1.3, yaw_deg=5.0).rotation() @ fwd
    assert RAW.cx + RAW.fx * d[0] / d[2] == pytest.approx(RAW.cx - RAW.fx * math.tan(math.radians(5.0)))
    r = Mounting(1.3, 2.0, -3.0, 1.5).rotation()
    np.testing.assert_allclose(r @ r.T, np.eye(3), atol=1e-12)
    with pytest.raises(ValueError, match="pitch_deg"):
        Mounting(1.3, pitch_deg=45.0)


@pytest.mark.parametrize("pitch", [-6.0, -1.5, 2.0, 7.0])
@pytest.mark.parametrize("yaw", [-9.0, 0.0, 4.0])
def test_from_forward_inverts_the_rotation_for_either_sign(pitch, yaw):
    """The car's forward axis as a pitched and yawed camera sees it gives back that pitch and yaw.
    Alone each against the picture's geometry (a camera looking down by p sees straight ahead p
    above its centre; one turned right by y sees it y to the left), together through ``rotation``."""
    p, y = math.radians(pitch), math.radians(yaw)
    alone = Mounting.from_forward(np.array([0.0, -math.sin(p), math.cos(p)]), 1.3)
    assert alone.pitch_deg == pytest.approx(pitch) and alone.yaw_deg == pytest.approx(0.0, abs=1e-9)
    alone = Mounting.from_forward(np.array([-math.sin(y), 0.0, math.cos(y)]), 1.3)
    assert alone.yaw_deg == pytest.approx(yaw) and alone.pitch_deg == pytest.approx(0.0, abs=1e-9)
    seen = Mounting(1.3, pitch, yaw).rotation() @ np.array([0.0, 0.0, 1.0])
    both = Mounting.from_forward(seen * 3.0, 1.3)      # any length
    assert both.pitch_deg == pytest.approx(pitch) and both.yaw_deg == pytest.approx(yaw)


def level_ray(model: Intrinsics, m: Mounting, u: float, v: float) -> np.ndarray:
    ray = np.linalg.solve(model.K, [u, v, 1.0])
    return m.rotation().T @ ray


def test_warp_samples_where_the_same_ray_meets_the_raw_camera():
    user, ref = Mounting(1.25, pitch_deg=-1.5, yaw_deg=2.0, roll_deg=0.8), Mounting(1.5, pitch_deg=1.0)
    mx, my = warp_maps(RAW, DIST, user, MODEL, ref)
    assert mx.shape == (128, 256) and mx.dtype == np.float32
    for u, v in ((10, 10), (128, 64), (250, 120), (40, 100)):
        ray = user.rotation() @ level_ray(MODEL, ref, u, v)
        want, _ = cv2.projectPoints(ray[None], np.zeros(3), np.zeros(3), RAW.K, np.array(DIST))
        assert (mx[v, u], my[v, u]) == pytest.approx(tuple(want.ravel()), abs=0.02)
    # no distortion, same camera and mounting: the identity
    ix, iy = warp_maps(MODEL, (), ref, MODEL, ref)
    np.testing.assert_allclose(ix, np.arange(256)[None].repeat(128, 0), atol=1e-3)
    np.testing.assert_allclose(iy, np.arange(128)[:, None].repeat(256, 1), atol=1e-3)


def test_inverse_brings_model_pixels_back_onto_the_raw_frame():
    user, ref = Mounting(1.25, pitch_deg=-1.5, yaw_deg=2.0), Mounting(1.5)
    bx, by = inverse_maps(RAW, DIST, user, MODEL, ref)
    assert bx.shape == (720, 1280)
    # the maps are made a band of rows at a time: rows either side of a band's edge and the last row too
    edges = [(u, v) for v in (INVERSE_BAND_ROWS - 1, INVERSE_BAND_ROWS, 2 * INVERSE_BAND_ROWS, 719) for u in (0, 1279)]
    for u, v in ((100, 100), (640, 360), (1200, 650), *edges):
        ray = user.rotation() @ level_ray(MODEL, ref, float(bx[v, u]), float(by[v, u]))
        back, _ = cv2.projectPoints(ray[None], np.zeros(3), np.zeros(3), RAW.K, np.array(DIST))
        assert tuple(back.ravel()) == pytest.approx((u, v), abs=0.05)
