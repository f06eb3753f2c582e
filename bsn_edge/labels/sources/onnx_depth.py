"""Depth from a user's ONNX monocular depth model, aligned to the clip's landmarks."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import cv2
import numpy as np

from bsn_edge.labels.align import Alignment, fit, pooled_correlation
from bsn_edge.labels.landmarks import frame_landmarks
from bsn_edge.labels.sources.base import ClipData, ClipRejectedError, DepthSource
from bsn_edge.labels.sources.onnx_model import OnnxImageModel
from bsn_edge.sequence.frames import read_gray, read_rgb
from bsn_edge.tracks import Matches

if TYPE_CHECKING:
    from bsn_edge.labels.config import LabelConfig


SMOOTH_REL = 0.1  # landmarks where the prediction varies more than this over 3x3 are skipped


def locally_smooth(pred: np.ndarray) -> np.ndarray:
    """Pixels where the prediction is smooth over their 3x3 neighbourhood. Corners, which the
    tracker likes, often sit on depth edges, where a rounded pixel may read the other surface."""
    k = np.ones((3, 3), np.uint8)
    p = pred.astype(np.float32)
    hi, lo = cv2.dilate(p, k), cv2.erode(p, k)
    with np.errstate(invalid="ignore", over="ignore"):   # unknown pixels (NaN) are never smooth
        smooth = (hi - lo) <= SMOOTH_REL * np.maximum(np.abs(hi), 1e-6)
    return smooth & np.isfinite(hi) & np.isfinite(lo)


class AlignedDepth(DepthSource):
    """A relative depth predictor brought into the poses' units by least squares on landmarks.

    ``window=None`` (default) fits one scale and shift to all landmarks of the clip: robust, and
    right for poses of one scale and a network whose output scale is stable across a clip.
    ``window=k`` fits each frame on the landmarks of the ``k`` frames either side of it (0: the
    frame alone), for poses whose scale drifts (monocular VO) or networks whose scale wanders.
    The clip is rejected when the correlation of the aligned prediction with the landmarks is
    under ``min_corr``.
    """

    name = "aligned"

    def __init__(self, predict, kind: str, clip: ClipData, poses: np.ndarray, frames: list[int],
                 min_corr: float, window: int | None = None, matches: Matches | None = None) -> None:
        self.kind, self.window = kind, window
        self._pred: dict[int, np.ndarray] = {}
        self._align: dict[int, Alignment] = {}
        K = clip.meta.intrinsics.K
        grays: dict[int, np.ndarray] = {}

        def gray(j: int) -> np.ndarray:
            if j not in grays:
                grays[j] = read_gray(clip.seq, j)
            return grays[j]

        samples: list[tuple[np.ndarray, np.ndarray]] = []
        for i in frames:
            pred = predict(i)
            self._pred[i] = pred
            u, v, z = frame_landmarks(gray, i, clip.frames, clip.meta.fps, poses, K, matches)
            ui, vi = np.rint(u).astype(int), np.rint(v).astype(int)
            smooth = locally_smooth(pred)[vi, ui]
            samples.append((pred[vi[smooth], ui[smooth]], z[smooth]))
            for old in [j for j in grays if j < i]:
                del grays[old]
        self.n_landmarks = int(sum(len(z) for _, z in samples))

        def fit_range(lo: int, hi: int) -> Alignment:
            part = samples[max(lo, 0):hi]
            return fit(np.concatenate([p for p, _ in part]), np.concatenate([z for _, z in part]), kind)

        try:
            clip_fit = fit_range(0, len(samples))
        except ValueError as e:
            raise ClipRejectedError(f"depth model cannot be aligned: {e}") from None
        self.frames_without_landmarks = 0
        for k, i in enumerate(frames):
            a = clip_fit
            if window is not None:
                try:
                    a = fit_range(k - window, k + window + 1)
                except ValueError:
                    self.frames_without_landmarks += 1
            self._align[i] = a
        self.clip_fit = clip_fit
        if window is None:
            self.corr = clip_fit.corr
        else:
            self.corr = pooled_correlation([p for p, _ in samples], [z for _, z in samples],
                                           [self._align[i] for i in frames])
        if not self.corr >= min_corr:      # NaN (nothing to correlate) is a rejection too
            raise ClipRejectedError(f"depth/landmark alignment correlation {self.corr:.2f} is under "
                                    f"{min_corr:.2f}")

    def __call__(self, i: int) -> np.ndarray:
        if i not in self._pred:
            raise KeyError(f"frame {i} was not aligned (not a label-rate frame)")
        return self._align[i].apply(self._pred[i])

    def describe(self) -> dict[str, Any]:
        return {"kind": self.name, "prediction": self.kind, "window": self.window,
                "correlation": round(self.corr, 4), "landmarks": self.n_landmarks,
                "clip_scale": round(self.clip_fit.scale, 4), "clip_shift": round(self.clip_fit.shift, 4),
                "frames_without_landmarks": self.frames_without_landmarks}


class OnnxDepth(AlignedDepth):
    """``onnx:MODEL``: the model's first output is depth or inverse depth (``bsn.depth_kind`` in its
    metadata: ``depth`` or ``inverse_depth``; MiDaS-style ``inverse_depth`` by default)."""

    name = "onnx"
    model: OnnxImageModel

    @classmethod
    def for_clip(cls, model: str, clip: ClipData, poses: np.ndarray, cfg: LabelConfig,
                 frames: list[int], window: int | None = None) -> OnnxDepth:
        net = OnnxImageModel(model)
        kind = net.meta.get("bsn.depth_kind", "inverse_depth")
        obj = cls(lambda i: net(read_rgb(clip.seq, i))[0], kind, clip, poses, frames, cfg.min_corr, window)
        obj.model = net
        return obj

    def describe(self) -> dict[str, Any]:
        return {**super().describe(), **self.model.describe(), "kind": "onnx"}
