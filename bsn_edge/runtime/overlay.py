"""The overlay video: blind spots tinted over the frame, sector levels and distances on top."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from bsn_edge.alerts.frame import AlertFrame
from bsn_edge.alerts.sectors import SectorGeometry
from bsn_edge.alerts.state_machine import Level

LEVEL_BGR = {Level.NONE: (80, 160, 80), Level.CAUTION: (0, 190, 255), Level.WARNING: (0, 0, 255)}
TINT = np.array([40, 40, 255], np.float32)


def draw(frame: np.ndarray, mask: np.ndarray, alert: AlertFrame, geometry: SectorGeometry) -> np.ndarray:
    """``frame`` at model size with the mask tinted and a bar per sector."""
    img = frame.copy()
    if mask.any():
        img[mask] = (img[mask] * 0.45 + TINT * 0.55).astype(np.uint8)
    h = img.shape[0]
    cols = geometry.column_sector
    for s, sector in enumerate(alert.sectors):
        xs = np.nonzero(cols == s)[0]
        if not len(xs):
            continue
        x0, x1 = int(xs[0]), int(xs[-1])
        color = LEVEL_BGR[sector.level]
        cv2.rectangle(img, (x0 + 2, 2), (x1 - 2, 20), color, -1)
        text = sector.level.name if sector.distance_m is None else f"{sector.level.name} {sector.distance_m:.0f}m"
        cv2.putText(img, text, (x0 + 6, 15), cv2.FONT_HERSHEY_SIMPLEX, 0.38, (0, 0, 0), 1, cv2.LINE_AA)
        if s < 2:
            cv2.line(img, (x1, 22), (x1, h), (255, 255, 255), 1)
    cv2.putText(img, f"{alert.state.name} {alert.fps:.0f} fps", (4, h - 6), cv2.FONT_HERSHEY_SIMPLEX, 0.38,
                (255, 255, 255), 1, cv2.LINE_AA)
    return img


class OverlayWriter:
    def __init__(self, path: str | Path, size: tuple[int, int], fps: float) -> None:
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        h, w = size
        self.writer = cv2.VideoWriter(str(self.path), cv2.VideoWriter_fourcc(*"mp4v"), fps, (w, h))
        if not self.writer.isOpened():
            raise OSError(f"OpenCV cannot write {self.path}")

    def write(self, img: np.ndarray) -> None:
        self.writer.write(img)

    def close(self) -> None:
        self.writer.release()
