"""Quantization calibration sets: frames sampled evenly from a folder of images or a video,
brought to the model's input (warped into the model camera when a camera file is known, else
resized), cached as a ``.npz`` beside nothing the user owns."""

from __future__ import annotations

import hashlib
import os
from collections.abc import Iterator
from pathlib import Path

import cv2
import numpy as np

from bsn_edge.calibration.camera_file import Calibration
from bsn_edge.card import ModelCard
from bsn_edge.sequence.folder import SequenceFolder
from bsn_edge.sequence.media import IMAGE_EXTS, VIDEO_EXTS


def _images(folder: Path) -> list[Path]:
    files = sorted(p for p in folder.rglob("*") if p.suffix.lower() in IMAGE_EXTS)
    # a sequence folder: take its RGB frames, not its depth or masks
    rgb = [p for p in files if p.parent.name == SequenceFolder.RGB]
    return rgb or files


def _open_video(path: Path) -> cv2.VideoCapture:
    cap = cv2.VideoCapture(str(path))
    if not cap.isOpened():
        raise ValueError(f"{path}: OpenCV cannot open this video")
    return cap


def _video_frames(path: Path, count: int) -> Iterator[np.ndarray]:
    """Up to ``count`` frames spread evenly over the whole video. A container that does not say how many
    frames it holds is counted first (grabbed, not decoded), so the picks still span all of it."""
    cap = _open_video(path)
    n = int(cap.get(cv2.CAP_PROP_FRAME_COUNT) or 0)
    try:
        if n <= 0:
            while cap.grab():
                n += 1
            cap.release()
            cap = _open_video(path)
        picks = set(np.linspace(0, max(n - 1, 0), min(count, n)).round().astype(int).tolist())
        i = 0
        while i <= max(picks, default=-1):
            ok = cap.grab()
            if not ok:
                break
            if i in picks:
                ok, frame = cap.retrieve()
                if ok:
                    yield frame
            i += 1
    finally:
        cap.release()


def _sequences(folder: Path) -> list[Path]:
    """The sequence folders directly inside ``folder`` (none when ``folder`` is one itself)."""
    if (folder / SequenceFolder.RGB).is_dir():
        return []
    return sorted(d for d in folder.iterdir() if d.is_dir() and (d / SequenceFolder.RGB).is_dir())


def _from_folder(folder: Path, size: tuple[int, int], count: int, card: ModelCard | None) -> list[np.ndarray]:
    """Up to ``count`` frames of one folder, evenly spaced, in the model's input: warped into the card's
    model camera when the folder is a sequence folder with a camera file, else resized."""
    h, w = size
    files = _images(folder)
    picks: list[int] = np.unique(np.linspace(0, len(files) - 1, min(count, len(files))).round().astype(int)).tolist() \
        if files else []
    frames = [img for k in picks if (img := cv2.imread(str(files[k]), cv2.IMREAD_COLOR)) is not None]
    if not frames:
        return []
    cam_file = SequenceFolder(folder).calibration_path
    if card is not None and cam_file.is_file():
        cam, at = Calibration.read(cam_file), card.at_size(h, w)
        fh, fw = frames[0].shape[:2]
        mf = cam.model_frame(fw, fh, at.camera, at.mounting)
        return [mf.to_model(f) for f in frames if f.shape[:2] == (fh, fw)]
    return [cv2.resize(f, (w, h), interpolation=cv2.INTER_AREA) for f in frames]


def load_frames(source: str | os.PathLike, size: tuple[int, int], count: int = 64,
                cache_dir: str | os.PathLike | None = None, card: ModelCard | None = None) -> np.ndarray:
    """``[N, H, W, 3]`` uint8 BGR frames for calibration (``N <= count``), sampled evenly.

    ``source`` is a folder of images (a sequence folder's ``rgb/`` is preferred), a folder of
    sequence folders (the count shared evenly between them, each sampled evenly) or a video file.
    With ``card``, frames of a sequence folder that has a camera file are warped into the card's
    model camera as the runtime warps them, each clip by its own camera; otherwise they are resized.
    Raises ``ValueError`` when no frame can be read. With ``cache_dir`` the set is cached, keyed by
    the source's path, modification time, size and count.
    """
    src = Path(source)
    if not src.exists():
        raise FileNotFoundError(f"calibration source {src} not found")
    h, w = size
    key = None
    if cache_dir is not None:
        stamp = f"{src.resolve()}|{src.stat().st_mtime_ns}|{h}x{w}|{count}|{card.camera if card else ''}"
        key = Path(cache_dir) / f"calib-{hashlib.sha256(stamp.encode()).hexdigest()[:16]}.npz"
        if key.is_file():
            return np.load(key)["frames"]
    frames: list[np.ndarray] = []
    if src.is_dir():
        seqs = _sequences(src)
        if seqs:
            shares = [len(a) for a in np.array_split(np.arange(count), len(seqs))]
            for seq, n in zip(seqs, shares, strict=True):
                frames += _from_folder(seq, size, n, card) if n else []
        else:
            frames = _from_folder(src, size, count, card)
    elif src.suffix.lower() in VIDEO_EXTS:
        frames = [cv2.resize(f, (w, h), interpolation=cv2.INTER_AREA) for f in _video_frames(src, count)]
    else:
        raise ValueError(f"{src}: a calibration source is a folder of images or a video "
                         f"({', '.join(VIDEO_EXTS)})")
    if not frames:
        raise ValueError(f"{src}: no readable frames for calibration")
    out = np.stack(frames[:count])
    if key is not None:
        key.parent.mkdir(parents=True, exist_ok=True)
        np.savez_compressed(key, frames=out)
    return out
