"""Whole clips: consistency of every output, the route, determinism."""

import numpy as np
import pytest

from bsn_edge import semantics as sm
from bsn_edge.synth import SynthConfig, make_clip, render_frames


@pytest.fixture(scope="module", params=["town", "suburb"])
def rendered(request):
    cfg = SynthConfig(frames=30, height=96, width=192, fps=5.0, style=request.param, seed=3)
    clip = make_clip(cfg)
    return clip, list(render_frames(clip))


def test_blind_spots_never_on_sky_or_visible_ground(rendered):
    _, frames = rendered
    total = 0
    for fr in frames:
        visible_ground = np.isin(fr.semantic, (sm.ROAD, sm.SIDEWALK, sm.TERRAIN, sm.SKY))
        assert not (fr.bsgt & visible_ground).any()
        total += fr.bsgt.sum()
    assert total > 0, "a clip through a street scene has blind spots"


def test_sky_and_zero_depth_coincide(rendered):
    _, frames = rendered
    for fr in frames:
        assert np.array_equal(fr.semantic == sm.SKY, fr.depth == 0)
        assert np.isfinite(fr.depth).all() and (fr.depth >= 0).all()


def test_outputs_have_the_contract_shapes(rendered):
    clip, frames = rendered
    h, w = clip.config.height, clip.config.width
    fr = frames[0]
    assert fr.rgb.shape == (h, w, 3) and fr.rgb.dtype == np.uint8
    assert fr.depth.shape == (h, w) and fr.depth.dtype == np.float32
    assert fr.semantic.dtype == np.uint8 and set(np.unique(fr.semantic)) <= set(range(19))
    assert fr.bsgt.dtype == bool


def test_poses_follow_the_route(rendered):
    clip, _ = rendered
    cfg, sc = clip.config, clip.scenario
    xy, yaw = sc.route.at(sc.speed * clip.times)
    np.testing.assert_allclose(clip.poses[:, :2, 3], xy, atol=1e-9)
    np.testing.assert_allclose(clip.poses[:, 2, 3], clip.rig.height_m)
    # undo the mounting: the car's level camera looks along the heading, parallel to the road
    level = clip.poses[:, :3, :3] @ clip.rig.mounting.rotation()
    heading = np.stack([np.cos(yaw), np.sin(yaw), np.zeros_like(yaw)], 1)
    np.testing.assert_allclose(level[:, :, 2], heading, atol=1e-9)
    # and the optical axis itself dips by the pitch
    np.testing.assert_allclose(clip.poses[:, 2, 2], -np.sin(clip.pitch), atol=1e-9)
    # the camera moves forward along its heading by speed / fps each frame (chords of arcs are shorter)
    step = np.linalg.norm(np.diff(clip.poses[:, :2, 3], axis=0), axis=1)
    assert np.all(step <= sc.speed / cfg.fps + 1e-6)
    assert np.median(step) == pytest.approx(sc.speed / cfg.fps, rel=1e-3)
    for T in clip.poses:  # rotations are proper
        np.testing.assert_allclose(T[:3, :3] @ T[:3, :3].T, np.eye(3), atol=1e-9)
        assert np.linalg.det(T[:3, :3]) == pytest.approx(1.0)


def test_route_turns_at_intersections():
    cfg = SynthConfig(frames=400, height=32, width=64, fps=10.0, seed=5)
    clip = make_clip(cfg)
    turns = clip.scenario.route.turns
    assert turns, "a 40 s clip crosses several intersections and turns at one of them"
    _, yaw = clip.scenario.route.at(clip.scenario.speed * clip.times)
    # straight runs keep the heading; each turn changes it by a quarter turn
    total = yaw[-1] - yaw[0]
    n_left = sum(t["direction"] == "left" for t in turns)
    n_right = len(turns) - n_left
    assert total == pytest.approx((n_left - n_right) * np.pi / 2, abs=0.02) or \
        clip.times[-1] * clip.scenario.speed < turns[-1]["at_m"] + 15


def test_same_seed_same_frames_other_seed_other_frames():
    cfg = SynthConfig(frames=3, height=48, width=96, seed=11)
    a = [f.rgb for f in render_frames(make_clip(cfg))]
    b = [f.rgb for f in render_frames(make_clip(cfg))]
    c = [f.rgb for f in render_frames(make_clip(SynthConfig(frames=3, height=48, width=96, seed=12)))]
    assert all(np.array_equal(x, y) for x, y in zip(a, b, strict=True))
    assert not np.array_equal(a[0], c[0])



def test_frames_rendered_in_worker_processes_are_the_frames_rendered_here():
    """The parent has used OpenCV's thread pool before its workers start (a forked worker could
    inherit that pool mid-lock and hang): they are spawned, and render exactly what one process does."""
    clip = make_clip(SynthConfig(frames=20, height=48, width=96, seed=13))
    here = list(render_frames(clip))
    workers = list(render_frames(clip, workers=2))
    assert len(workers) == len(here) == 20
    for a, b in zip(here, workers, strict=True):
        assert np.array_equal(a.rgb, b.rgb) and np.array_equal(a.depth, b.depth)
        assert np.array_equal(a.semantic, b.semantic) and np.array_equal(a.bsgt, b.bsgt)
    # a chosen few, alone or in workers, are those frames of the whole clip
    pick = [0, 2, 4, 6, 8, 10, 12, 14, 16, 18, 19]
    for alone in (list(render_frames(clip, indices=pick)), list(render_frames(clip, workers=2, indices=pick))):
        assert len(alone) == len(pick)
        for i, fr in zip(pick, alone, strict=True):
            assert np.array_equal(fr.rgb, here[i].rgb) and np.array_equal(fr.depth, here[i].depth)
    with pytest.raises(ValueError, match="frame indices"):
        list(render_frames(clip, indices=[20]))

@pytest.mark.parametrize("bad", [
    {"frames": 0}, {"style": "desert"}, {"fps": 0.0}, {"height": 8}, {"far": 400.0},
    {"bs_range": 300.0}, {"traffic": -1.0},
])
def test_config_rejects_bad_values(bad):
    with pytest.raises(ValueError):
        SynthConfig(**bad)


def test_unknown_style_lists_the_valid_ones():
    with pytest.raises(ValueError, match=r"suburb.*town|town.*suburb"):
        SynthConfig(style="desert")
