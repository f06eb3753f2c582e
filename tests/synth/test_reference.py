"""The fast renderer (screen rectangles, near-plane clipping, occlusion culling) against a
brute-force reference that tests every ray against every box."""

import numpy as np
import pytest

from bsn_edge import semantics as sm
from bsn_edge.synth import Renderer, SynthConfig, make_clip


def brute_force(boxes, layout, intr, T_wc, far, bs_range, near=0.05):
    u, v = np.meshgrid(np.arange(intr.width), np.arange(intr.height))
    d = np.stack([(u - intr.cx) / intr.fx, (v - intr.cy) / intr.fy, np.ones(u.shape)], -1) @ T_wc[:3, :3].T
    d = d.reshape(-1, 3)
    C = T_wc[:3, 3]
    with np.errstate(divide="ignore", invalid="ignore"):
        tg = np.where(d[:, 2] < 0, -C[2] / d[:, 2], np.inf)
        ground = tg < far
        inv = 1.0 / d
        t1 = (boxes.lo[None] - C) * inv[:, None]     # [P, N, 3]
        t2 = (boxes.hi[None] - C) * inv[:, None]
    tn = np.minimum(t1, t2).max(-1)
    tf = np.maximum(t1, t2).min(-1)
    hit = (tn <= tf) & (tn > near)
    tn = np.where(hit, tn, np.inf)
    first = tn.argmin(1)
    tbox = tn[np.arange(len(tn)), first]
    obj = tbox < np.where(ground, tg, far)
    gx, gy = C[0] + tg * d[:, 0], C[1] + tg * d[:, 1]
    inside = ((gx[:, None] >= boxes.lo[None, :, 0]) & (gx[:, None] <= boxes.hi[None, :, 0]) &
              (gy[:, None] >= boxes.lo[None, :, 1]) & (gy[:, None] <= boxes.hi[None, :, 1]) &
              boxes.grounded[None])
    under = ground & inside.any(1)
    gcls = np.full(len(d), sm.SKY, np.uint8)
    gcls[ground] = layout.classify(gx[ground], gy[ground])
    sem = np.where(obj, boxes.cls[first], gcls)
    depth = np.where(obj, tbox, np.where(ground, tg, 0.0))
    in_range = np.hypot(gx - C[0], gy - C[1]) <= bs_range
    bs = obj & ground & np.isin(gcls, sm.TRAVERSABLE) & ~under & in_range
    shape = (intr.height, intr.width)
    return depth.reshape(shape), sem.reshape(shape), bs.reshape(shape)


# town and highway in the default run; suburb and urban (the slowest brute force) with -m slow
@pytest.mark.parametrize("style", ["town", pytest.param("suburb", marks=pytest.mark.slow), "highway",
                                   pytest.param("urban", marks=pytest.mark.slow)])
def test_fast_renderer_matches_brute_force(style):
    cfg = SynthConfig(frames=40, height=40, width=80, style=style, seed=4)
    clip = make_clip(cfg)
    r = Renderer(clip.intrinsics, far=cfg.far, bs_range=cfg.bs_range)
    checked_bs = 0
    for i in (0, 20, 39):
        fr = r.render(clip.scenario.world, clip.poses[i], float(clip.times[i]), i)
        b = fr.boxes
        # only boxes whose nearest point could be in view (``far`` bounds the z-depth, so a box seen
        # at the image's edge may be farther than ``far``; hills on the horizon are long boxes)
        c = clip.poses[i][:2, 3]
        gap = np.maximum(np.maximum(b.lo[:, :2] - c, c - b.hi[:, :2]), 0.0)
        near = np.hypot(gap[:, 0], gap[:, 1]) < 2 * cfg.far
        depth, sem, bs = brute_force(b.take(np.where(near)[0]), clip.scenario.world.layout,
                                     clip.intrinsics, clip.poses[i], cfg.far, cfg.bs_range)
        # float32 vs float64 can flip a pixel exactly on an edge; nothing more
        assert (sem != fr.semantic).mean() < 0.003
        assert (bs != fr.bsgt).mean() < 0.003
        same = sem == fr.semantic
        np.testing.assert_allclose(fr.depth[same], depth[same], rtol=1e-4, atol=1e-3)
        checked_bs += bs.sum()
    assert checked_bs > 0
