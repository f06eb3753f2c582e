"""Camera intrinsics and distortion from chessboard views (OpenCV)."""

from __future__ import annotations

import os
from collections.abc import Iterator
from pathlib import Path

import cv2
import numpy as np

from bsn_edge.calibration.camera_file import Calibration
from bsn_edge.camera import Intrinsics
from bsn_edge.sequence.media import IMAGE_EXTS, VIDEO_EXTS

SUBPIX = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 30, 1e-3)


def _views(source: Path, every: int) -> Iterator[tuple[str, np.ndarray | None]]:
    if source.is_dir():
        for p in sorted(q for q in source.iterdir() if q.suffix.lower() in IMAGE_EXTS):
            yield p.name, cv2.imread(str(p), cv2.IMREAD_GRAYSCALE)
    elif source.suffix.lower() in VIDEO_EXTS:
        cap = cv2.VideoCapture(str(source))
        if not cap.isOpened():
            raise ValueError(f"{source}: OpenCV cannot open this video")
        i = 0
        while True:
            ok, frame = cap.read()
            if not ok:
                break
            if i % every == 0:
                yield f"frame {i}", cv2.cvtColor(frame, cv2.COLOR_BGR2GRAY)
            i += 1
        cap.release()
    else:
        raise ValueError(f"{source}: give a folder of chessboard images or a video of a chessboard")


def calibrate(source: str | os.PathLike, board: tuple[int, int] = (9, 6), square_m: float = 0.025,
              video_every: int = 10, progress=None) -> Calibration:
    """Find the board's inner corners (``board`` = columns x rows) in every view, refine them,
    and solve for intrinsics and distortion. Views without the whole board are skipped and listed."""
    source = Path(source)
    if not source.exists():
        raise FileNotFoundError(f"{source} not found")
    cols, rows = board
    objp = np.zeros((cols * rows, 3), np.float32)
    objp[:, :2] = np.mgrid[0:cols, 0:rows].T.reshape(-1, 2) * square_m
    obj, img, used, skipped, size = [], [], [], [], None
    for name, gray in _views(source, video_every):
        if progress:
            progress(1)
        if gray is None:
            skipped.append({"view": name, "reason": "unreadable image"})
            continue
        if size is None:
            size = (gray.shape[1], gray.shape[0])
        elif gray.shape[::-1] != size:
            # another size means another (resampled) camera matrix: never mixed in
            skipped.append({"view": name, "reason": f"size {gray.shape[1]}x{gray.shape[0]} (width x height) "
                                                    f"differs from {size[0]}x{size[1]}"})
            continue
        flags = cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE
        found, corners = cv2.findChessboardCorners(gray, (cols, rows), flags=flags)
        if not found:
            skipped.append({"view": name, "reason": f"no complete {cols}x{rows} board found"})
            continue
        corners = cv2.cornerSubPix(gray, corners, (11, 11), (-1, -1), SUBPIX)
        obj.append(objp)
        img.append(corners)
        used.append(name)
    if not used and not skipped:
        kinds = " ".join(sorted(IMAGE_EXTS)) if source.is_dir() else "frames"
        raise ValueError(f"{source}: no images found (looked for {kinds}); give a folder of chessboard photos "
                         "or a video of the board")
    if len(used) < 3:
        raise ValueError(f"{source}: found the {cols}x{rows} board in {len(used)} views; need at least 3 "
                         f"(skipped: {len(skipped)})")
    assert size is not None     # a board was found in a view of this size
    rms, K, dist, _, _ = cv2.calibrateCamera(obj, img, size, None, None)
    k = Intrinsics(float(K[0, 0]), float(K[1, 1]), float(K[0, 2]), float(K[1, 2]), int(size[0]), int(size[1]))
    return Calibration(k, tuple(float(d) for d in dist.ravel()[:5]), float(rms), tuple(used), tuple(skipped),
                       board, square_m, intrinsics_method="chessboard")
