"""Repainting vehicles and people in training images: domain randomisation of how objects look.

A synthetic car has a few paints and one shader; a real one has any colour, reflections and grime.
Repainting the pixels of vehicles and people (colour, tone curve, a smooth stain) in a share of the
training samples leaves depth, semantics and blind spots as they are, so the model has to find
objects by their shape and where they stand, not by how the renderer paints them. The dataset and
the sample cache draw and apply it through the same code, so both give the same batches.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import torch

from bsn_edge import semantics as sm

GAIN = (0.35, 1.4)        # per-channel gain range: any hue, dark to bright
GAMMA = (0.6, 1.7)        # tone-curve exponent range
STAIN = 0.35              # largest amplitude of the smooth multiplicative stain
STAIN_CELL = 16           # pixels per cell of the stain's noise (upsampled bilinearly)


@dataclass(frozen=True)
class Repaint:
    """One sample's repaint: RGB channel gains, tone-curve exponent and a stain field (cells)."""

    gain: tuple[float, float, float]
    gamma: float
    stain: np.ndarray          # [h, w] float32, multiplicative, around 1

    @classmethod
    def draw(cls, rng: np.random.Generator, size: tuple[int, int]) -> Repaint:
        """A repaint for an image of ``size`` (H, W), drawn from ``rng`` in a fixed order."""
        gain = tuple(float(g) for g in rng.uniform(*GAIN, 3))
        gamma = float(rng.uniform(*GAMMA))
        amp = rng.uniform(0.0, STAIN)
        cells = rng.standard_normal((size[0] // STAIN_CELL + 1, size[1] // STAIN_CELL + 1))
        stain = (1.0 + amp * np.clip(cells, -2.0, 2.0) / 2.0).astype(np.float32)
        return cls(gain, gamma, stain)


def draw_repaint(rng: np.random.Generator, share: float, size: tuple[int, int]) -> Repaint | None:
    """With probability ``share`` a :class:`Repaint`, else None; draws nothing when ``share`` is 0, so
    the rest of an augmentation stream is the same as without repainting."""
    if share <= 0.0:
        return None
    hit = rng.random() < share
    return Repaint.draw(rng, size) if hit else None


def repaint(rgb: torch.Tensor, semantic: torch.Tensor, paints: Sequence[Repaint | None]) -> torch.Tensor:
    """``rgb`` ``[B, 3, H, W]`` in [0, 1] with the vehicle and person pixels of ``semantic`` ``[B, H, W]``
    (trainIds) repainted by ``paints`` (one per sample, None: as it is). Returns a new tensor."""
    if len(paints) != rgb.shape[0]:
        raise ValueError(f"{len(paints)} repaints for a batch of {rgb.shape[0]}")
    out = rgb.clone()
    h, w = rgb.shape[-2:]
    ids = torch.tensor(sm.ROAD_USERS, device=semantic.device)
    for r, p in enumerate(paints):
        if p is None:
            continue
        obj = torch.isin(semantic[r], ids)
        if not bool(obj.any()):
            continue
        stain = torch.nn.functional.interpolate(torch.from_numpy(p.stain)[None, None], size=(h, w),
                                                mode="bilinear", align_corners=False)[0]
        gain = torch.tensor(p.gain, dtype=rgb.dtype)[:, None, None]
        painted = (rgb[r].clamp(0.0, 1.0) ** p.gamma * gain * stain).clamp_(0.0, 1.0)
        out[r] = torch.where(obj[None], painted, rgb[r])
    return out
