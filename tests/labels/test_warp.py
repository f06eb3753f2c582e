"""T-frame labels on scenes whose geometry is known exactly."""

import cv2
import numpy as np
import pytest

from bsn_edge import semantics as sm
from bsn_edge.camera import Intrinsics, look_pose
from bsn_edge.labels import LabelConfig, Warper, label_frame, remove_small_components
from bsn_edge.labels.warp import look_agrees, smooth_grey
from bsn_edge.synth import Boxes, Renderer
from tests.fakes import car, world_with

FPS, SPEED, T = 5.0, 8.0, 25


def drive(layout, boxes, n=T + 1, intr=None, pose_error=None):
    """Render a straight drive along +y in the right lane; returns intrinsics, frames and poses."""
    intr = intr or Intrinsics.from_fov(256, 128, 80.0)
    r = Renderer(intr)
    world = world_with(layout, boxes)
    poses = np.stack([look_pose(np.array([1.6, i * SPEED / FPS, 1.5]), np.pi / 2, 0.02) for i in range(n)])
    frames = [r.render(world, T_wc) for T_wc in poses]
    if pose_error is not None:
        poses = np.stack([pose_error(i, p) for i, p in enumerate(poses)])
    return intr, frames, poses


def labels_for(intr, frames, poses, depth_tol=1.0, min_area=0):
    w = Warper(intr, poses[0, :3, 3])
    clouds = [w.cloud(f.depth, sm.is_traversable(f.semantic), p) for f, p in zip(frames, poses, strict=True)]
    f0 = frames[0]
    return label_frame(w, clouds[1:], f0.depth, sm.is_traversable(f0.semantic), f0.semantic == sm.SKY,
                       poses[0], LabelConfig(depth_tol=depth_tol, vis_range=16.0, min_area=min_area))


def test_parked_car_gives_blind_spots_behind_it_and_nowhere_else(straight_road):
    van = car(3.4, 12.0, 5.4, 18.0, h=2.4)  # parked in the right parking strip
    intr, frames, poses = drive(straight_road, van)
    lab = labels_for(intr, frames, poses, min_area=LabelConfig().min_area_px(128, 256))
    sem, gt = frames[0].semantic, frames[0].bsgt
    assert lab.omega.sum() > 30
    assert not (lab.omega & np.isin(sem, (sm.ROAD, sm.SIDEWALK, sm.TERRAIN, sm.SKY))).any()
    assert (sem[lab.omega] == sm.CAR).all(), "labels lie on the occluding car"
    precision = (lab.omega & gt).sum() / lab.omega.sum()
    # splatting rounds to the nearest pixel, so a few pixels at the car's outline disagree
    assert precision > 0.85, f"labels are true blind spots ({precision:.2f})"


def test_open_road_has_no_blind_spots(straight_road):
    intr, frames, poses = drive(straight_road, Boxes.empty())
    lab = labels_for(intr, frames, poses)
    assert not lab.omega.any()
    assert lab.warped.sum() > 1000  # plenty of road was warped, all of it visible


def test_depth_consistency_removes_residue_of_a_pose_error(straight_road):
    def nudge(i, T_wc):  # later poses drift sideways and yaw a little: road lands off the road
        if i == 0:
            return T_wc
        out = T_wc.copy()
        c, s = np.cos(0.01), np.sin(0.01)
        out[:3, :3] = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]]) @ out[:3, :3]
        out[0, 3] += 0.6
        return out
    intr, frames, poses = drive(straight_road, Boxes.empty(), pose_error=nudge)
    raw = labels_for(intr, frames, poses, depth_tol=0.0)  # filter off
    filtered = labels_for(intr, frames, poses, depth_tol=1.0)
    assert raw.omega.sum() > 100, "the pose error leaves warped road outside the visible road"
    assert filtered.omega.sum() < 0.05 * raw.omega.sum()
    assert filtered.removed_by_depth > 0.9 * raw.omega.sum()


def test_component_filter_removes_specks():
    m = np.zeros((60, 80), bool)
    m[10:30, 10:30] = True          # 400 px
    m[50:52, 70:72] = True          # 4 px speck
    m[40, 5] = True                 # 1 px
    out = remove_small_components(m, 100)
    assert out[10:30, 10:30].all() and out.sum() == 400
    assert np.array_equal(remove_small_components(m, 0), m)


def test_visibility_is_sky_or_near(straight_road):
    intr, frames, poses = drive(straight_road, car(0.7, 10.0, 2.5, 14.5), n=3)
    lab = labels_for(intr, frames[:1] + frames[1:], poses)
    f0 = frames[0]
    expected = (f0.semantic == sm.SKY) | ((f0.depth > 0) & (f0.depth < 16.0))
    assert np.array_equal(lab.visibility, expected)


def test_subsampled_warp_covers_like_the_full_warp(straight_road):
    """Taking coarse pixel grids for shrinking points leaves no holes: compare with margin -> full."""
    van = car(3.4, 12.0, 5.4, 18.0, h=2.4)
    intr, frames, poses = drive(straight_road, van)
    w = Warper(intr, poses[0, :3, 3])
    clouds = [w.cloud(f.depth, sm.is_traversable(f.semantic), p) for f, p in zip(frames, poses, strict=True)]
    fast, _, _ = w.splat(clouds[1:], poses[0], margin=0.5)
    full, _, _ = w.splat(clouds[1:], poses[0], margin=1e-9)
    assert fast.sum() == pytest.approx(full.sum(), rel=0.01)
    assert (full & ~fast).sum() <= 0.01 * full.sum()


