"""What ``bsn-adapt`` does, as one validated record (written beside its results)."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any

from bsn_edge.labels.config import LabelConfig

LABEL_DEPTHS = ("auto", "ground", "model")
ASSUMED_HEIGHT_M = 1.5   # the model camera's mounting height: a camera whose height nobody stated
ADAPT_LABELS = LabelConfig(look_tol=8.0)   # bsn-label's defaults, with the look check for road-plane labels


@dataclass(frozen=True)
class AdaptConfig:
    """Labelling, fine-tuning and threshold choice of one adaptation.

    labels:                     the T-frame labels, as ``bsn-label`` makes them (``--rate --T
                                --min-corr``); its ``look_tol`` applies to clips labelled from the
                                road plane only (below)
    label_depth:                depth the labels are made with: ``model`` (the run's depth head),
                                ``ground`` (the road plane of the clip's mounting, things at their
                                ground contact: needs a camera file with a mounting), ``auto`` (the
                                depth head, and the road plane for a clip it does not fit when the
                                clip's mounting is known)
    labels.look_tol:            grey levels, for clips labelled from the road plane: warped road
                                that looks like the label frame's picture where it lands is visible
                                road, not a blind spot (``LabelConfig.look_tol``; 0 = off). The
                                teacher's car outlines spill over the road by a few pixels and the
                                plane puts them at the car's ground contact; the picture does not.
                                Labels from the depth head are made without it (measured: it cost
                                them recall and gained nothing)
    holdout_fraction:           share of the user's labelled frames kept out of fine-tuning to
                                choose the threshold and measure agreement (whole clips when
                                there are several, else the end of the one clip)
    steps, batch_size, lr:      fine-tuning of B (D stays as it is)
    distill_weight:             the teacher's pairwise-similarity distillation, as in training
    max_fps:                    frames are taken at most this often (visual odometry and labels
                                need no more; a long recording stays small)
    min_moving_s:               the least driving (image motion) a clip must hold to be labelled
    seed:                       data order and augmentation
    """

    labels: LabelConfig = ADAPT_LABELS
    label_depth: str = "auto"
    holdout_fraction: float = 0.25
    steps: int = 300
    batch_size: int = 8
    lr: float = 2e-4
    distill_weight: float = 1.0
    max_fps: float = 10.0
    min_moving_s: float = 2.0
    seed: int = 0
    threads: int = 2

    def __post_init__(self) -> None:
        if not isinstance(self.labels, LabelConfig):
            raise ValueError(f"labels must be a LabelConfig, got {type(self.labels).__name__}")
        if self.label_depth not in LABEL_DEPTHS:
            raise ValueError(f"label_depth must be one of {', '.join(LABEL_DEPTHS)}, got {self.label_depth!r}")
        if not 0 < self.holdout_fraction < 1:
            raise ValueError(f"holdout_fraction must be in (0, 1), got {self.holdout_fraction}")
        if self.steps < 1 or self.batch_size < 1:
            raise ValueError(f"steps and batch_size must be >= 1, got {self.steps}, {self.batch_size}")
        if not self.lr > 0 or self.distill_weight < 0:
            raise ValueError("lr must be positive and distill_weight non-negative")
        if not self.max_fps > 0:
            raise ValueError(f"max_fps must be positive, got {self.max_fps}")
        if self.min_moving_s < 0 or self.threads < 1:
            raise ValueError("min_moving_s must be >= 0 and threads >= 1")

    def label_config(self, depth: str = "") -> LabelConfig:
        """The T-frame label settings of a clip labelled with the ``depth`` source spec (the look
        check is for the road plane's labels, ``ground``)."""
        if depth != "ground":
            return dataclasses.replace(self.labels, look_tol=0.0)
        # a clip with no mounting finds its road plane from the direction of travel, at this height
        return dataclasses.replace(self.labels, camera_height=self.labels.camera_height or ASSUMED_HEIGHT_M)

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)
