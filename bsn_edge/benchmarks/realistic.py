"""Realistic sources for setting (b) of the label benchmark, made from a rendered clip.

- depth: what a monocular network gives: inverse depth with a smooth multiplicative error
  field (about 10 %, changing slowly over the clip) under an unknown scale and shift, written
  as ``rel_depth/NNNNNN.npy`` and used as ``--depth rel:rel_depth:inverse`` (aligned to
  landmarks by least squares);
- poses: none: ``--poses vo`` (the built-in visual odometry on the rendered frames);
- segmentation: the true classes with boundary errors: boundaries pushed around by a smooth
  random displacement of up to a few pixels.
"""

from __future__ import annotations

import shutil
from pathlib import Path

import cv2
import numpy as np

from bsn_edge.labels import Sources
from bsn_edge.sequence import SequenceMeta, read_depth
from bsn_edge.sequence.folder import SequenceFolder, frame_name
from bsn_edge.sequence.images import read_image
from bsn_edge.synth.shading import periodic_noise

DEPTH_ERROR = 0.10      # multiplicative, smooth
SEG_SHIFT_PX = 3.0      # boundary displacement amplitude


def _smooth_field(rng: np.random.Generator, h: int, w: int, cutoff: float) -> np.ndarray:
    n = periodic_noise(rng, 256, cutoff)
    return cv2.resize(n, (w, h), interpolation=cv2.INTER_LINEAR)


def prepare_realistic(seq: Path, out: Path, seed: int) -> tuple[Path, Sources]:
    """Copy ``seq`` to ``out`` with realistic depth and segmentation; returns it and its sources."""
    if out.exists():
        shutil.rmtree(out)
    out.mkdir(parents=True)
    src, dst = SequenceFolder(seq), SequenceFolder(out)
    shutil.copy(src.meta_path, dst.meta_path)
    shutil.copytree(src.dir(src.RGB), dst.dir(dst.RGB))
    meta = SequenceMeta.read(seq)
    h, w = meta.height, meta.width
    rng = np.random.default_rng([seed, 0xB])
    scale, shift = rng.uniform(2.0, 20.0), rng.uniform(0.0, 0.2)
    err_a, err_b = _smooth_field(rng, h, w, 0.02), _smooth_field(rng, h, w, 0.02)
    (out / "rel_depth").mkdir()
    dst.dir(dst.SEMANTIC).mkdir()
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float32)
    for i in range(meta.frames):
        d = read_depth(src.depth(i))
        phase = i / max(meta.frames - 1, 1)
        err = 1.0 + DEPTH_ERROR * ((1 - phase) * err_a + phase * err_b)
        inv = np.where(d > 0, 1.0 / np.maximum(d, 1e-3), 0.0) * err
        np.save(out / "rel_depth" / frame_name(i, ".npy"), (scale * inv + shift).astype(np.float32))
        sem = read_image(src.semantic(i), cv2.IMREAD_UNCHANGED)
        fx = SEG_SHIFT_PX * _smooth_field(rng, h, w, 0.05)
        fy = SEG_SHIFT_PX * _smooth_field(rng, h, w, 0.05)
        jittered = cv2.remap(sem, xx + fx, yy + fy, cv2.INTER_NEAREST, borderMode=cv2.BORDER_REPLICATE)
        cv2.imwrite(str(dst.semantic(i)), jittered)
    return out, Sources(depth="rel:rel_depth:inverse", seg="files", poses="vo")
