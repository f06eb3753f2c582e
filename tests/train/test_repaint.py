"""Repainting objects: only vehicle and person pixels change, by the drawn gain, tone curve and stain."""

import numpy as np
import pytest
import torch

from bsn_edge import semantics as sm
from bsn_edge.data.repaint import Repaint, draw_repaint, repaint


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
