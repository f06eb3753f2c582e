"""``rel:DIR``: relative depth maps a network already wrote, aligned like an ONNX model's output."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from bsn_edge.labels.sources.base import ClipData
from bsn_edge.labels.sources.onnx_depth import AlignedDepth
from bsn_edge.sequence.folder import frame_name


class RelFilesDepth(AlignedDepth):
    """``DIR/NNNNNN.npy`` float32 maps at the frame size; ``rel:DIR`` holds depth, ``rel:DIR:inverse``
    inverse depth (MiDaS-style disparity). Scale and shift are unknown and found from landmarks."""

    name = "relative files"
    folder: Path

    @classmethod
    def from_spec(cls, spec: str, clip: ClipData, poses: np.ndarray, min_corr: float,
                  frames: list[int], window: int | None = None) -> RelFilesDepth:
        folder, _, suffix = spec.partition(":")
        kind = {"": "depth", "depth": "depth", "inverse": "inverse_depth"}.get(suffix)
        if kind is None:
            raise ValueError(f"rel:{spec}: the suffix must be ':inverse' or nothing")
        root = Path(folder)
        if not root.is_absolute() and not root.exists():
            root = clip.seq / folder
        if not root.is_dir():
            raise FileNotFoundError(f"relative depth folder {folder} not found")
        shape = (clip.meta.height, clip.meta.width)

        def predict(i: int) -> np.ndarray:
            p = root / frame_name(i, ".npy")
            if not p.exists():
                raise FileNotFoundError(f"{p} missing")
            a = np.load(p, allow_pickle=False)
            if a.shape != shape:
                raise ValueError(f"{p}: shape {a.shape}, expected {shape}")
            return a.astype(np.float32)
        obj = cls(predict, kind, clip, poses, frames, min_corr, window)
        obj.folder = root
        return obj

    def describe(self) -> dict[str, Any]:
        return {**super().describe(), "kind": "relative files", "folder": str(self.folder)}
