"""Training data: labelled sequence folders -> tensors, split by clip, geometry-honest augmentation."""

from __future__ import annotations

import hashlib
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
import torch
from torch.utils.data import Dataset

from bsn_edge import semantics as sm
from bsn_edge.calibration.camera_file import clip_camera
from bsn_edge.camera import Intrinsics
from bsn_edge.data.camera_look import camera_look, draw_camera_look
from bsn_edge.data.guessed_camera import ClipCamera, Guess, guessed_camera
from bsn_edge.data.repaint import draw_repaint, draw_see_through, repaint, see_through
from bsn_edge.labels.generator import label_camera
from bsn_edge.model_frame import ModelFrame, model_camera
from bsn_edge.mounting import Mounting
from bsn_edge.sequence import SequenceMeta, read_depth, read_mask
from bsn_edge.sequence.folder import SequenceFolder
from bsn_edge.sequence.frames import read_rgb

IMAGENET_MEAN = np.array([0.485, 0.456, 0.406], np.float32)
IMAGENET_STD = np.array([0.229, 0.224, 0.225], np.float32)


@dataclass(frozen=True)
class Clip:
    """A labelled sequence folder."""

    path: Path
    style: str
    frames: tuple[int, ...]     # frames that have labels


def find_clips(root: str | Path, label_name: str = "T5s",
               skipped: list[tuple[str, str]] | None = None) -> list[Clip]:
    """Every sequence folder under ``root`` (itself included) that has labels ``label_name``.
    Folders found without usable labels are appended to ``skipped`` as ``(folder, reason)``."""
    root = Path(root)
    if not root.exists():
        raise FileNotFoundError(f"data folder {root} not found")
    out = []
    for meta_path in sorted([root / SequenceFolder.META, *root.rglob(f"*/{SequenceFolder.META}")]):
        if not meta_path.exists():
            continue
        seq = SequenceFolder(meta_path.parent)
        labels = seq.labels(label_name)
        frames = tuple(labels.frames())
        if not frames:
            if skipped is not None:
                why = "labelled, but no frame: the clip is shorter than T" if labels.root.is_dir() \
                    else f"no labels/{label_name} (run bsn-label on it)"
                skipped.append((str(seq.path), why))
            continue
        meta = SequenceMeta.read(seq.path)
        out.append(Clip(seq.path, str(meta.extra.get("style", meta.source)), frames))
    if not out:
        other = sorted({q.name for q in root.rglob("labels/T*s") if q.is_dir()} - {label_name})
        hint = (f"; the clips there have labels {', '.join(other)}: pass --set data.label=\"{other[0]}\" "
                "(the horizon they were made with)") if other else "; make them with bsn-label"
        raise ValueError(f"no labelled sequence folders (labels/{label_name}) under {root}{hint}")
    return out


def split_clips(clips: list[Clip], val_fraction: float, test_fraction: float,
                seed: int = 0) -> dict[str, list[Clip]]:
    """Split by clip, never by frame: a clip's frames are near-duplicates of each other. A clip's
    split depends on its folder name and the seed, so adding clips rarely moves others; and when
    validation is asked for, every style with two or more training clips gets at least one
    validation clip (else its decision threshold would be chosen on nothing)."""
    if not 0 <= val_fraction < 1 or not 0 <= test_fraction < 1 or val_fraction + test_fraction >= 1:
        raise ValueError(f"bad split fractions val={val_fraction} test={test_fraction}")

    def key(c: Clip) -> float:
        return int(hashlib.sha256(f"{seed}:{c.path.name}".encode()).hexdigest()[:8], 16) / 0xFFFFFFFF

    out: dict[str, list[Clip]] = {"train": [], "val": [], "test": []}
    for c in clips:
        h = key(c)
        part = "test" if h < test_fraction else "val" if h < test_fraction + val_fraction else "train"
        out[part].append(c)
    if val_fraction > 0:
        for style in sorted({c.style for c in out["train"]}):
            own = [c for c in out["train"] if c.style == style]
            if len(own) >= 2 and not any(c.style == style for c in out["val"]):
                moved = min(own, key=key)
                out["train"].remove(moved)
                out["val"].append(moved)
    return out


