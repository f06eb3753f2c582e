"""Whether a folder of pictures is one camera.

A folder is one camera when its pictures say so: one size (a few of another are damaged frames), one
camera in their EXIF records (or none in any), and consecutive pictures that show one scene moving on
(enough ORB features matched between them agree on one epipolar geometry, as frames of one drive a
second apart do, and photos of different streets do not). Then online calibration and the first guess
gather over its frames as over a video's. Otherwise each picture is a camera of its own: its own EXIF
lens, the model camera's mounting assumed, nothing carried from one picture to the next.
"""

from __future__ import annotations

import itertools
from collections import Counter
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from enum import Enum
from pathlib import Path

import cv2
import numpy as np

from bsn_edge.calibration.exif import camera_of
from bsn_edge.user_file import read_user_file

PAIRS = 8               # consecutive pairs looked at, from the folder's start
SHARED = 40             # matches on one epipolar geometry that make two pictures one scene moving on
CONTINUOUS_SHARE = 0.5  # of the pairs looked at, at least this share must be continuous
ONE_SIZE_SHARE = 0.75   # of the pictures looked at, at least this share must have the commonest size
_WIDTH = 320            # pictures are compared at this width
_ORB_FEATURES = 1000


class FolderCameras(Enum):
    """What a folder of pictures is."""

    ONE = "one camera"
    EACH = "each picture its own camera"


@dataclass(frozen=True)
class FolderVerdict:
    """A folder's cameras and why."""

    cameras: FolderCameras
    why: str

    def to_dict(self) -> dict[str, str]:
        return {"cameras": self.cameras.value, "why": self.why}


def judge_folder(files: Sequence[Path], pairs: int = PAIRS,
                 read: Callable[[Path], np.ndarray | None] | None = None) -> FolderVerdict:
    """One camera or each picture its own, for the pictures ``files`` in their order; ``read`` decodes a
    picture (None for one that is damaged; default: OpenCV's)."""
    if len(files) < 2:
        return FolderVerdict(FolderCameras.ONE, "one picture")
    named = {camera_of(f) for f in files}
    if len(named) > 1:
        return FolderVerdict(FolderCameras.EACH, f"their EXIF records name {len(named)} cameras")
    looked = files[:pairs + 1]
    pictures = [(read or _read)(f) for f in looked]
    grey = [None if p is None else cv2.cvtColor(p, cv2.COLOR_BGR2GRAY) for p in pictures]
    sizes = Counter(g.shape for g in grey if g is not None)
    if not sizes:
        return FolderVerdict(FolderCameras.ONE, f"none of the first {len(looked)} pictures decodes")
    size, count = sizes.most_common(1)[0]
    if count < ONE_SIZE_SHARE * sum(sizes.values()):
        return FolderVerdict(FolderCameras.EACH, f"the first {len(looked)} pictures have {len(sizes)} sizes")
    # a picture of another size among many of one is a damaged frame of that camera (counted when run)
    feats = [_features(g) for g in grey if g is not None and g.shape == size]
    shared = [_shared(a, b) for a, b in itertools.pairwise(feats)]
    continuous = sum(s >= SHARED for s in shared)
    said = "one camera in their EXIF records" if next(iter(named)) is not None else "no EXIF camera"
    if continuous < CONTINUOUS_SHARE * len(shared):
        return FolderVerdict(FolderCameras.EACH, f"{said}, but only {continuous} of {len(shared)} consecutive "
                                                 "pictures show one scene moving on")
    return FolderVerdict(FolderCameras.ONE, f"{said}, {continuous} of {len(shared)} consecutive pictures "
                                            "show one scene moving on")


def _read(path: Path) -> np.ndarray | None:
    try:
        data = read_user_file(path, "picture")      # never cv2.imread: it would block on a FIFO
    except (OSError, ValueError):
        return None
    try:
        return cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_COLOR)
    except cv2.error:
        return None


def _features(grey: np.ndarray | None) -> tuple[np.ndarray, np.ndarray | None]:
    if grey is None:
        return np.zeros((0, 2), np.float32), None
    s = _WIDTH / grey.shape[1]
    small = cv2.resize(grey, None, fx=s, fy=s, interpolation=cv2.INTER_AREA)
    kp, des = cv2.ORB.create(_ORB_FEATURES).detectAndCompute(small, None)
    return np.array([k.pt for k in kp], np.float32).reshape(-1, 2), des


def _shared(a: tuple[np.ndarray, np.ndarray | None], b: tuple[np.ndarray, np.ndarray | None]) -> int:
    """Matches between two pictures that one fundamental matrix explains."""
    (pa, da), (pb, db) = a, b
    if da is None or db is None:
        return 0
    ms = cv2.BFMatcher(cv2.NORM_HAMMING, crossCheck=True).match(da, db)
    if len(ms) < 8:
        return 0
    p0 = pa[[m.queryIdx for m in ms]]
    p1 = pb[[m.trainIdx for m in ms]]
    _, mask = cv2.findFundamentalMat(p0, p1, cv2.FM_RANSAC, 1.0, 0.999)
    return 0 if mask is None else int(mask.sum())
