"""Running a trained run and the baselines over labelled clips."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import cv2
import numpy as np
import torch

from bsn_edge.card import ModelCard
from bsn_edge.data import BlindSpotDataset, Clip
from bsn_edge.evaluate.baselines import detection_2d, detection_3d, traversable_hidden
from bsn_edge.metrics import Counts, ScoreHistogram, ThresholdSweep
from bsn_edge.sequence import read_kitti_poses
from bsn_edge.sequence.folder import SequenceFolder
from bsn_edge.synth.sheet import tint
from bsn_edge.train.device import scaled
from bsn_edge.train.validation import outputs

METHODS = ("BSN", "Traversable", "Detection-2D", "Detection-3D")


def _scored(counts: dict[str, Counts], ranked: ScoreHistogram, sweep: ThresholdSweep | None) -> dict[str, Any]:
    """Each method's metrics; BSN's with its average precision (and, over all clips, the sweep's best
    threshold and IoU)."""
    scored: dict[str, dict[str, Any]] = {m: c.metrics() for m, c in counts.items() if c.tp + c.fp + c.fn}
    if "BSN" in scored:
        scored["BSN"]["ap"] = ranked.average_precision()
        if sweep is not None:
            best_th, best = sweep.best()
            scored["BSN"] |= {"ap_by_chance": ranked.positive_share(), "best_threshold": best_th,
                              "best_iou": best["iou"]}
    return scored


@torch.no_grad()
def _baselines(item: dict[str, Any], x: torch.Tensor, depth: np.ndarray, teacher: torch.nn.Module | None,
               teacher_scale: float, intr, boxes_at: Path | None, pose: np.ndarray | None) -> dict[str, np.ndarray]:
    """The paper's baselines on one frame: traversable-and-hidden and 2D detection from the teacher's
    segmentation (or the ground truth's without a teacher), 3D detection where the clip has boxes."""
    if teacher is not None:
        t_logits = teacher(scaled(x, teacher_scale))[0]
        t_logits = torch.nn.functional.interpolate(t_logits, size=x.shape[2:], mode="bilinear", align_corners=False)
        sem = t_logits.argmax(1)[0].numpy().astype(np.uint8)
    else:
        sem = item["semantic"].numpy().astype(np.uint8)
    preds = {"Traversable": traversable_hidden(sem, depth, intr), "Detection-2D": detection_2d(sem)}
    if boxes_at is not None and pose is not None:
        preds["Detection-3D"] = detection_3d(np.load(boxes_at), pose, intr, preds["Detection-2D"])
    return preds


@torch.no_grad()
def evaluate(model, card: ModelCard, clips: list[Clip], size: tuple[int, int], label: str,
             teacher: torch.nn.Module | None, grid_frames: int = 3, teacher_scale: float = 0.5,
             baselines: bool = True) -> dict[str, Any]:
    """Metrics inside V for BSN and (unless ``baselines`` is False) the baselines, overall and per
    clip, plus grid rows. BSN also gets scores that need no threshold: its average precision, and the
    best IoU any threshold of the sweep would give on these clips (optimistic: chosen on the clips it
    scores). ``b_reads`` says what B read beside the frame: D's depth, none, or for an
    ``oracle_depth`` model the clips' own depth. The baselines read the teacher's segmentation, or
    the ground truth's when ``teacher`` is None; ``segmentation`` says which (None: no baselines)."""
    if card.threshold is None:
        raise ValueError("the run has no decision threshold yet (training did not finish)")
    threshold, methods = card.threshold, (METHODS if baselines else METHODS[:1])
    overall = {m: Counts() for m in methods}
    ranked, sweep = ScoreHistogram(), ThresholdSweep()
    per_clip: dict[str, dict[str, Any]] = {}
    rows = []
    card_at = card.at_size(*size)
    intr = card_at.camera
    for clip in clips:
        # everything in the model camera: the frames, the labels and the baselines' geometry
        ds = BlindSpotDataset([clip], size, label_name=label, camera=card_at.camera, mounting=card_at.mounting)
        seq = SequenceFolder(clip.path)
        poses = read_kitti_poses(seq.poses_path) if seq.poses_path.exists() else None
        if poses is not None:
            poses = poses @ ds.warps(clip).pose_fix
        counts = {m: Counts() for m in methods}
        clip_ranked = ScoreHistogram()
        picks = set(np.linspace(0, len(ds) - 1, grid_frames).round().astype(int).tolist()) \
            if grid_frames else set()
        for k in range(len(ds)):
            item = ds[k]
            x = item["image"][None]
            logits, depth, _ = outputs(model, x, {"depth": item["depth"][None]})
            prob = torch.sigmoid(logits)[0, 0].numpy()
            d = depth[0, 0].numpy()
            label_m = item["blindspot"][0].numpy() > 0.5
            vis = item["visibility"][0].numpy() > 0.5
            preds = {"BSN": prob >= threshold}
            if baselines:
                boxes_at = seq.boxes(ds.items[k][1]) if seq.dir(seq.BOXES).is_dir() and poses is not None else None
                pose = poses[ds.items[k][1]] if boxes_at is not None and poses is not None else None
                preds |= _baselines(item, x, d, teacher, teacher_scale, intr, boxes_at, pose)
            for h in (clip_ranked, sweep):
                h.add(prob, label_m, vis)
            for m, p in preds.items():
                counts[m].add(p, label_m, vis)
                overall[m].add(p, label_m, vis)
            if k in picks:
                rgb = ds.load(k)["rgb"]
                rows.append((rgb, label_m, vis, preds))
        per_clip[clip.path.name] = {"style": clip.style, "frames": len(ds),
                                    **_scored(counts, clip_ranked, None)}
        ranked.merge(clip_ranked)
    scored = _scored(overall, ranked, sweep)
    b_reads = ("ground-truth depth (a research oracle; no camera has it)" if model.oracle_depth
               else "D's depth" if model.use_depth else "no depth")
    return {"threshold": threshold, "methods": list(methods), "overall": scored, "b_reads": b_reads,
            "per_clip": per_clip, "grid_rows": rows,
            "segmentation": (None if not baselines else "teacher" if teacher is not None
                             else "ground truth (no teacher in the run)")}


def grid_image(rows, methods=METHODS) -> np.ndarray:
    """Figure-5-style grid: frame, T-frame labels, then each method (blind spots tinted red,
    outside V dimmed)."""
    out = []
    for rgb, label_m, vis, preds in rows:
        dim = rgb.copy()
        dim[~vis] = (dim[~vis] * 0.45).astype(np.uint8)
        tiles = [rgb, tint(dim, label_m)] + [tint(dim, preds[m]) if m in preds else np.zeros_like(rgb)
                                             for m in methods]
        out.append(np.hstack(tiles))
    grid = np.vstack(out)
    bar = np.full((20, grid.shape[1], 3), 255, np.uint8)
    w = rows[0][0].shape[1]
    for i, name in enumerate(("frame", "T-frame labels", *methods)):
        cv2.putText(bar, name, (i * w + 4, 14), cv2.FONT_HERSHEY_SIMPLEX, 0.4, (0, 0, 0), 1, cv2.LINE_AA)
    return np.vstack([bar, grid])