class ClipWarps:
    """The warps of one clip into the model camera: its frames (with the clip's lens) and its
    labels (made in the clip's undistorted camera, bsn-label's). With ``camera`` GUESSED the frames
    are warped with the camera a user without a camera file gets (:mod:`~bsn_edge.data.guessed_camera`),
    and everything else follows them: the labels are brought onto the raw frame first (through the
    clip's lens), then warped as the frames are."""

    def __init__(self, path: Path, label_name: str, model: Intrinsics, model_mounting: Mounting,
                 camera: ClipCamera = ClipCamera.OWN) -> None:
        meta = SequenceMeta.read(path)
        own = clip_camera(path, model_mounting)
        own_mounting = own.mounting or model_mounting     # clip_camera gives every clip one
        lab_cam = (label_camera(SequenceFolder(path).labels(label_name)) or own.intrinsics).scaled(meta.width,
                                                                                                   meta.height)
        self.guess: Guess | None = None
        self._onto_raw: ModelFrame | None = None
        self.labels: ModelFrame | None
        if camera is ClipCamera.OWN:
            cam = own
            self.labels = ModelFrame(lab_cam, (), own_mounting, model, model_mounting)
        else:
            cam, self.guess = guessed_camera(path, own, meta.width, meta.height, model, model_mounting)
            self.labels = None
            if own.has_distortion or lab_cam != own.intrinsics.scaled(meta.width, meta.height):
                self._onto_raw = ModelFrame(own.intrinsics.scaled(meta.width, meta.height), own.dist, own_mounting,
                                            lab_cam, own_mounting)
        self.frames = cam.model_frame(meta.width, meta.height, model, model_mounting)
        # the clip camera's pose turned into the model camera's: T_wc_model = T_wc_raw [R_raw<-model]
        self.pose_fix = np.eye(4)
        self.pose_fix[:3, :3] = (cam.mounting or model_mounting).rotation() @ model_mounting.rotation().T

    def labels_to_model(self, mask: np.ndarray) -> np.ndarray:
        """A label mask of the clip (bsn-label's camera) in the model camera, nearest."""
        if self.labels is not None:
            return self.labels.labels_to_model(mask)
        if self._onto_raw is not None:
            mask = self._onto_raw.to_raw(mask, cv2.INTER_NEAREST)
        return self.frames.labels_to_model(mask)


