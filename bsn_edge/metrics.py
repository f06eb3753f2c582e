"""IoU, recall and precision of blind-spot masks inside the visibility mask V."""

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
