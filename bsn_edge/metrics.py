"""IoU, recall and precision of blind-spot masks inside the visibility mask V, and the average
precision of their probabilities (no threshold); depth errors by distance bin."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

THRESHOLDS = np.round(np.arange(0.05, 0.96, 0.05), 2)


@dataclass
class Counts:
    """Pooled pixel counts inside V."""

    tp: int = 0
    fp: int = 0
    fn: int = 0

    def add(self, pred: np.ndarray, label: np.ndarray, valid: np.ndarray) -> None:
        p, t, v = pred.astype(bool), label.astype(bool), valid.astype(bool)
        self.tp += int((p & t & v).sum())
        self.fp += int((p & ~t & v).sum())
        self.fn += int((~p & t & v).sum())

    def metrics(self) -> dict[str, float]:
        return {"iou": self.tp / max(self.tp + self.fp + self.fn, 1),
                "recall": self.tp / max(self.tp + self.fn, 1),
                "precision": self.tp / max(self.tp + self.fp, 1)}


class ThresholdSweep:
    """Counts at every candidate threshold, to pick the one with the best IoU on validation."""

    def __init__(self, thresholds: np.ndarray = THRESHOLDS) -> None:
        self.thresholds = thresholds
        self.counts = [Counts() for _ in thresholds]

    def add(self, prob: np.ndarray, label: np.ndarray, valid: np.ndarray) -> None:
        for th, c in zip(self.thresholds, self.counts, strict=True):
            c.add(prob >= th, label, valid)

    def best(self) -> tuple[float, dict[str, float]]:
        scores = [c.metrics() for c in self.counts]
        k = int(np.argmax([s["iou"] for s in scores]))
        return float(self.thresholds[k]), scores[k]


class ScoreHistogram:
    """Probabilities of the positive and the negative pixels inside V, counted in ``bins`` equal bins
    of [0, 1], for scores that need no decision threshold. Pixels in one bin count as tied."""

    def __init__(self, bins: int = 1000) -> None:
        if bins < 2:
            raise ValueError(f"ScoreHistogram needs at least 2 bins, got {bins}")
        self.bins = bins
        self.pos = np.zeros(bins, np.int64)
        self.neg = np.zeros(bins, np.int64)

    def add(self, prob: np.ndarray, label: np.ndarray, valid: np.ndarray) -> None:
        v = valid.astype(bool)
        k = np.clip((prob[v] * self.bins).astype(np.int64), 0, self.bins - 1)
        t = label.astype(bool)[v]
        self.pos += np.bincount(k[t], minlength=self.bins)
        self.neg += np.bincount(k[~t], minlength=self.bins)

    def merge(self, other: ScoreHistogram) -> None:
        """Add the counts of ``other`` (of the same bins) to these."""
        if other.bins != self.bins:
            raise ValueError(f"cannot merge a ScoreHistogram of {other.bins} bins into one of {self.bins}")
        self.pos += other.pos
        self.neg += other.neg

    def positive_share(self) -> float | None:
        """The share of the pixels inside V that are positive: the average precision of a ranking by
        chance; None when nothing was added."""
        n = int(self.pos.sum() + self.neg.sum())
        return int(self.pos.sum()) / n if n else None

    def average_precision(self) -> float | None:
        """Area under the precision-recall curve as a step function (each threshold's precision times
        the recall it adds), the highest scores first; None when there were no positives."""
        tp, fp = np.cumsum(self.pos[::-1]), np.cumsum(self.neg[::-1])
        if tp[-1] == 0:
            return None
        added = self.pos[::-1] / tp[-1]
        return float(np.sum(added * tp / np.maximum(tp + fp, 1)))


def bin_name(lo: float, hi: float) -> str:
    """How a distance bin ``[lo, hi)`` metres is named in reports: ``"5-10"``."""
    return f"{lo:g}-{hi:g}"


def depth_by_bin(pred: np.ndarray, truth: np.ndarray, bins, min_points: int = 1) -> dict[str, dict[str, float]]:
    """Per distance bin ``[lo, hi)`` of the true depth, over the points with a prediction (> 0): their
    number, AbsRel (mean ``|pred / truth - 1|``), median ratio ``pred / truth`` and the share within
    a factor 1.25; bins with fewer than ``min_points`` points are left out."""
    pred, truth = np.asarray(pred, np.float64).ravel(), np.asarray(truth, np.float64).ravel()
    out = {}
    for lo, hi in bins:
        m = (truth >= lo) & (truth < hi) & (pred > 0)
        if m.sum() < max(1, min_points):
            continue
        r = pred[m] / truth[m]
        out[bin_name(lo, hi)] = {"n": int(m.sum()), "abs_rel": float(np.mean(np.abs(r - 1))),
                                 "median_ratio": float(np.median(r)),
                                 "delta_1.25": float(np.mean(np.maximum(r, 1 / r) < 1.25))}
    return out


class DepthBins:
    """AbsRel per distance bin pooled over many frames, in constant memory (sums per bin)."""

    def __init__(self, bins) -> None:
        self.bins = tuple(bins)
        self.err = np.zeros(len(self.bins))
        self.n = np.zeros(len(self.bins), np.int64)

    def add(self, pred: np.ndarray, truth: np.ndarray) -> None:
        """Points of one frame (arrays of the same shape, already restricted to what is scored)."""
        for b, stats in enumerate(depth_by_bin(pred, truth, self.bins).get(bin_name(*k)) for k in self.bins):
            if stats is not None:
                self.err[b] += stats["abs_rel"] * stats["n"]
                self.n[b] += stats["n"]

    def abs_rel(self) -> dict[str, float | None]:
        """AbsRel per bin over every point added (None where a bin had none)."""
        return {bin_name(lo, hi): (float(self.err[b] / self.n[b]) if self.n[b] else None)
                for b, (lo, hi) in enumerate(self.bins)}
