"""The overlay video: blind spots tinted over the frame, sector levels and distances on top."""

from __future__ import annotations

import errno
import os
from pathlib import Path

import cv2
import numpy as np

from bsn_edge.alerts.blindness import Blindness
from bsn_edge.alerts.frame import AlertFrame
from bsn_edge.alerts.sectors import SectorGeometry
from bsn_edge.alerts.state_machine import Level
from bsn_edge.model_frame import ModelFrame

LEVEL_BGR = {Level.NONE: (80, 160, 80), Level.CAUTION: (0, 190, 255), Level.WARNING: (0, 0, 255)}
UNSEEN_BGR = (160, 160, 160)   # a sector the camera cannot see: grey, whatever its level
TINT = (40, 40, 255)      # BGR of blind spots, blended in at TINT_WEIGHT
TINT_WEIGHT = 0.55


LABEL_FONT, LABEL_SCALE = cv2.FONT_HERSHEY_SIMPLEX, 0.38

def draw(frame: np.ndarray, mf: ModelFrame, mask: np.ndarray, alert: AlertFrame,
         geometry: SectorGeometry) -> np.ndarray:
    """The raw ``frame`` with the model's mask brought back onto it and tinted, and a bar per
    sector (sector edges are bearings in the model camera, drawn where they fall in this frame)."""
    img = frame.copy()
    raw_mask = mf.to_raw(mask.astype(np.uint8), cv2.INTER_NEAREST)
    rows = np.flatnonzero(raw_mask.any(axis=1))
    if len(rows):
        # the rows the mask reaches blended whole and copied where it is: OpenCV's vector code, where
        # numpy's masked indexing took half the drawing's time
        band = img[rows[0]:rows[-1] + 1]
        tinted = cv2.add(cv2.convertScaleAbs(band, alpha=1.0 - TINT_WEIGHT), tuple(TINT_WEIGHT * c for c in TINT))
        cv2.copyTo(tinted, raw_mask[rows[0]:rows[-1] + 1], band)
    h = img.shape[0]
    cols = mf.raw_column_sector(geometry.column_sector)
    for s, sector in enumerate(alert.sectors):
        xs = np.nonzero(cols == s)[0]
        if not len(xs):
            continue
        x0, x1 = int(xs[0]), int(xs[-1])
        color = UNSEEN_BGR if sector.unseen else LEVEL_BGR[sector.level]
        cv2.rectangle(img, (x0 + 2, 2), (x1 - 2, 20), color, -1)
        said = "CANNOT SEE" if sector.unseen else sector.level.name if sector.distance_m is None \
            else f"{sector.level.name} {sector.distance_m:.0f}m"
        text = _fitted((f"{geometry.cfg.names[s]} {said}", said, said.split()[0]), x1 - x0 - 8)
        cv2.putText(img, text, (x0 + 6, 15), LABEL_FONT, LABEL_SCALE, (0, 0, 0), 1, cv2.LINE_AA)
        if s < len(alert.sectors) - 1:
            cv2.line(img, (x1, 22), (x1, h), (255, 255, 255), 1)
    camera = "" if alert.camera is Blindness.CLEAR else f"  camera {alert.camera.name}"
    rate = f" {alert.fps:.0f} fps" if alert.fps > 0 else ""      # none yet on the first frames: not "0 fps"
    cv2.putText(img, f"{alert.state.name}{rate}{camera}", (4, h - 6), cv2.FONT_HERSHEY_SIMPLEX,
                0.38, (255, 255, 255), 1, cv2.LINE_AA)
    return img


def _fitted(texts: tuple[str, ...], width: int) -> str:
    """The first of ``texts`` (longest first) that fits ``width`` pixels, else the last: a narrow sector shows
    its level without its name rather than a label cut off."""
    for text in texts:
        if cv2.getTextSize(text, LABEL_FONT, LABEL_SCALE, 1)[0][0] <= width:
            return text
    return texts[-1]


class OverlayWriter:
    """The overlay video at the raw frame's size (the encoder starts on the first frame; frames of
    another size are fitted to it).

    OpenCV's writer reports no write error, so the file's disk is watched frame by frame: under
    ``MIN_FREE_BYTES`` left on it, or a file that has not grown over ``STALLED_FRAMES`` frames, is an
    ``OSError`` at that frame (the runtime counts it as a sink fault, DEGRADED), not a broken file found
    at the end."""

    MIN_FREE_BYTES = 8 << 20
    STALLED_FRAMES = 100

    def __init__(self, path: str | Path, fps: float) -> None:
        self.path = Path(path)
        self.fps = fps
        self.writer: cv2.VideoWriter | None = None
        self.size: tuple[int, int] | None = None
        self._grown_at = 0          # frames written when the file last grew
        self._bytes = 0
        self._frames = 0

    def open(self) -> None:
        """Create the file, so that a read-only disk refuses at once (on the sink's thread: opening can block)."""
        self.path.parent.mkdir(parents=True, exist_ok=True)
        with open(self.path, "wb"):
            pass

    def write(self, img: np.ndarray) -> None:
        h, w = img.shape[:2]
        if self.writer is None:
            self.size = (w, h)
            self.writer = cv2.VideoWriter(str(self.path), cv2.VideoWriter.fourcc(*"mp4v"), self.fps, (w, h))
            if not self.writer.isOpened():
                raise OSError(f"OpenCV cannot write {self.path}")
        if (w, h) != self.size:
            img = cv2.resize(img, self.size, interpolation=cv2.INTER_AREA)
        self.writer.write(img)
        self._frames += 1
        self._check_room()

    def _check_room(self) -> None:
        vfs = os.statvfs(self.path.parent)
        free = vfs.f_bavail * vfs.f_frsize
        if free < self.MIN_FREE_BYTES:
            raise OSError(errno.ENOSPC, f"{free / 1e6:.1f} MB left on the disk of {self.path} (under "
                                        f"{self.MIN_FREE_BYTES / 1e6:.0f} MB): the overlay is given up before it "
                                        "fills the disk")
        size = os.stat(self.path).st_size
        if size > self._bytes:
            self._bytes, self._grown_at = size, self._frames
        elif self._frames - self._grown_at >= self.STALLED_FRAMES:
            raise OSError(errno.EIO, f"{self.path} has not grown over {self.STALLED_FRAMES} frames: its disk "
                                     "takes no more")

    def close(self) -> None:
        """Finish the file and read it back: OpenCV's writer does not report a full disk, so an overlay
        that cannot be played is an ``OSError`` here, not a file left for the user to find broken."""
        if self.writer is None:
            return
        self.writer.release()
        self.writer = None
        cap = cv2.VideoCapture(str(self.path))
        ok = cap.isOpened() and cap.read()[0]
        cap.release()
        if not ok:
            raise OSError(f"{self.path} cannot be played back (the disk may be full or the file was removed)")
