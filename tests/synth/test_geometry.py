"""Geometry of the synthetic renderer against analytic truth."""

import numpy as np

from bsn_edge import semantics as sm
from bsn_edge.sequence.images import depth_to_png16
from bsn_edge.synth import Boxes, Renderer
from bsn_edge.synth.boxes import KIND_VEHICLE
from tests.fakes import car, ego_pose, world_with


def analytic_ground(intr, T_wc):
    """Ray-plane intersection with z = 0 in float64, independent of the renderer."""
    u, v = np.meshgrid(np.arange(intr.width), np.arange(intr.height))
    rays = np.stack([(u - intr.cx) / intr.fx, (v - intr.cy) / intr.fy, np.ones_like(u, float)], -1)
    d = rays @ T_wc[:3, :3].T
    C = T_wc[:3, 3]
    with np.errstate(divide="ignore"):
        t = np.where(d[..., 2] < 0, -C[2] / d[..., 2], np.inf)
    return t, C[0] + t * d[..., 0], C[1] + t * d[..., 1]


def test_ground_depth_is_ray_plane_distance(straight_road, small_camera):
    T = ego_pose(pitch=0.05)
    fr = Renderer(small_camera).render(world_with(straight_road, Boxes.empty()), T)
    t, _, _ = analytic_ground(small_camera, T)
    ground = np.isfinite(t) & (t < 250.0)
    assert ground.sum() > 0.3 * t.size
    np.testing.assert_allclose(fr.depth[ground], t[ground], rtol=1e-5)
    # and the 16-bit encoding keeps it within half a step
    enc = depth_to_png16(fr.depth).astype(np.float64) / 256.0
    assert np.abs(enc[ground] - t[ground]).max() <= 0.5 / 256 + 1e-6


def test_sky_is_exactly_zero_depth(straight_road, small_camera):
    fr = Renderer(small_camera).render(world_with(straight_road, car(0.7, 15, 2.5, 19.5)), ego_pose())
    assert np.array_equal(fr.semantic == sm.SKY, fr.depth == 0)
    assert (fr.semantic == sm.SKY).any()


def test_box_ahead_hides_the_road_behind_it(straight_road, small_camera):
    x0, y0, x1, y1 = 0.7, 15.0, 2.5, 19.5
    T = ego_pose()
    fr = Renderer(small_camera, bs_range=50.0).render(world_with(straight_road, car(x0, y0, x1, y1)), T)
    is_car = fr.semantic == sm.CAR
    assert is_car.sum() > 100
    assert fr.bsgt.any()
    assert not (fr.bsgt & ~is_car).any(), "blind spots only on the occluder's pixels"
    # where the continued ray lands decides it, exactly as the definition says
    t, gx, gy = analytic_ground(small_camera, T)
    under = (gx >= x0) & (gx <= x1) & (gy >= y0) & (gy <= y1)
    trav = np.isin(straight_road.classify(gx, gy), sm.TRAVERSABLE)
    in_range = np.hypot(gx - T[0, 3], gy - T[1, 3]) <= 50.0
    expected = is_car & np.isfinite(t) & trav & ~under & in_range
    mismatch = (expected != fr.bsgt).sum()
    assert mismatch <= 0.01 * is_car.sum(), f"{mismatch} pixels disagree with the analytic labels"
    # rays that land under the box are not blind spots, rays that pass over it are
    assert (is_car & under).any() and not (fr.bsgt & under).any()
    assert (gy[fr.bsgt] > y0).all(), "hidden ground lies past the occluder's near face"


def test_ground_under_a_box_is_not_a_blind_spot_even_behind_another(straight_road, small_camera):
    near, far = car(0.7, 10.0, 2.5, 14.0, h=2.5), car(0.7, 16.0, 2.5, 20.0)
    fr = Renderer(small_camera).render(world_with(straight_road, Boxes.concat([near, far])), ego_pose())
    _t, gx, gy = analytic_ground(small_camera, ego_pose())
    under_far = (gx >= 0.7) & (gx <= 2.5) & (gy >= 16.0) & (gy <= 20.0)
    assert (under_far & (fr.semantic == sm.CAR)).any()
    assert not (fr.bsgt & under_far).any()


def test_beyond_range_is_not_a_blind_spot(straight_road, small_camera):
    w = world_with(straight_road, car(0.7, 15, 2.5, 19.5))
    near_only = Renderer(small_camera, bs_range=14.0).render(w, ego_pose())  # car starts at 15 m
    wide = Renderer(small_camera, bs_range=50.0).render(w, ego_pose())
    assert not near_only.bsgt.any()
    assert wide.bsgt.any()


def test_box_behind_camera_is_invisible(straight_road, small_camera):
    fr = Renderer(small_camera).render(world_with(straight_road, car(0.7, -10, 2.5, -5)), ego_pose())
    assert not (fr.semantic == sm.CAR).any()


def test_box_straddling_the_camera_plane_is_drawn(straight_road, small_camera):
    # a parked car beside the ego, half of it behind the camera
    fr = Renderer(small_camera).render(world_with(straight_road, car(3.3, -3, 5.1, 5.0)), ego_pose())
    assert (fr.semantic[:, small_camera.width // 2:] == sm.CAR).sum() > 200


def test_boxes_culled_before_projection_show_on_no_pixel(small_camera):
    """Frustum culling against brute force: every box left out has no point of its surface in
    the picture in front of the camera; boxes with points in view are all kept."""
    rng = np.random.default_rng(4)
    lo = np.c_[rng.uniform(-40, 40, (400, 2)), np.zeros(400)]
    hi = lo + rng.uniform(0.2, 6.0, (400, 3))
    boxes = Boxes.make(lo, hi, sm.CAR, KIND_VEHICLE, (0.5, 0.5, 0.5))
    r = Renderer(small_camera)
    T_wc = ego_pose()
    kept = set(r._screen_boxes(boxes, T_wc)[0].tolist())
    g = np.linspace(0.0, 1.0, 9)
    unit = np.stack(np.meshgrid(g, g, g, indexing="ij"), -1).reshape(-1, 3)
    R_cw, C = T_wc[:3, :3].T, T_wc[:3, 3]
    k = small_camera
    for b in range(len(boxes)):
        p = (boxes.lo[b] + unit * (boxes.hi[b] - boxes.lo[b]) - C) @ R_cw.T
        z = p[:, 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            u, v = k.fx * p[:, 0] / z + k.cx, k.fy * p[:, 1] / z + k.cy
        seen = ((z > r.near) & (u >= 0) & (u <= k.width) & (v >= 0) & (v <= k.height)).any()
        if seen:
            assert b in kept, f"box {b} has points in view but was culled"
    assert 20 < len(kept) < 300, "the scene has boxes both in view and out of it"
