"""The model frame against analytic geometry: a flat road seen from two heights, and straight ahead."""

import math

import cv2
import numpy as np
import pytest

from bsn_edge.camera import Intrinsics
from bsn_edge.model_frame import ModelFrame
from bsn_edge.mounting import Mounting, warp_maps

RAW = Intrinsics(1000.0, 1000.0, 640.0, 360.0, 1280, 720)
DIST = (-0.2, 0.04, 0.0, 0.0, 0.0)
MODEL = Intrinsics.from_fov(256, 128, 80.0)
REF = Mounting(1.5, pitch_deg=1.5)
USER = Mounting(1.2, pitch_deg=-1.5, yaw_deg=2.0, roll_deg=1.0)


def road_z(K: Intrinsics, m: Mounting, dist=()) -> np.ndarray:
    """z-depth of the flat road at every pixel of a camera ``m.height_m`` above it (0 = no road),
    by intersecting each pixel's ray with the plane: no code under test involved."""
    u, v = np.meshgrid(np.arange(K.width, dtype=np.float64), np.arange(K.height, dtype=np.float64))
    n = cv2.undistortPoints(np.stack([u.ravel(), v.ravel()], -1)[:, None], K.K, np.asarray(dist, float))
    rays = np.c_[n.reshape(-1, 2), np.ones(u.size)]           # camera frame, unit z
    # the level frame's "down" seen from the camera is R @ (0, 1, 0)
    down = m.rotation() @ np.array([0.0, 1.0, 0.0])
    along = rays @ down
    z = np.where(along > 1e-6, m.height_m / np.maximum(along, 1e-6), 0.0)
    return z.reshape(K.height, K.width).astype(np.float32)


def test_depth_goes_to_the_user_camera_by_the_height_ratio_and_its_own_axis():
    # a fine model grid, so that nearest-neighbour sampling (a row of the map) stays small next to
    # what is tested: the height ratio and the change of axis
    big = Intrinsics.from_fov(1024, 512, 80.0)
    mf = ModelFrame(RAW, DIST, USER, big, REF)
    # an ideal model reads the road as the reference camera at the reference height would
    got = mf.depth_to_raw(road_z(big, REF))
    truth = road_z(RAW, USER, DIST)
    sel = (truth > 5) & (truth < 30) & (got > 0)
    assert sel.sum() > 50000
    rel = np.abs(got[sel] - truth[sel]) / truth[sel]
    assert np.median(rel) < 0.005 and np.percentile(rel, 95) < 0.02
    # the height ratio is what makes it right: reading the model's depth as metres is 1.5 / 1.2 off
    plain = ModelFrame(RAW, DIST, Mounting(1.5, USER.pitch_deg, USER.yaw_deg, USER.roll_deg), big, REF)
    off = plain.depth_to_raw(road_z(big, REF))[sel] / truth[sel]
    assert np.median(off) == pytest.approx(1.5 / 1.2, rel=0.01)


def test_a_user_cameras_depth_reads_as_the_reference_camera_would():
    mf = ModelFrame(RAW, DIST, USER, MODEL, REF)
    got = mf.depth_to_model(road_z(RAW, USER, DIST))
    want = road_z(MODEL, REF)
    sel = (want > 5) & (want < 40) & (got > 0) & mf.seen
    rel = np.abs(got[sel] - want[sel]) / want[sel]
    assert sel.sum() > 2000 and np.median(rel) < 0.01 and np.percentile(rel, 95) < 0.04


def test_straight_ahead_of_the_car_is_the_model_cameras_centre_column_whatever_the_yaw():
    for yaw in (-8.0, 0.0, 6.0):
        user = Mounting(1.3, pitch_deg=2.0, yaw_deg=yaw, roll_deg=0.0)
        mf = ModelFrame(RAW, (), user, MODEL, REF)
        # the car's axis, far away, seen by the yawed camera: left of its centre when yawed right
        d = user.rotation() @ np.array([0.0, 0.0, 1.0])
        u = RAW.cx + RAW.fx * d[0] / d[2]
        p, y = math.radians(2.0), math.radians(yaw)
        assert u == pytest.approx(RAW.cx - RAW.fx * math.tan(y) / math.cos(p), abs=1e-6)
        frame = np.zeros((RAW.height, RAW.width), np.uint8)
        c = round(u)
        frame[:, c - 2:c + 3] = 255
        col = mf.to_model(frame)[64].astype(float)
        centre = (col * np.arange(MODEL.width)).sum() / col.sum()
        assert centre == pytest.approx(MODEL.cx, abs=0.6)


