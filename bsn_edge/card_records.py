"""The records a model card carries beside its own fields: how the model was trained (:class:`TrainingRecord`)
and its known answer (:class:`SelfTest`); :mod:`bsn_edge.card` writes and reads them with the card."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

# the arithmetic a training piece ran in; UNRECORDED: its records do not name it (written before they did)
PRECISION_BF16, PRECISION_FP32, UNRECORDED = "bf16", "fp32", "unrecorded"
PRECISIONS = (PRECISION_BF16, PRECISION_FP32, UNRECORDED)


@dataclass(frozen=True)
class TrainingRecord:
    """How a model was trained, as its run recorded it: optimizer steps and samples seen in all
    (every piece and resume of the run), wall-clock hours of training, the clips it trained and
    validated on, the run it started from (``init``, empty: from scratch), where its teacher
    came from, and the arithmetic D and B trained in (``precision``: every kind its pieces ran in,
    sorted, ``bf16`` or ``fp32``, ``unrecorded`` for a piece from before the trainer named it; empty
    when no piece did, and then left out of the card, so older cards digest as they did), and where the
    card's threshold was chosen when not on the run's own validation clips (``threshold_from``; empty:
    there, and left out of the card), and the share of D and B's convolution channels alive at the
    run's last record (``alive``, one line; empty when its history did not count them, and then left
    out of the card)."""

    steps: int
    samples: int
    hours: float
    train_clips: int
    val_clips: int
    init: str = ""
    teacher: str = ""
    precision: tuple[str, ...] = ()
    threshold_from: str = ""
    alive: str = ""
    adapted_on: str = ""     # bsn-adapt's: the recordings it fine-tuned on, one line; empty: not adapted

    def __post_init__(self) -> None:
        if min(self.steps, self.samples, self.train_clips, self.val_clips) < 0 or not self.hours >= 0:
            raise ValueError(f"a training record counts nothing below zero, got {self}")
        if not set(self.precision) <= set(PRECISIONS) or list(self.precision) != sorted(set(self.precision)):
            raise ValueError(f"training precision: sorted kinds of {PRECISIONS}, got {self.precision!r}")

    def to_dict(self) -> dict[str, Any]:
        d = dataclasses.asdict(self)
        if self.precision:
            d["precision"] = list(self.precision)
        else:
            del d["precision"]
        for optional in ("threshold_from", "alive", "adapted_on"):
            if not d[optional]:
                del d[optional]
        return d

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> TrainingRecord:
        return cls(steps=int(d["steps"]), samples=int(d["samples"]), hours=float(d["hours"]),
                   train_clips=int(d["train_clips"]), val_clips=int(d["val_clips"]), init=str(d.get("init", "")),
                   teacher=str(d.get("teacher", "")), precision=tuple(map(str, d.get("precision", ()))),
                   threshold_from=str(d.get("threshold_from", "")), alive=str(d.get("alive", "")),
                   adapted_on=str(d.get("adapted_on", "")))


@dataclass(frozen=True)
class SelfTest:
    """A known answer: the model's outputs on ``selftest.test_frame`` pooled to ``grid`` cells,
    and how far a healthy run may stray from them (absolute on probabilities, relative on depth)."""

    grid: tuple[int, int]
    prob: tuple[float, ...]
    depth: tuple[float, ...]
    prob_atol: float
    depth_rtol: float

    def __post_init__(self) -> None:
        n = self.grid[0] * self.grid[1]
        if min(self.grid) < 1 or len(self.prob) != n or len(self.depth) != n:
            raise ValueError(f"self_test: {len(self.prob)} / {len(self.depth)} values for a "
                             f"{self.grid[0]}x{self.grid[1]} grid")
        if not all(0.0 <= p <= 1.0 for p in self.prob) or not all(d > 0 and math.isfinite(d) for d in self.depth):
            raise ValueError("self_test: probabilities must lie in [0, 1] and depths be positive")
        if not (0 < self.prob_atol < 1 and 0 < self.depth_rtol < 1):
            raise ValueError(f"self_test: tolerances must lie in (0, 1), got {self.prob_atol}, {self.depth_rtol}")
