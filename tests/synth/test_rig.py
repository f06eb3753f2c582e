"""Clips with drawn cameras: the lens, the mounting and the hood against geometry done by hand."""

import cv2
import numpy as np
import pytest

from bsn_edge import semantics as sm
from bsn_edge.calibration import Calibration
from bsn_edge.synth import SynthConfig, make_clip, render_frames, write_clip
from bsn_edge.synth.rig import HEIGHT_M, HFOV_DEG, Rig


def test_drawn_cameras_cover_the_promised_ranges():
    rigs = [Rig.draw(s) for s in range(200)]
    hfov = [r.hfov_deg for r in rigs]
    assert HFOV_DEG[0] <= min(hfov) < 55 and 105 < max(hfov) <= HFOV_DEG[1]
    assert HEIGHT_M[0] <= min(r.height_m for r in rigs) and max(r.height_m for r in rigs) <= HEIGHT_M[1]
    assert 0.3 < np.mean([r.k1 < 0 for r in rigs]) < 0.7 and 0.2 < np.mean([r.hood > 0 for r in rigs]) < 0.6
    assert max(abs(r.yaw_deg) for r in rigs) > 2 and max(abs(r.roll_deg) for r in rigs) > 1.5


def seed_with(pred) -> int:
    return next(s for s in range(500) if pred(Rig.draw(s)))


def test_rendered_road_depth_is_the_ray_through_the_lens_meeting_the_ground():
    seed = seed_with(lambda r: r.k1 < -0.03 and abs(r.yaw_deg) > 1 and abs(r.roll_deg) > 0.5 and r.hood == 0)
    clip = make_clip(SynthConfig(frames=3, height=128, width=256, seed=seed, parked=0, traffic=0, pedestrians=0))
    fr = next(render_frames(clip))
    K, dist, T = clip.intrinsics, np.array(clip.rig.dist), clip.poses[0]
    checked = 0
    for v in range(80, 128, 6):
        for u in range(4, 252, 12):
            if fr.semantic[v, u] != sm.ROAD:
                continue
            ray = cv2.undistortPoints(np.array([[[u, v]]], float), K.K, dist).ravel()
            d_cam = np.array([ray[0], ray[1], 1.0])
            d_w = T[:3, :3] @ d_cam
            z = -T[2, 3] / d_w[2]            # the camera's z-depth where the ray meets the ground z = 0
            assert fr.depth[v, u] == pytest.approx(z, rel=0.03), (u, v)
            checked += 1
    assert checked > 20


def test_hood_is_neither_road_nor_blind_spot_and_the_camera_file_is_written(tmp_path):
    seed = seed_with(lambda r: r.hood > 0.1)
    out = write_clip(SynthConfig(frames=2, height=96, width=192, seed=seed), tmp_path / "c", video=False)
    rig = Rig.draw(seed)
    cal = Calibration.read(out / "calibration.json")
    assert cal.mounting == rig.mounting and cal.dist == rig.dist
    assert (cal.intrinsics.fx, cal.intrinsics.width) == pytest.approx((rig.intrinsics(192, 96).fx, 192))
    sem = cv2.imread(str(out / "semantic" / "000000.png"), cv2.IMREAD_UNCHANGED)
    depth = cv2.imread(str(out / "depth" / "000000.png"), cv2.IMREAD_UNCHANGED)
    bottom = sem[-2, 96]
    assert bottom == sm.IGNORE and depth[-2, 96] == 0
    assert (sem == sm.IGNORE).mean() > 0.05


def test_fixed_camera_is_the_earlier_one():
    clip = make_clip(SynthConfig(frames=2, camera="fixed"))
    assert clip.rig.hfov_deg == 80.0 and clip.rig.height_m == 1.5 and not clip.rig.dist and clip.rig.hood == 0
    with pytest.raises(ValueError, match="camera must be one of"):
        SynthConfig(camera="fisheye")
