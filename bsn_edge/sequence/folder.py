"""The sequence folder's layout, owned by one object: no other module spells a sub-folder name or
a frame pattern.

::

    SEQ/meta.json  poses.txt  video.mp4  synth_config.json  calibration.json (the camera file)
    SEQ/rgb/NNNNNN.png (or .jpg)   depth/NNNNNN.png   semantic/NNNNNN.png
    SEQ/bsgt/NNNNNN.png   boxes/NNNNNN.npy                       (synthetic only)
    SEQ/labels/T5s/blindspot/NNNNNN.png  visibility/NNNNNN.png  report.json  params.json
"""

from __future__ import annotations

import os
from pathlib import Path

from bsn_edge.sequence.media import IMAGE_EXTS

FRAME_DIGITS = 6


def frame_name(i: int, ext: str = ".png") -> str:
    """File name of frame ``i``: ``000042.png``."""
    return f"{i:0{FRAME_DIGITS}d}{ext}"


def frame_index(path: str | Path) -> int | None:
    """Frame index from a file name (``000042.png`` -> 42), None if it is not a frame file."""
    stem = Path(path).stem
    return int(stem) if stem.isdigit() else None


class LabelSet:
    """``SEQ/labels/<name>/``: one set of T-frame labels and what made them."""

    BLINDSPOT, VISIBILITY, REPORT, PARAMS = "blindspot", "visibility", "report.json", "params.json"

    def __init__(self, root: Path) -> None:
        self.root = root

    @property
    def name(self) -> str:
        return self.root.name

    def blindspot(self, i: int) -> Path:
        return self.root / self.BLINDSPOT / frame_name(i)

    def visibility(self, i: int) -> Path:
        return self.root / self.VISIBILITY / frame_name(i)

    @property
    def report_path(self) -> Path:
        return self.root / self.REPORT

    @property
    def params_path(self) -> Path:
        return self.root / self.PARAMS

    def make_dirs(self) -> None:
        for sub in (self.BLINDSPOT, self.VISIBILITY):
            (self.root / sub).mkdir(parents=True, exist_ok=True)

    def frames(self) -> list[int]:
        """Frames that have a blind-spot label file."""
        d = self.root / self.BLINDSPOT
        if not d.is_dir():
            return []
        return sorted(i for p in d.glob("*.png") if (i := frame_index(p)) is not None)


class SequenceFolder:
    """Where every file of one clip lives."""

    META, POSES, VIDEO, SYNTH_CONFIG = "meta.json", "poses.txt", "video.mp4", "synth_config.json"
    CALIBRATION = "calibration.json"
    RGB, DEPTH, SEMANTIC, BSGT, BOXES, LABELS = "rgb", "depth", "semantic", "bsgt", "boxes", "labels"
    FRAME_DIRS = (RGB, DEPTH, SEMANTIC, BSGT, BOXES)
    # everything bsn-synth writes (what its --force replaces)
    SYNTH_OUTPUTS = (*FRAME_DIRS, META, POSES, VIDEO, SYNTH_CONFIG, CALIBRATION)

    def __init__(self, path: str | os.PathLike) -> None:
        self.path = Path(path)

    def __repr__(self) -> str:
        return f"SequenceFolder({str(self.path)!r})"

    def __truediv__(self, name: str) -> Path:
        return self.path / name

    @property
    def meta_path(self) -> Path:
        return self.path / self.META

    @property
    def poses_path(self) -> Path:
        return self.path / self.POSES

    @property
    def video_path(self) -> Path:
        return self.path / self.VIDEO

    @property
    def synth_config_path(self) -> Path:
        return self.path / self.SYNTH_CONFIG

    @property
    def calibration_path(self) -> Path:
        """The clip's camera file (intrinsics, distortion, mounting), when its camera is known."""
        return self.path / self.CALIBRATION

    def dir(self, kind: str) -> Path:
        """One of the per-frame folders (``rgb``, ``depth``, ``semantic``, ``bsgt``, ``boxes``)."""
        if kind not in self.FRAME_DIRS:
            raise ValueError(f"unknown frame folder {kind!r}; valid: {', '.join(self.FRAME_DIRS)}")
        return self.path / kind

    def rgb(self, i: int) -> Path:
        """Frame ``i``'s image: the ``.png`` if there is one, else the first other image kind found
        (a path that does not exist when there is none)."""
        png = self.path / self.RGB / frame_name(i)
        if png.exists():
            return png
        for ext in IMAGE_EXTS:
            p = png.with_suffix(ext)
            if p.exists():
                return p
        return png

    def depth(self, i: int) -> Path:
        return self.path / self.DEPTH / frame_name(i)

    def semantic(self, i: int) -> Path:
        return self.path / self.SEMANTIC / frame_name(i)

    def bsgt(self, i: int) -> Path:
        return self.path / self.BSGT / frame_name(i)

    def boxes(self, i: int) -> Path:
        return self.path / self.BOXES / frame_name(i, ".npy")

    def labels(self, name: str) -> LabelSet:
        """The label set ``name`` (e.g. ``T5s``)."""
        return LabelSet(self.path / self.LABELS / name)

    def rgb_frames(self) -> list[int]:
        """Indices of the frame images in ``rgb/``."""
        d = self.path / self.RGB
        if not d.is_dir():
            return []
        return sorted({i for p in d.iterdir() if p.suffix.lower() in IMAGE_EXTS and (i := frame_index(p)) is not None})

    def count_frames(self) -> int:
        """Frames of the clip: images in ``rgb/``, else the frames of ``video.mp4``; 0 if neither."""
        frames = self.rgb_frames()
        if frames:
            return len(frames)
        if self.video_path.is_file():
            import cv2

            cap = cv2.VideoCapture(str(self.video_path))
            try:
                return max(int(cap.get(cv2.CAP_PROP_FRAME_COUNT)), 0)
            finally:
                cap.release()
        return 0
