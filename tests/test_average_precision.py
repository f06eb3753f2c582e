"""Average precision from the score histogram, against values worked out by hand and a direct
computation over the sorted pixels."""

import numpy as np
import pytest

from bsn_edge.metrics import ScoreHistogram


def _ap(scores: list[float], labels: list[bool], bins: int = 1000) -> float | None:
    h = ScoreHistogram(bins)
    h.add(np.array(scores), np.array(labels), np.ones(len(scores), bool))
    return h.average_precision()


def test_by_hand():
    # ranked: pos (P 1/1), neg, pos (P 2/3), neg: AP = 1/2 * 1 + 1/2 * 2/3
    assert _ap([0.9, 0.8, 0.7, 0.1], [True, False, True, False]) == pytest.approx(5 / 6)
    assert _ap([0.9, 0.8, 0.2, 0.1], [True, True, False, False]) == pytest.approx(1.0)
    # one tie of a positive and a negative at the top: precision 1/2 there
    assert _ap([0.5, 0.5], [True, False]) == pytest.approx(0.5)


def test_no_positives_has_no_ap():
    assert _ap([0.3, 0.6], [False, False]) is None


def test_only_pixels_inside_v_count():
    h = ScoreHistogram()
    prob = np.array([0.9, 0.95, 0.1])
    label = np.array([False, True, True])
    h.add(prob, label, np.array([False, True, True]))   # the high-scored negative is outside V
    assert h.average_precision() == pytest.approx(1.0)


def test_matches_sorted_pixels_with_ties():
    rng = np.random.default_rng(0)
    n, bins = 20_000, 100
    # scores on the bin centres so the histogram loses nothing; labels that depend on the score
    scores = (rng.integers(0, bins, n) + 0.5) / bins
    labels = rng.random(n) < scores ** 2
    expected = 0.0
    for s in np.unique(scores)[::-1]:
        above = scores >= s
        expected += (labels & (scores == s)).sum() / labels.sum() * (labels & above).sum() / above.sum()
    assert _ap(list(scores), list(labels), bins) == pytest.approx(expected, rel=1e-9)


def test_random_scores_give_the_positive_share():
    rng = np.random.default_rng(1)
    labels = rng.random(200_000) < 0.03
    h = ScoreHistogram()
    h.add(rng.random(labels.size), labels, np.ones(labels.size, bool))
    assert h.positive_share() == labels.mean()
    assert h.average_precision() == pytest.approx(0.03, abs=0.003)


def test_rejects_one_bin():
    with pytest.raises(ValueError, match="at least 2 bins"):
        ScoreHistogram(1)