def test_outputs_come_back_on_the_raw_pixels_and_outside_the_view_is_marked():
    """Each raw pixel gets the model pixel its ray meets: undistorted by OpenCV, turned from the
    user's mounting to the model's, projected by the model camera (no code under test)."""
    mf = ModelFrame(RAW, DIST, USER, MODEL, REF)
    u, v = np.meshgrid(np.arange(RAW.width, dtype=np.float64), np.arange(RAW.height, dtype=np.float64))
    n = cv2.undistortPoints(np.stack([u.ravel(), v.ravel()], -1)[:, None], RAW.K, np.asarray(DIST, float))
    rays = np.c_[n.reshape(-1, 2), np.ones(u.size)] @ (REF.rotation() @ USER.rotation().T).T
    col = (MODEL.fx * rays[:, 0] / rays[:, 2] + MODEL.cx).reshape(u.shape)
    row = (MODEL.fy * rays[:, 1] / rays[:, 2] + MODEL.cy).reshape(u.shape)
    cols = np.tile(np.arange(MODEL.width, dtype=np.float32), (MODEL.height, 1))
    rows = np.tile(np.arange(MODEL.height, dtype=np.float32)[:, None], (1, MODEL.width))
    back_col, back_row = mf.to_raw(cols), mf.to_raw(rows)
    assert back_col.shape == (RAW.height, RAW.width)
    inside = (col > 1) & (col < MODEL.width - 2) & (row > 1) & (row < MODEL.height - 2)
    assert inside.mean() > 0.9
    assert np.abs(back_col - col)[inside].max() < 1e-3 and np.abs(back_row - row)[inside].max() < 1e-3
    beyond = (col < -1) | (col > MODEL.width) | (row < -1) | (row > MODEL.height)
    assert beyond.sum() > 1000 and not back_col[beyond].any() and not back_row[beyond].any()
    # the raw camera sees 65 degrees across, the model camera 80: the model frame's sides are unseen
    assert not mf.seen[:, 0].any() and mf.seen[MODEL.height // 2, 40:-40].all()
    with pytest.raises(ValueError, match="built for"):
        mf.to_model(np.zeros((100, 100, 3), np.uint8))


@pytest.mark.parametrize("k", [2, 3, 4])
def test_a_frame_k_times_finer_is_the_area_average_of_k_by_k_blocks(k):
    """The model camera itself, k times finer: the picture in the model frame is OpenCV's own area
    resize of the raw frame with the binomial low-pass after it, pixel for pixel (no remap code)."""
    raw = MODEL.scaled(MODEL.width * k, MODEL.height * k)
    frame = np.random.default_rng(k).integers(0, 256, (raw.height, raw.width, 3), dtype=np.uint8)
    mf = ModelFrame(raw, (), REF, MODEL, REF)
    assert mf.shrink == k
    area = cv2.resize(frame, (MODEL.width, MODEL.height), interpolation=cv2.INTER_AREA)
    want = cv2.filter2D(area, -1, np.outer([1, 2, 1], [1, 2, 1]) / 16.0, borderType=cv2.BORDER_REFLECT_101)
    assert np.abs(mf.to_model(frame).astype(int) - want).max() <= 1


@pytest.mark.parametrize("factor, k", [(1.2, 1), (1.875, 1), (2.5, 2), (3.8, 3), (7.1, 7)])
def test_a_finer_frame_is_shrunk_in_blocks_about_their_centres(factor, k):
    """From twice the model's scale, a shrink by the whole factor k = floor(factor) (the remap is
    left between 1 and 1.5), below it to the model's scale; either way every model pixel sees the
    raw column its ray meets, and a frame cut to a multiple of k still fills the model frame."""
    w, h = round(MODEL.width * factor), round(MODEL.height * factor)
    raw = MODEL.scaled(w, h)
    mf = ModelFrame(raw, (), REF, MODEL, REF)
    assert mf.shrink == k
    ramp = np.tile(np.arange(w, dtype=np.float32), (h, 1))    # each pixel holds its own column
    out = mf.to_model(ramp)[MODEL.height // 2]
    # model column u sees raw column (u + 0.5) * w / W - 0.5 (pixel centres); a block of k columns
    # averages to its centre, so a misplaced block shows as (k - 1) / 2 columns off. The last few
    # model columns meet the < k raw columns the cut left out, mirrored.
    want = (np.arange(MODEL.width) + 0.5) * w / MODEL.width - 0.5
    assert np.abs(out - want)[8:-8].max() < 0.02 * k + 0.02


@pytest.mark.parametrize("factor", [1.55, 1.875, 2.5, 3.8])
def test_stripes_finer_than_the_model_can_show_come_out_grey_not_aliased(factor):
    """One-pixel stripes are beyond the model camera's resolution whenever the raw frame is finer
    than 1.5x: low-passed they come out as their mean grey; sampled without it they would alias
    into false stripes (standard deviation ~73 grey levels)."""
    w, h = round(MODEL.width * factor), round(MODEL.height * factor)
    mf = ModelFrame(MODEL.scaled(w, h), (), REF, MODEL, REF)
    stripes = np.tile((np.arange(w) % 2 * 255).astype(np.uint8), (h, 1))
    out = mf.to_model(stripes)[8:-8, 8:-8].astype(float)
    assert abs(out.mean() - 127.5) < 3 and out.std() < 5


@pytest.mark.parametrize("scale", [1, 3])
def test_where_the_raw_camera_sees_nothing_the_picture_is_mirrored_as_opencv_mirrors_it(scale):
    """A raw camera narrower than the model camera (50 degrees across against 80), turned and rolled:
    the model frame's sides are unseen. The picture there is OpenCV's own BORDER_REFLECT remap of the
    raw frame (after the same block shrink and low-pass, on the same fixed-point maps), and no tap of
    the maps falls outside it."""
    raw = Intrinsics.from_fov(MODEL.width * scale, MODEL.height * scale, 50.0)
    mf = ModelFrame(raw, (), USER, MODEL, REF)
    assert 0.2 < 1 - mf.seen.mean() < 0.8
    frame = np.random.default_rng(scale).integers(0, 256, (raw.height, raw.width, 3), dtype=np.uint8)
    mx, my = warp_maps(raw, (), USER, MODEL, REF)
    k = mf.shrink
    src = frame
    if k > 1:
        w, h = raw.width // k, raw.height // k
        src = cv2.resize(frame[:h * k, :w * k], (w, h), interpolation=cv2.INTER_AREA)
        mx, my = (mx - (k - 1) / 2) / k, (my - (k - 1) / 2) / k
    if mf.prefilter:
        src = cv2.GaussianBlur(src, (3, 3), 0)
    fixed = cv2.convertMaps(mx.astype(np.float32), my.astype(np.float32), cv2.CV_16SC2)
    want = cv2.remap(src, *fixed, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REFLECT)
    # the same up to one grey level where a coordinate sits on a rounding tie of the fixed point
    assert np.abs(mf.to_model(frame).astype(int) - want).max() <= 1
    taps = mf.fixed_maps[0]
    assert taps[..., 0].min() >= 0 and taps[..., 0].max() <= src.shape[1] - 1
    assert taps[..., 1].min() >= 0 and taps[..., 1].max() <= src.shape[0] - 1


@pytest.mark.parametrize(("width", "height", "hfov"), [(640, 150, 70.0), (180, 400, 40.0), (300, 90, 100.0)])
def test_the_model_sees_only_rays_that_land_inside_the_raw_picture_on_both_axes(width, height, hfov):
    """A pinhole camera mounted as the model camera, shorter (or narrower) than it: model pixel (u, v)
    looks along x = (u - cx) / fx, y = (v - cy) / fy, which the raw camera images at cx' + fx' x,
    cy' + fy' y; the model sees it when that lies within the raw picture (pixel centres 0 .. n - 1, so
    -0.5 .. n - 0.5). Rows above and below, columns left and right: worked from the tangents here."""
    raw = Intrinsics.from_fov(width, height, hfov)
    model = Intrinsics.from_fov(512, 256, 80.0)
    mf = ModelFrame(raw, (), REF, model, REF)
    x = (np.arange(model.width) - model.cx) / model.fx
    y = (np.arange(model.height) - model.cy) / model.fy
    cols = np.abs(raw.cx + raw.fx * x - (raw.width - 1) / 2) <= raw.width / 2
    rows = np.abs(raw.cy + raw.fy * y - (raw.height - 1) / 2) <= raw.height / 2
    assert not rows.all() or not cols.all(), "the raw camera must miss part of the model's view"
    np.testing.assert_array_equal(mf.seen, rows[:, None] & cols[None, :])
