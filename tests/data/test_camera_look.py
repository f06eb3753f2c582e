"""A camera of the sample's own over the whole frame: each effect against its formula or a property
that holds whatever the code, and the batch path equal to the dataset's."""

import numpy as np
import pytest
import torch

from bsn_edge.data.camera_look import (
    BLUR,
    CONTRAST,
    GAMMA,
    NOISE,
    SATURATION,
    WHITE_BALANCE,
    CameraLook,
    camera_look,
    draw_camera_look,
    gaussian_blur,
)

PLAIN = dict(white_balance=(1.0, 1.0, 1.0), contrast=1.0, saturation=1.0, gamma=1.0, blur=0.0, noise=0.0,
             noise_seed=0)


def _look(**kw) -> CameraLook:
    return CameraLook(**{**PLAIN, **kw})


def test_each_effect_is_its_formula():
    grey = torch.full((3, 8, 8), 0.4)
    torch.testing.assert_close(_look().apply(grey), grey)
    wb = _look(white_balance=(1.2, 1.0, 0.5)).apply(grey)
    torch.testing.assert_close(wb[:, 0, 0], torch.tensor([0.48, 0.4, 0.2]))
    torch.testing.assert_close(_look(gamma=2.0).apply(grey), torch.full((3, 8, 8), 0.16))
    # saturation 0: every pixel its BT.601 luma; a grey frame has no colour to scale
    colour = torch.zeros(3, 2, 2)
    colour[0] = 1.0
    torch.testing.assert_close(_look(saturation=0.0).apply(colour), torch.full((3, 2, 2), 0.299))
    torch.testing.assert_close(_look(saturation=0.3).apply(grey), grey)
    # contrast about the frame's mean: half the distance from it
    half = torch.cat([torch.full((3, 4, 8), 0.2), torch.full((3, 4, 8), 0.6)], 1)
    out = _look(contrast=0.5).apply(half)
    assert torch.allclose(out[:, :4], torch.tensor(0.3)) and torch.allclose(out[:, 4:], torch.tensor(0.5))


def test_blur_keeps_a_flat_frame_and_spreads_an_edge_as_a_gaussian_does():
    flat = torch.full((3, 16, 16), 0.7)
    torch.testing.assert_close(gaussian_blur(flat, 1.3), flat)
    edge = torch.zeros(1, 1, 64)
    edge[..., 32:] = 1.0
    got = gaussian_blur(edge.expand(1, 8, 64).clone(), 1.5)[0, 4]
    # a step blurred by a Gaussian of sigma s is its CDF, Phi((x - 31.5) / s), within what sampling the
    # kernel at whole pixels costs (under 0.005 at this sigma)
    x = torch.arange(64, dtype=torch.float64)
    want = 0.5 * (1 + torch.erf((x - 31.5) / (1.5 * np.sqrt(2))))
    assert torch.allclose(got.double()[20:44], want[20:44], atol=6e-3)


def test_noise_has_the_drawn_spread_and_one_seed_one_pattern():
    mid = torch.full((3, 128, 128), 0.5)
    a = _look(noise=0.03, noise_seed=7).apply(mid)
    assert abs(float((a - mid).std()) - 0.03) < 0.002
    assert torch.equal(a, _look(noise=0.03, noise_seed=7).apply(mid))
    assert not torch.equal(a, _look(noise=0.03, noise_seed=8).apply(mid))


def test_draws_stay_in_their_ranges_and_no_share_draws_nothing():
    a, b = np.random.default_rng(3), np.random.default_rng(3)
    assert draw_camera_look(a, 0.0, (64, 128)) is None
    assert a.random() == b.random(), "a zero share leaves the stream as it was"
    rng = np.random.default_rng(0)
    looks = [draw_camera_look(rng, 0.5, (64, 128)) for _ in range(200)]
    drawn = [look for look in looks if look is not None]
    assert 70 < len(drawn) < 130
    for look in drawn:
        assert all(WHITE_BALANCE[0] <= g <= WHITE_BALANCE[1] for g in look.white_balance)
        for value, (lo, hi) in ((look.contrast, CONTRAST), (look.saturation, SATURATION), (look.gamma, GAMMA),
                                (look.blur, BLUR), (look.noise, NOISE)):
            assert lo <= value <= hi
    rgb = torch.rand(2, 3, 8, 8)
    out = camera_look(rgb, [drawn[0], None])
    assert torch.equal(out[1], rgb[1]) and not torch.equal(out[0], rgb[0])
    assert float(out.min()) >= 0.0 and float(out.max()) <= 1.0
    with pytest.raises(ValueError, match="camera looks for a batch of 2"):
        camera_look(rgb, [None])