class BlindSpotDataset(Dataset):
    """Samples of labelled clips warped into the model camera ``camera`` at ``size`` (H, W).

    Each item: ``image`` [3, H, W] normalised RGB, ``depth`` [1, H, W] metres (0 = none),
    ``semantic`` [H, W] trainIds (255 ignore), ``blindspot`` and ``visibility`` [1, H, W] 0/1,
    ``sky`` [1, H, W] bool. Every clip is warped into the model camera (``camera`` and
    ``mounting``, :class:`ModelFrame`: frames with their lens, masks nearest, depth converted to
    the model camera at its reference height); outside the clip's view and on the car's hood
    the visibility mask is 0. ``augment`` flips horizontally (everything together, so left stays
    left of right in image, labels, depth and semantics alike), jitters brightness/contrast and
    repaints the vehicles and people of a share ``object_repaint`` of the samples
    (:mod:`~bsn_edge.data.repaint`) and shows a share ``camera_look`` through a camera of their own
    (:mod:`~bsn_edge.data.camera_look`). ``clip_camera`` GUESSED warps every clip with the camera a user
    without a camera file gets instead of its own (:mod:`~bsn_edge.data.guessed_camera`).
    """

    def __init__(self, clips: list[Clip], size: tuple[int, int], augment: bool = False,
                 label_name: str = "T5s", seed: int = 0, camera: Intrinsics | None = None,
                 mounting: Mounting | None = None, object_repaint: float = 0.0,
                 object_see_through: float = 0.0, clip_camera: ClipCamera = ClipCamera.OWN,
                 camera_look: float = 0.0) -> None:
        for name, share in (("object_repaint", object_repaint), ("object_see_through", object_see_through),
                            ("camera_look", camera_look)):
            if not 0.0 <= share <= 1.0:
                raise ValueError(f"{name} is a share of samples in [0, 1], got {share}")
        self.items = [(c, f) for c in clips for f in c.frames]
        if not self.items:
            raise ValueError("dataset is empty")
        self.size = size
        if camera is None or mounting is None:
            camera, mounting = model_camera((size[0], size[1]))
        self.camera, self.mounting = camera, mounting
        if (self.camera.height, self.camera.width) != tuple(size):
            raise ValueError(f"model camera is {self.camera.height}x{self.camera.width}, the size {size[0]}x{size[1]}")
        self._warps: dict[Path, ClipWarps] = {}
        self.augment = augment
        self.object_repaint = object_repaint
        self.object_see_through = object_see_through
        self.camera_look = camera_look
        self.label_name = label_name
        self.seed = seed
        self.clip_camera = ClipCamera(clip_camera)

    def __len__(self) -> int:
        return len(self.items)

    def warps(self, clip: Clip) -> ClipWarps:
        if clip.path not in self._warps:
            self._warps[clip.path] = ClipWarps(clip.path, self.label_name, self.camera, self.mounting,
                                               self.clip_camera)
        return self._warps[clip.path]

    def load(self, k: int) -> dict[str, np.ndarray]:
        clip, f = self.items[k]
        seq = SequenceFolder(clip.path)
        lab = seq.labels(self.label_name)
        warp = self.warps(clip)
        rgb = read_rgb(clip.path, f)
        sem_p = seq.semantic(f)
        sem_raw = cv2.imread(str(sem_p), cv2.IMREAD_UNCHANGED) if sem_p.is_file() else None   # none: a user's clip
        sem = sem_raw if sem_raw is not None else np.full(rgb.shape[:2], sm.IGNORE, np.uint8)
        dep_p = seq.depth(f)
        depth = read_depth(dep_p) if dep_p.exists() else np.zeros(rgb.shape[:2], np.float32)
        fr = warp.frames
        sem_m = fr.labels_to_model(sem)
        sem_m[~fr.seen] = sm.IGNORE
        vis = warp.labels_to_model(read_mask(lab.visibility(f)).astype(np.uint8))
        vis[~fr.seen] = 0                      # the clip's camera does not see there
        if sem_raw is not None:
            vis[sem_m == sm.IGNORE] = 0        # the car's own hood
        return {
            "rgb": fr.to_model(rgb),
            "depth": fr.depth_to_model(depth),
            "semantic": sem_m,
            "blindspot": warp.labels_to_model(read_mask(lab.blindspot(f)).astype(np.uint8)),
            "visibility": vis,
        }

    def __getitem__(self, key: int | tuple[int, int]) -> dict[str, torch.Tensor]:
        """Item ``key``, or ``(k, draw)``: item ``k`` augmented with the draw ``draw`` (the
        trainer's stream gives each sample its own, so augmentation does not depend on order)."""
        k, draw = key if isinstance(key, tuple) else (key, key)
        a = self.load(k)
        rgb = a["rgb"][..., ::-1].astype(np.float32) / 255.0
        if self.augment:
            rng = np.random.default_rng([self.seed, draw])
            if rng.random() < 0.5:
                a = {name: v[:, ::-1] for name, v in a.items()}
                rgb = rgb[:, ::-1]
            rgb = np.clip(rgb * rng.uniform(0.8, 1.2) + rng.uniform(-0.08, 0.08), 0, 1)
            paint = draw_repaint(rng, self.object_repaint, rgb.shape[:2])
            through = draw_see_through(rng, self.object_see_through, rgb.shape[:2])
            look = draw_camera_look(rng, self.camera_look, rgb.shape[:2])
            if paint is not None or through is not None or look is not None:
                x = torch.from_numpy(np.ascontiguousarray(rgb.transpose(2, 0, 1)))[None]
                sem_t = torch.from_numpy(np.ascontiguousarray(a["semantic"]))[None]
                if paint is not None:
                    x = repaint(x, sem_t, [paint])
                if through is not None:
                    x = see_through(x, sem_t, [through])
                if look is not None:
                    x = camera_look(x, [look])
                rgb = x[0].numpy().transpose(1, 2, 0)
        img = (rgb - IMAGENET_MEAN) / IMAGENET_STD
        sem = a["semantic"].astype(np.int64)
        return {
            "image": torch.from_numpy(np.ascontiguousarray(img.transpose(2, 0, 1))),
            "depth": torch.from_numpy(np.ascontiguousarray(a["depth"]))[None].float(),
            "semantic": torch.from_numpy(np.ascontiguousarray(sem)),
            "blindspot": torch.from_numpy(np.ascontiguousarray(a["blindspot"]))[None].float(),
            "visibility": torch.from_numpy(np.ascontiguousarray(a["visibility"]))[None].float(),
            "sky": torch.from_numpy(np.ascontiguousarray(a["semantic"] == sm.SKY))[None],
        }
