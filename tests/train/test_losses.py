"""The losses of BlindSpotNet training."""

import torch

from bsn_edge.train.losses import depth_loss, distillation_loss, masked_bce


def test_distillation_is_zero_for_identical_features_and_positive_otherwise():
    torch.manual_seed(0)
    f = torch.randn(2, 16, 32, 64)
    assert distillation_loss(f, f).item() < 1e-10
    # channel counts may differ: the loss compares patch-similarity structure
    assert distillation_loss(torch.randn(2, 8, 32, 64), f).item() > 1e-3
    # scaling features does not change cosine similarities
    assert distillation_loss(3.0 * f, f).item() < 1e-10


def test_masked_bce_ignores_pixels_outside_v():
    logits = torch.full((1, 1, 4, 4), -2.0)   # confident 'no blind spot'
    target = torch.zeros(1, 1, 4, 4)
    valid = torch.zeros(1, 1, 4, 4)
    valid[..., :2, :] = 1
    base = masked_bce(logits, target, valid)
    target[..., 2:, :] = 1            # outside V: must not matter
    logits[..., 3, :] = 50.0
    assert torch.allclose(masked_bce(logits, target, valid), base)
    target[..., 0, 0] = 1             # inside V: does
    assert masked_bce(logits, target, valid) > base
    assert masked_bce(logits, target, torch.zeros_like(valid)).item() == 0.0


def test_depth_loss_is_zero_at_the_truth_and_teaches_sky_as_far():
    t = torch.full((1, 1, 2, 2), 10.0)
    assert depth_loss(t.clone(), t).item() < 1e-6
    sky = torch.zeros(1, 1, 2, 2, dtype=torch.bool)
    sky[..., 0, 0] = True
    t[..., 0, 0] = 0.0
    assert depth_loss(torch.full((1, 1, 2, 2), 10.0), t, sky).item() > 0.1
