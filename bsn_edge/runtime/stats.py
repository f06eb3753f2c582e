"""Latency statistics in constant memory: a log-spaced histogram, however long the run."""

from __future__ import annotations

import numpy as np

BINS_PER_DECADE = 100          # percentiles to within about 1.2 %
LO_S, HI_S = 1e-5, 1e2         # 10 us .. 100 s; anything outside lands in the end bins


class LatencyStats:
    """Counts, sum and a histogram of latencies in seconds; ``percentiles`` in milliseconds."""

    def __init__(self) -> None:
        decades = np.log10(HI_S / LO_S)
        self.counts = np.zeros(round(decades * BINS_PER_DECADE) + 1, np.int64)
        self.n = 0
        self.total_s = 0.0
        self.max_s = 0.0

    def add(self, seconds: float) -> None:
        k = int(np.log10(max(seconds, LO_S) / LO_S) * BINS_PER_DECADE)
        self.counts[min(k, len(self.counts) - 1)] += 1
        self.n += 1
        self.total_s += seconds
        self.max_s = max(self.max_s, seconds)

    def percentile(self, q: float) -> float:
        """The ``q``-th percentile in milliseconds (the upper edge of its bin, capped at the max)."""
        if not self.n:
            return 0.0
        k = int(np.searchsorted(np.cumsum(self.counts), q / 100.0 * self.n, side="left"))
        upper = LO_S * 10 ** ((k + 1) / BINS_PER_DECADE)
        return 1e3 * min(upper, self.max_s)

    def percentiles(self) -> dict[str, float]:
        return {"p50_ms": self.percentile(50), "p95_ms": self.percentile(95), "p99_ms": self.percentile(99)}
