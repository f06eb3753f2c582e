"""The losses of BlindSpotNet training."""

import math

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


def test_a_free_scale_sample_is_taught_its_depth_up_to_a_factor_of_its_own():
    torch.manual_seed(0)
    t = torch.rand(2, 1, 8, 16) * 30 + 5
    pred = t * torch.tensor([1.6, 0.7]).view(2, 1, 1, 1)       # each sample right but for its scale
    # metric: the mean |log| of each factor; free scale: nothing to learn on that sample
    assert abs(depth_loss(pred, t).item() - (math.log(1.6) + abs(math.log(0.7))) / 2) < 1e-5
    assert depth_loss(pred, t, free_scale=torch.tensor([True, True])).item() < 1e-5
    half = depth_loss(pred, t, free_scale=torch.tensor([False, True])).item()
    assert abs(half - math.log(1.6) / 2) < 1e-5
    # a wrong shape is still taught in a free-scale sample
    bent = pred.clone()
    bent[..., :4, :] *= 2.0
    assert depth_loss(bent, t, free_scale=torch.tensor([True, True])).item() > 0.3


def test_v_widens_to_every_seen_pixel_nearer_than_the_range_and_no_farther():
    from bsn_edge.semantics import CAR, IGNORE, ROAD, SKY
    from bsn_edge.train.losses import visible_out_to

    v = torch.tensor([[[[1.0, 0.0, 0.0, 0.0, 0.0, 0.0]]]])
    depth = torch.tensor([[[[40.0, 5.0, 29.9, 30.0, 0.0, 8.0]]]])
    sem = torch.tensor([[[SKY, CAR, CAR, ROAD, ROAD, IGNORE]]])
    # kept (V), near car, car just inside, road at the range, no depth, the hood or outside the view
    assert visible_out_to(v, depth, sem, 30.0).flatten().tolist() == [1.0, 1.0, 1.0, 0.0, 0.0, 0.0]
    assert visible_out_to(v, depth, sem, 4.0).flatten().tolist() == v.flatten().tolist()


def test_a_weight_multiplies_each_pixels_term_and_the_mean_stays_over_v():
    logits = torch.zeros(1, 1, 1, 3)                  # each term is ln 2 at logit 0
    target = torch.tensor([[[[1.0, 0.0, 1.0]]]])
    valid = torch.tensor([[[[1.0, 1.0, 0.0]]]])
    weight = torch.tensor([[[[4.0, 1.0, 9.0]]]])      # the third pixel is outside V: its weight is moot
    assert math.isclose(masked_bce(logits, target, valid, weight).item(), (4 + 1) * math.log(2) / 2, rel_tol=1e-6)
    assert math.isclose(masked_bce(logits, target, valid, torch.ones_like(weight)).item(),
                        masked_bce(logits, target, valid).item(), rel_tol=1e-7)
