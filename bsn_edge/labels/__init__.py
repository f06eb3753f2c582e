"""T-frame blind-spot labels from driving video (BlindSpotNet, Section 3)."""

from bsn_edge.labels.config import LabelConfig
from bsn_edge.labels.generator import ClipRejectedError, Sources, label_sequence, labels_dir, resample
from bsn_edge.labels.warp import Warper, label_frame, remove_small_components

__all__ = [
    "ClipRejectedError",
    "LabelConfig",
    "Sources",
    "Warper",
    "label_frame",
    "label_sequence",
    "labels_dir",
    "remove_small_components",
    "resample",
]