def test_config_min_area_scales_with_image():
    cfg = LabelConfig()
    assert cfg.min_area_px(375, 1242) == 100
    assert cfg.min_area_px(256, 512) == 28
    assert LabelConfig(min_area=7).min_area_px(10, 10) == 7
    assert cfg.horizon_frames == 25 and cfg.name == "T5s"
    with pytest.raises(ValueError, match="spans no frame"):
        LabelConfig(rate=1.0, horizon_s=0.2)


def grey(frame) -> np.ndarray:
    return cv2.cvtColor(frame.rgb, cv2.COLOR_BGR2GRAY)


def bloated(frame, px: int):
    """Frame 0 as a segmentation model with a few pixels of outline error sees it: the car's mask
    grown over the road, the grown pixels at the car's depth."""
    is_car = frame.semantic == sm.CAR
    kernel = np.ones((2 * px + 1, 2 * px + 1), np.uint8)
    ring = cv2.dilate(is_car.astype(np.uint8), kernel).astype(bool) & ~is_car
    sem = np.where(ring, np.uint8(sm.CAR), frame.semantic)
    depth = np.where(ring, cv2.dilate(np.where(is_car, frame.depth, 0).astype(np.float32), kernel), frame.depth)
    return sem, depth.astype(np.float32), ring


def test_look_check_clears_road_a_bloated_outline_hides_and_keeps_true_blind_spots(straight_road):
    van = car(3.4, 12.0, 5.4, 18.0, h=2.4)
    intr, frames, poses = drive(straight_road, van)
    sem, depth, ring = bloated(frames[0], 3)
    w = Warper(intr, poses[0, :3, 3])
    clouds = [w.cloud(f.depth, sm.is_traversable(f.semantic), p, grey(f))
              for f, p in zip(frames[1:], poses[1:], strict=True)]

    def label(look_tol):
        return label_frame(w, clouds, depth, sm.is_traversable(sem), sem == sm.SKY, poses[0],
                           LabelConfig(depth_tol=1.0, vis_range=16.0, min_area=0, look_tol=look_tol),
                           grey=grey(frames[0]))
    off, on = label(0.0), label(8.0)
    gt = frames[0].bsgt

    assert (off.omega & ring).sum() > 30, "the bloated outline makes false blind spots on road"
    assert (on.omega & ring).sum() < 0.2 * (off.omega & ring).sum()
    assert (on.omega & gt).sum() > 0.85 * (off.omega & gt).sum(), "what the car hides stays a blind spot"
    assert on.removed_by_look >= (off.omega & ring).sum() - (on.omega & ring).sum()


def test_look_agrees_compares_patches_where_warped_road_landed():
    rng = np.random.default_rng(0)
    here = rng.integers(60, 120, (40, 60)).astype(np.uint8)
    same = here.astype(np.float32)
    brighter = same + 30.0                          # another surface: 30 grey levels apart
    nowhere = np.full(same.shape, np.nan, np.float32)
    warped = np.stack([np.where(np.arange(60) < 30, same, np.nan), nowhere]).astype(np.float32)
    seen = look_agrees(here, np.stack([smooth_grey(here), nowhere]), 8.0)
    assert seen.all(), "the same picture looks alike everywhere"
    assert not look_agrees(here, np.stack([smooth_grey(brighter), nowhere]), 8.0).any()
    half = look_agrees(here, np.where(np.isfinite(warped), smooth_grey(here), np.nan).astype(np.float32), 8.0)
    assert half[:, :30].all() and not half[:, 30:].any(), "only where road landed"


def test_pixels_without_depth_are_not_visible(straight_road):
    """V is sky or depth in (0, vis_range): a patch with no depth (0 on disk) outside the sky, on near
    road that is otherwise visible, drops out of V, and nothing else changes."""
    intr, frames, poses = drive(straight_road, Boxes.empty())
    full = labels_for(intr, frames, poses)
    f0 = frames[0]
    holed = f0.depth.copy()
    holed[100:120, 100:150] = 0.0
    assert full.visibility[100:120, 100:150].all() and not (f0.semantic[100:120, 100:150] == sm.SKY).any()
    w = Warper(intr, poses[0, :3, 3])
    clouds = [w.cloud(f.depth, sm.is_traversable(f.semantic), p) for f, p in zip(frames, poses, strict=True)]
    lab = label_frame(w, clouds[1:], holed, sm.is_traversable(f0.semantic), f0.semantic == sm.SKY, poses[0],
                      LabelConfig(depth_tol=1.0, vis_range=16.0, min_area=0))
    assert not lab.visibility[100:120, 100:150].any()
    outside = np.ones(holed.shape, bool)
    outside[100:120, 100:150] = False
    assert (lab.visibility[outside] == full.visibility[outside]).all()


def test_blind_spot_regions_joined_only_at_corners_are_one_region():
    """A staircase of ten 2x2 blocks, each touching the next only at a corner (40 pixels, 8-connected),
    stays whole above a minimum of 30; a staircase of five (20 pixels) goes, and so does a lone block."""
    mask = np.zeros((40, 60), bool)
    for k in range(10):
        mask[2 + 2 * k: 4 + 2 * k, 2 + 2 * k: 4 + 2 * k] = True
    for k in range(5):
        mask[2 + 2 * k: 4 + 2 * k, 40 + 2 * k: 42 + 2 * k] = True
    mask[35:37, 55:57] = True
    kept = remove_small_components(mask, 30)
    assert kept[:, :30].sum() == 40 and (kept[:, :30] == mask[:, :30]).all()
    assert not kept[:, 30:].any()
