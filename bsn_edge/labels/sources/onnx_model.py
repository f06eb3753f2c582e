"""Running a user's ONNX image model on a clip's frames: input conventions in one place.

Two input layouts are understood:
- ``uint8 [1, H, W, 3]``: BGR as OpenCV decodes it (the layout of bsn-edge's own models);
- ``float32 [1, 3, H, W]``: RGB scaled to [0, 1] and normalised by ``bsn.mean`` / ``bsn.std``
  from the model's metadata (ImageNet statistics by default), the torchvision convention.
Fixed input sizes are honoured (the frame is resized); dynamic ones take the frame's size
rounded to a multiple of 32. The output is resized back to the frame's size.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import cv2
import numpy as np

IMAGENET_MEAN = (0.485, 0.456, 0.406)
IMAGENET_STD = (0.229, 0.224, 0.225)


class OnnxImageModel:
    """One onnxruntime session and the pre-processing its input asks for."""

    def __init__(self, path: str | Path, threads: int = 2) -> None:
        from bsn_edge.modelfile.read import session

        self.path = Path(path)
        if not self.path.is_file():
            raise FileNotFoundError(f"ONNX model {self.path} not found")
        try:
            self.session = session(self.path, threads)
        except Exception as e:
            raise ValueError(f"{self.path}: onnxruntime cannot load it: {e}") from None
        inp = self.session.get_inputs()[0]
        self.input_name = inp.name
        self.meta: dict[str, str] = dict(self.session.get_modelmeta().custom_metadata_map)
        self.uint8 = inp.type == "tensor(uint8)"
        shape = list(inp.shape)
        if len(shape) != 4:
            raise ValueError(f"{self.path}: input {inp.name!r} must be 4-D, got {shape}")
        if self.uint8:
            if shape[3] not in (3, "3"):
                raise ValueError(f"{self.path}: a uint8 input must be [1, H, W, 3], got {shape}")
            hw = shape[1:3]
        else:
            if shape[1] not in (3, "3"):
                raise ValueError(f"{self.path}: a float input must be [1, 3, H, W], got {shape}")
            hw = shape[2:4]
        self.fixed_hw = tuple(hw) if all(isinstance(d, int) for d in hw) else None
        self.mean = np.array(json.loads(self.meta.get("bsn.mean", json.dumps(IMAGENET_MEAN))), np.float32)
        self.std = np.array(json.loads(self.meta.get("bsn.std", json.dumps(IMAGENET_STD))), np.float32)

    def _size(self, h: int, w: int) -> tuple[int, int]:
        if self.fixed_hw:
            return self.fixed_hw
        return max(32, round(h / 32) * 32), max(32, round(w / 32) * 32)

    def __call__(self, bgr: np.ndarray) -> np.ndarray:
        """First output for one BGR frame, squeezed to ``[C, H, W]`` at the frame's size."""
        h, w = bgr.shape[:2]
        mh, mw = self._size(h, w)
        img = cv2.resize(bgr, (mw, mh), interpolation=cv2.INTER_AREA) if (mh, mw) != (h, w) else bgr
        if self.uint8:
            x = np.ascontiguousarray(img[None])
        else:
            rgb = img[..., ::-1].astype(np.float32) / 255.0
            x = np.ascontiguousarray(((rgb - self.mean) / self.std).transpose(2, 0, 1)[None])
        out = np.asarray(self.session.run(None, {self.input_name: x})[0], np.float32)
        if out.ndim == 4:
            out = out[0]
        elif out.ndim == 2:
            out = out[None]
        elif out.ndim != 3:  # [C, H, W] (or [1, H, W]) is taken as it is
            raise ValueError(f"{self.path}: output of shape {out.shape} is not an image")
        if out.shape[1:] != (h, w):
            out = np.stack([cv2.resize(c, (w, h), interpolation=cv2.INTER_LINEAR) for c in out])
        return out

    def describe(self) -> dict[str, Any]:
        own = {k: v for k, v in self.meta.items() if k.startswith("bsn.")}
        return {"model": str(self.path), "input": "uint8 BGR NHWC" if self.uint8 else "float RGB NCHW",
                "size": self.fixed_hw, "metadata": own}
