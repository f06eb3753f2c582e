"""The inference engine: one onnxruntime session on the fused model, configured from its metadata."""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from bsn_edge.camera import Intrinsics
from bsn_edge.export.fused import session


@dataclass(frozen=True)
class ModelInfo:
    """What the runtime reads from ``metadata_props``."""

    variant: str
    size: tuple[int, int]
    threshold: float
    intrinsics: Intrinsics | None
    quantization: str

    @classmethod
    def read(cls, sess, path: Path) -> ModelInfo:
        meta = dict(sess.get_modelmeta().custom_metadata_map)
        try:
            size = tuple(json.loads(meta["bsn.input_size"]))
            threshold = float(json.loads(meta["bsn.threshold"]))
        except KeyError as e:
            raise ValueError(f"{path}: not a bsn-export model (metadata {e.args[0]} missing)") from None
        intr = json.loads(meta.get("bsn.intrinsics", "null"))
        return cls(meta.get("bsn.variant", "?"), size, threshold, Intrinsics(**intr) if intr else None,
                   meta.get("bsn.quantization", "?"))


class Engine:
    """Resizes frames into a preallocated input buffer and runs the model."""

    def __init__(self, model: str | Path, threads: int = 2, spinning: bool = True) -> None:
        self.path = Path(model)
        if not self.path.is_file():
            raise FileNotFoundError(f"model {self.path} not found")
        try:
            self.sess = session(self.path, threads, spinning)
        except Exception as e:
            raise ValueError(f"{self.path}: onnxruntime cannot load it: {e}") from None
        self.info = ModelInfo.read(self.sess, self.path)
        h, w = self.info.size
        self.buf = np.empty((1, h, w, 3), np.uint8)

    def preprocess(self, frame: np.ndarray) -> np.ndarray:
        """Resize once, straight into the input buffer (no copy when the size already fits)."""
        h, w = self.info.size
        if frame.shape[:2] == (h, w):
            self.buf[0] = frame
        else:
            cv2.resize(frame, (w, h), dst=self.buf[0], interpolation=cv2.INTER_AREA)
        return self.buf

    def infer(self, batch: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        prob, depth = self.sess.run(None, {"frame": batch})
        return prob[0, 0], depth[0, 0]

    def warmup(self, n: int = 3) -> None:
        for _ in range(n):
            self.infer(np.zeros_like(self.buf))
