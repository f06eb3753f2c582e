"""Depth from a bsn-edge model (a sealed export), seen as ``bsn-run`` sees a frame."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from bsn_edge.calibration.camera_file import Calibration
from bsn_edge.labels.sources.base import ClipData
from bsn_edge.labels.sources.onnx_depth import AlignedDepth
from bsn_edge.sequence.frames import read_rgb

if TYPE_CHECKING:
    from bsn_edge.labels.config import LabelConfig
    from bsn_edge.mounting import Mounting


class BsnDepth(AlignedDepth):
    """``bsn:MODEL``: each frame is warped into the model's camera with the clip's calibration (its
    camera file, or ``--calib``; without one, the clip's intrinsics at the model's mounting), the
    model's metric depth is brought back to the clip's camera (``ModelFrame.depth_to_raw``), and,
    like any model depth, aligned to the landmarks with the same rejection rule: the alignment
    corrects the scale of the model's metres on this camera (scale only: the model is metric, and
    an affine fit would let far landmarks bend the near road), and refuses a clip it cannot fit.
    Pixels the model camera does not see are unknown (0)."""

    name = "bsn"
    model_path: str
    variant: str
    mounting: Mounting

    @classmethod
    def for_clip(cls, model: str, clip: ClipData, poses: np.ndarray, cfg: LabelConfig,
                 frames: list[int], window: int | None = None) -> BsnDepth:
        from bsn_edge.runtime.engine import Engine

        engine = Engine(model)
        card = engine.card
        cal = clip.info.get("calibration") or Calibration.of(clip.meta.intrinsics, (), card.mounting,
                                                             method="assumed")
        if cal.mounting is None:
            cal = cal.with_mounting(card.mounting, method="assumed")
        mf = cal.model_frame(clip.meta.width, clip.meta.height, card.camera, card.mounting)

        def predict(i: int) -> np.ndarray:
            _, depth = engine.infer(mf.to_model(read_rgb(clip.seq, i))[None])
            raw = mf.depth_to_raw(depth)
            return np.where(raw > 0, raw, np.nan).astype(np.float32)   # unseen: left out of the fit

        obj = cls(predict, "metric_depth", clip, poses, frames, cfg.min_corr, window)
        obj.model_path, obj.variant, obj.mounting = model, card.variant, mf.mounting
        return obj

    def __call__(self, i: int) -> np.ndarray:
        return np.nan_to_num(super().__call__(i), nan=0.0)

    def describe(self) -> dict[str, Any]:
        return {**super().describe(), "kind": "bsn", "model": str(self.model_path), "variant": self.variant,
                "mounting": self.mounting.to_dict()}
