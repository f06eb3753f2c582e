"""Segmentation from a user's ONNX model, mapped to Cityscapes trainIds."""

from __future__ import annotations

import json
from typing import Any

import numpy as np

from bsn_edge.labels.sources.base import ClipData, SegSource
from bsn_edge.labels.sources.onnx_model import OnnxImageModel
from bsn_edge.semantics import IGNORE, NUM_CLASSES
from bsn_edge.sequence.frames import read_rgb


class OnnxSeg(SegSource):
    """Per-class scores ``[1, C, H, W]`` -> argmax -> trainIds.

    The model's classes map to trainIds by ``bsn.class_map`` in its metadata (a JSON list, one
    trainId per class, 255 for none); a model with 19 classes and no map is taken as Cityscapes.
    """

    name = "onnx"

    def __init__(self, model: str, clip: ClipData) -> None:
        self.model = OnnxImageModel(model)
        self.clip = clip
        raw = self.model.meta.get("bsn.class_map")
        self.class_map = None if raw is None else np.array(json.loads(raw), np.int64)
        if self.class_map is not None and ((self.class_map < 0) | ((self.class_map >= NUM_CLASSES)
                                                                    & (self.class_map != IGNORE))).any():
            raise ValueError(f"{model}: bsn.class_map holds values that are not trainIds")

    def __call__(self, i: int) -> np.ndarray:
        scores = self.model(read_rgb(self.clip.seq, i))
        cls = scores.argmax(axis=0)
        if self.class_map is not None:
            if scores.shape[0] != len(self.class_map):
                raise ValueError(f"{self.model.path}: {scores.shape[0]} classes but bsn.class_map has "
                                 f"{len(self.class_map)} entries")
            return self.class_map[cls].astype(np.uint8)
        if scores.shape[0] != NUM_CLASSES:
            raise ValueError(f"{self.model.path}: {scores.shape[0]} classes and no bsn.class_map in its "
                             "metadata to map them to Cityscapes trainIds")
        return cls.astype(np.uint8)

    def describe(self) -> dict[str, Any]:
        return {"kind": "onnx", **self.model.describe()}
