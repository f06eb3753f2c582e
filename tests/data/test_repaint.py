"""Repainting objects and seeing through them: only vehicle and person pixels change, by the drawn
gain, tone curve and stain, or by the scene from elsewhere in the frame blended in."""

import numpy as np
import pytest
import torch

from bsn_edge import semantics as sm
from bsn_edge.data.repaint import (
    THROUGH_ALPHA,
    Repaint,
    SeeThrough,
    draw_repaint,
    draw_see_through,
    repaint,
    see_through,
)


def test_a_repaint_is_gain_times_tone_curve_times_stain_on_objects_only():
    rgb = torch.full((2, 3, 4, 6), 0.25)
    sem = torch.full((2, 4, 6), sm.ROAD, dtype=torch.long)
    sem[0, 1:3, 2:4] = sm.CAR
    sem[0, 0, 0] = sm.PERSON
    sem[1, 2, 2] = sm.CAR
    paint = Repaint((1.2, 0.5, 0.8), 2.0, np.full((2, 2), 1.5, np.float32))
    out = repaint(rgb, sem, [paint, None])
    want = torch.tensor([1.2, 0.5, 0.8]) * 0.25 ** 2 * 1.5          # independent of the code: the formula
    obj = (sem[0] == sm.CAR) | (sem[0] == sm.PERSON)
    torch.testing.assert_close(out[0][:, obj], want[:, None].expand(3, int(obj.sum())))
    assert torch.equal(out[0][:, ~obj], rgb[0][:, ~obj])
    assert torch.equal(out[1], rgb[1]), "None leaves a sample as it is"
    assert torch.equal(rgb, torch.full((2, 3, 4, 6), 0.25)), "the input is not written"
    with pytest.raises(ValueError, match="repaints for a batch"):
        repaint(rgb, sem, [paint])


def test_no_share_draws_nothing_so_the_stream_is_unchanged():
    a, b = np.random.default_rng(3), np.random.default_rng(3)
    assert draw_repaint(a, 0.0, (64, 128)) is None
    assert a.random() == b.random()
    hits = [draw_repaint(np.random.default_rng(i), 0.5, (64, 128)) is not None for i in range(200)]
    assert 70 < sum(hits) < 130
    p = draw_repaint(np.random.default_rng(0), 1.0, (64, 128))
    assert p.stain.shape == (5, 9) and p.stain.min() > 0.0


def test_see_through_blends_the_tinted_scene_from_up_and_aside_into_objects_only():
    rows = torch.arange(8, dtype=torch.float32)[:, None] / 10 + torch.arange(4, dtype=torch.float32)[None] / 100
    rgb = torch.stack([rows, rows * 0.5, 1 - rows])[None].repeat(2, 1, 1, 1)      # [2, 3, 8, 4]
    sem = torch.full((2, 8, 4), sm.BUILDING, dtype=torch.long)
    sem[0, 5:7, 1] = sm.CAR
    sem[0, 7, 3] = sm.PERSON
    sem[1, 4, 2] = sm.CAR
    t = SeeThrough((2, 1), 0.8, np.full((2, 2), 0.5, np.float32))
    out = see_through(rgb, sem, [t, None])
    for y, x in ((5, 1), (6, 1), (7, 3)):
        # independent of the code: the pixel two rows up and one column to the left, tinted, half and half
        want = 0.5 * rgb[0, :, y, x] + 0.5 * 0.8 * rgb[0, :, y - 2, (x - 1) % 4]
        torch.testing.assert_close(out[0, :, y, x], want)
    obj = torch.isin(sem[0], torch.tensor(sm.ROAD_USERS))
    assert torch.equal(out[0][:, ~obj], rgb[0][:, ~obj])
    assert torch.equal(out[1], rgb[1]), "None leaves a sample as it is"
    with pytest.raises(ValueError, match="see-throughs for a batch"):
        see_through(rgb, sem, [t])


def test_see_through_draws_nothing_without_a_share_and_stays_in_its_ranges():
    a, b = np.random.default_rng(5), np.random.default_rng(5)
    assert draw_see_through(a, 0.0, (64, 128)) is None
    assert a.random() == b.random()
    for i in range(50):
        t = draw_see_through(np.random.default_rng(i), 1.0, (64, 128))
        assert 4 <= t.shift[0] <= 22 and abs(t.shift[1]) <= 32, "from higher up, at most a quarter aside"
        assert t.alpha.min() >= 0.0 and t.alpha.max() <= THROUGH_ALPHA[1]
        assert t.alpha.shape == (3, 6)
