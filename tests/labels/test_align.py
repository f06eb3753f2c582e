"""Least-squares alignment of relative depth to landmarks."""

import numpy as np
import pytest

from bsn_edge.labels.align import fit, pooled_correlation


def test_recovers_scale_and_shift_of_depth():
    rng = np.random.default_rng(0)
    true = rng.uniform(2, 60, 500)
    pred = (true - 3.0) / 2.5                     # metric = 2.5 * pred + 3
    a = fit(pred, true, "depth")
    assert a.scale == pytest.approx(2.5, rel=1e-6) and a.shift == pytest.approx(3.0, abs=1e-5)
    assert a.corr == pytest.approx(1.0)
    np.testing.assert_allclose(a.apply(pred), true, rtol=1e-5)


def test_recovers_inverse_depth_and_ignores_outliers():
    rng = np.random.default_rng(1)
    true = rng.uniform(2, 60, 400)
    pred = 7.0 / true + 0.02 + rng.normal(0, 1e-4, 400)   # MiDaS-like disparity
    pred[:20] = rng.uniform(0, 4, 20)                     # bad tracks
    a = fit(pred, true, "inverse_depth")
    good = a.apply(pred[20:])
    assert np.median(np.abs(good - true[20:]) / true[20:]) < 0.01
    assert a.corr > 0.9


def test_uncorrelated_depth_has_low_correlation():
    rng = np.random.default_rng(2)
    true = rng.uniform(2, 60, 300)
    a = fit(rng.uniform(0, 1, 300), true, "depth")
    assert abs(a.corr) < 0.3
    assert pooled_correlation([rng.uniform(0, 1, 300)], [true], [a]) < 0.3


def test_too_few_landmarks_and_unknown_kind():
    with pytest.raises(ValueError, match="too few landmarks"):
        fit(np.ones(5), np.ones(5))
    with pytest.raises(ValueError, match="unknown prediction kind"):
        fit(np.ones(50), np.ones(50), "disparity")


def test_pooled_correlation_leaves_out_pixels_the_prediction_does_not_cover():
    rng = np.random.default_rng(3)
    z = rng.uniform(3, 40, 400)
    pred = 0.5 * z + 1.0
    pred[::7] = np.nan                           # outside a narrow camera's view
    a = fit(pred, z, "depth")
    corr = pooled_correlation([pred], [z], [a])
    assert np.isfinite(corr) and corr > 0.999


def test_a_metric_prediction_is_scaled_where_it_is_near_and_far_errors_do_not_bend_it():
    """A metric network 10 % short everywhere near, and far off beyond 20 m (where networks err
    most): the scale-only fit recovers 1 / 0.9 from the near landmarks, with no shift."""
    rng = np.random.default_rng(4)
    z = np.concatenate([rng.uniform(3, 18, 300), rng.uniform(30, 80, 300)])
    pred = np.where(z < 20, 0.9 * z, 0.5 * z) * np.exp(rng.normal(0, 0.02, len(z)))
    a = fit(pred, z, "metric_depth")
    assert a.shift == 0.0 and a.scale == pytest.approx(1 / 0.9, rel=0.01)
    near = z < 18
    assert np.median(np.abs(a.apply(pred)[near] - z[near]) / z[near]) < 0.03
    affine = fit(pred, z, "depth")
    assert np.median(np.abs(affine.apply(pred)[near] - z[near]) / z[near]) > 0.05, "the affine fit bends the near range"
