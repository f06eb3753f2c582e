"""Evaluation of blind-spot predictions: metrics, baselines, reports."""

from bsn_edge.metrics import Counts, ThresholdSweep

__all__ = ["Counts", "ThresholdSweep"]
