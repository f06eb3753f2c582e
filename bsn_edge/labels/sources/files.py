"""Sources that read the sequence folder's own files."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from bsn_edge.labels.sources.base import ClipData, DepthSource, SegSource
from bsn_edge.sequence import SequenceMeta, read_depth, read_poses, read_tum_poses
from bsn_edge.sequence.folder import SequenceFolder


def frame_count(seq: Path) -> int:
    """Frames of a clip: the images in ``rgb/``, else ``meta.json``'s count (a video clip)."""
    return SequenceFolder(seq).count_frames() or SequenceMeta.read(seq).frames


def _check_files(clip: ClipData, sub: str) -> SequenceFolder:
    seq = SequenceFolder(clip.seq)
    folder = seq.dir(sub)
    if not folder.is_dir():
        raise FileNotFoundError(f"{clip.seq}: no {sub}/ folder (needed for --{'seg' if sub == seq.SEMANTIC else sub} "
                                "files)")
    path = seq.depth if sub == seq.DEPTH else seq.semantic
    missing = [i for i in range(clip.frames) if not path(i).exists()]
    if missing:
        head = ", ".join(path(i).name for i in missing[:5])
        raise FileNotFoundError(f"{folder}: {len(missing)} of {clip.frames} frames missing ({head}...)")
    return seq


class FilesDepth(DepthSource):
    """``depth/NNNNNN.png``: 16-bit, metres x 256."""

    name = "files"

    def __init__(self, clip: ClipData) -> None:
        self.seq = _check_files(clip, SequenceFolder.DEPTH)
        self.shape = (clip.meta.height, clip.meta.width)

    def __call__(self, i: int) -> np.ndarray:
        p = self.seq.depth(i)
        d = read_depth(p)
        if d.shape != self.shape:
            raise ValueError(f"{p}: size {d.shape[0]}x{d.shape[1]} differs from meta.json's "
                             f"{self.shape[0]}x{self.shape[1]}")
        return d


class FilesSeg(SegSource):
    """``semantic/NNNNNN.png``: Cityscapes trainIds."""

    name = "files"

    def __init__(self, clip: ClipData) -> None:
        self.seq = _check_files(clip, SequenceFolder.SEMANTIC)
        self.shape = (clip.meta.height, clip.meta.width)

    def __call__(self, i: int) -> np.ndarray:
        p = self.seq.semantic(i)
        s = cv2.imread(str(p), cv2.IMREAD_UNCHANGED)
        if s is None:
            raise FileNotFoundError(f"{p}: unreadable")
        if s.ndim != 2 or s.shape != self.shape:
            raise ValueError(f"{p}: expected a single-channel {self.shape[0]}x{self.shape[1]} trainId image, "
                             f"got shape {s.shape}")
        return s.astype(np.uint8)


def load_poses(clip: ClipData, spec: str) -> np.ndarray:
    """Camera-to-world poses, one per frame, from ``files`` or a trajectory file (KITTI or TUM).

    A TUM trajectory with timestamps is matched to frame times ``i / fps`` (its first stamp is
    taken as frame 0's time) by nearest stamp within half a frame.
    """
    if spec == "files":
        path = SequenceFolder(clip.seq).poses_path
        if not path.exists():
            raise FileNotFoundError(f"{clip.seq}: no poses.txt (use --poses TRAJ.txt or --poses vo)")
        poses = read_poses(path)
    else:
        path = Path(spec)
        if not path.exists():
            raise FileNotFoundError(f"trajectory file {path} not found")
        first = next((ln for ln in path.read_text().splitlines()
                      if ln.strip() and not ln.lstrip().startswith("#")), "")
        if len(first.split()) == 8:
            stamps, tum = read_tum_poses(path)
            times = stamps[0] + np.arange(clip.frames) / clip.meta.fps
            k = np.clip(np.searchsorted(stamps, times), 1, len(stamps) - 1)
            k = np.where(np.abs(stamps[k - 1] - times) < np.abs(stamps[k] - times), k - 1, k)
            if np.any(np.abs(stamps[k] - times) > 0.5 / clip.meta.fps):
                bad = int(np.argmax(np.abs(stamps[k] - times) > 0.5 / clip.meta.fps))
                raise ValueError(f"{path}: no pose within half a frame of frame {bad} "
                                 f"(t = {times[bad]:.3f} s)")
            poses = tum[k]
        else:
            poses = read_poses(path)
    if len(poses) != clip.frames:
        raise ValueError(f"{path}: {len(poses)} poses for {clip.frames} frames")
    if not np.isfinite(poses).all():
        raise ValueError(f"{path}: non-finite pose values")
    return poses
