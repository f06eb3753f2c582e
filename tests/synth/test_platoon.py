"""The platoon ahead of the ego: in its lane, at a following distance, rendered where it stands."""

import numpy as np
import pytest

from bsn_edge import semantics as sm
from bsn_edge.synth import SynthConfig, make_clip, render_frames
from bsn_edge.synth.platoon import EGO_NOSE, LEAD_HEADWAY, LEAD_STANDSTILL
from bsn_edge.synth.populate import QUEUE_SPEED, build_scenario


def _ahead(scenario):
    """Per agent box: distance of its near face ahead of the ego at t = 0 along the ego's heading,
    and its offset across it (by hand from the route's start)."""
    xy, yaw = scenario.route.at(0.0)
    fwd = np.array([np.cos(yaw[0]), np.sin(yaw[0])])
    side = np.array([-fwd[1], fwd[0]])
    b = scenario.world.agents.boxes
    corners = np.stack([np.stack([b.lo[:, 0], b.lo[:, 1]], 1), np.stack([b.hi[:, 0], b.hi[:, 1]], 1),
                        np.stack([b.lo[:, 0], b.hi[:, 1]], 1), np.stack([b.hi[:, 0], b.lo[:, 1]], 1)], 1)
    rel = corners - xy[0]
    return (rel @ fwd).min(axis=1), (rel @ side).mean(axis=1)


def test_the_platoon_follows_in_the_egos_lane_at_a_following_distance():
    for seed in range(4):
        cfg = SynthConfig(frames=40, style="town", seed=seed, lead=1.0, queue=0.0, parked=0,
                          pedestrians=0)
        sc = build_scenario(cfg)
        near, across = _ahead(sc)
        in_lane = (np.abs(across) < 1.0) & (near > 0)
        gap = near[in_lane].min() - EGO_NOSE
        assert LEAD_STANDSTILL[0] <= gap <= LEAD_STANDSTILL[1] + LEAD_HEADWAY[1] * sc.speed, (seed, gap)
        # without it, everything else of the seed is the same world
        bare = build_scenario(SynthConfig(frames=40, style="town", seed=seed, lead=0.0, queue=0.0, parked=0,
                                          pedestrians=0))
        np.testing.assert_array_equal(bare.world.static.lo, sc.world.static.lo)
        near0, across0 = _ahead(bare)
        assert not ((np.abs(across0) < 1.0) & (near0 > 0) & (near0 < EGO_NOSE + gap + 0.5)).any()


def test_no_platoon_on_an_empty_road_or_when_off():
    for cfg in (SynthConfig(frames=10, seed=1, traffic=0, lead=1.0, queue=1.0),
                SynthConfig(frames=10, seed=1, lead=0.0, queue=0.0)):
        near, across = _ahead(build_scenario(cfg))
        assert not ((np.abs(across) < 1.0) & (near > 0) & (near < 30)).any()
    with pytest.raises(ValueError, match="lead"):
        SynthConfig(lead=1.5)
    with pytest.raises(ValueError, match="queue"):
        SynthConfig(queue=-0.1)


@pytest.mark.slow     # 24 worlds built
def test_a_queued_clip_creeps_close_behind_a_platoon():
    for seed in range(4):
        sc = build_scenario(SynthConfig(frames=40, style="urban", seed=seed, lead=0.0, queue=1.0, parked=0,
                                        pedestrians=0))
        assert QUEUE_SPEED[0] <= sc.speed <= QUEUE_SPEED[1]
        near, across = _ahead(sc)
        gap = near[(np.abs(across) < 1.0) & (near > 0)].min() - EGO_NOSE
        assert LEAD_STANDSTILL[0] <= gap <= LEAD_STANDSTILL[1] + LEAD_HEADWAY[1] * QUEUE_SPEED[1], (seed, gap)
    # the queue draws from its own stream: a seed it passes by is the same world as with no queue at all
    pairs = {s: (build_scenario(SynthConfig(frames=10, seed=s, queue=0.5)),
                 build_scenario(SynthConfig(frames=10, seed=s, queue=0.0))) for s in range(20)}
    passed = [s for s, (a, b) in pairs.items() if a.speed == b.speed]
    assert 0 < len(passed) < 20
    a, b = pairs[passed[0]]
    np.testing.assert_array_equal(a.world.static.lo, b.world.static.lo)
    np.testing.assert_array_equal(a.world.agents.boxes.lo, b.world.agents.boxes.lo)


def test_the_lead_vehicle_is_drawn_at_its_distance():
    """Back-project the rendered vehicle pixels straight ahead: the nearest lie on its rear face."""
    cfg = SynthConfig(frames=2, height=128, width=256, style="town", seed=3, lead=1.0, parked=0,
                      pedestrians=0, camera="fixed")
    clip = make_clip(cfg)
    near, across = _ahead(clip.scenario)
    rear = near[(np.abs(across) < 1.0) & (near > 0)].min()
    fr = next(render_frames(clip))
    K, T = clip.intrinsics, clip.poses[0]
    xy, yaw = clip.scenario.route.at(0.0)
    fwd = np.array([np.cos(yaw[0]), np.sin(yaw[0]), 0.0])
    v, u = np.nonzero(np.isin(fr.semantic, sm.VEHICLES) & (np.abs(np.arange(256) - K.cx) < 8)[None])
    assert len(u) > 20
    rays = np.stack([(u - K.cx) / K.fx, (v - K.cy) / K.fy, np.ones(len(u))], 1) * fr.depth[v, u][:, None]
    world = rays @ T[:3, :3].T + T[:3, 3]
    ahead = (world[:, :2] - xy[0]) @ fwd[:2]
    assert np.percentile(ahead, 5) == pytest.approx(rear, abs=0.1)
