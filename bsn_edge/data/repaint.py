"""Repainting vehicles and people in training images: domain randomisation of how objects look.

A synthetic car has a few paints and one shader; a real one has any colour, reflections and grime,
and glass through which, or in which, the scene around it shows. Two augmentations change the
pixels of vehicles and people in a share of the training samples and leave depth, semantics and
blind spots as they are, so the model has to find objects by their shape and where they stand, not
by what they show inside their outline:

- a repaint (:class:`Repaint`): colour gains, a tone curve, a smooth stain;
- see-through (:class:`SeeThrough`): the scene from elsewhere in the same frame (shifted, mostly
  from higher up: buildings, trees, sky) blended into patches of the objects, tinted as glass is.

The dataset and the sample cache draw and apply both through the same code, so both give the same
batches.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Protocol, Self, TypeVar

import numpy as np
import torch

from bsn_edge import semantics as sm

GAIN = (0.35, 1.4)        # per-channel gain range: any hue, dark to bright
GAMMA = (0.6, 1.7)        # tone-curve exponent range
STAIN = 0.35              # largest amplitude of the smooth multiplicative stain
STAIN_CELL = 16           # pixels per cell of the stain's noise (upsampled bilinearly)
THROUGH_ALPHA = (0.4, 1.0)     # range of the largest blend of the shown scene into an object
THROUGH_TINT = (0.35, 1.0)     # range of the glass tint's gain on the shown scene
THROUGH_UP = (1 / 16, 1 / 3)   # range of how far up the shown scene comes from, shares of the height
THROUGH_SIDE = 0.25            # largest sideways offset of the shown scene, share of the width
THROUGH_CELL = 24              # pixels per cell of the blend's noise (patches, as panes and reflections)


def _field(cells: np.ndarray, h: int, w: int, dtype: torch.dtype) -> torch.Tensor:
    """A field of ``cells`` upsampled bilinearly to ``[1, h, w]``."""
    return torch.nn.functional.interpolate(torch.from_numpy(cells)[None, None], size=(h, w), mode="bilinear",
                                           align_corners=False)[0].to(dtype)


@dataclass(frozen=True)
class Repaint:
    """One sample's repaint: RGB channel gains, tone-curve exponent and a stain field (cells)."""

    gain: tuple[float, float, float]
    gamma: float
    stain: np.ndarray          # [h, w] float32, multiplicative, around 1

    @classmethod
    def draw(cls, rng: np.random.Generator, size: tuple[int, int]) -> Repaint:
        """A repaint for an image of ``size`` (H, W), drawn from ``rng`` in a fixed order."""
        r, g, b = (float(x) for x in rng.uniform(*GAIN, 3))
        gain = (r, g, b)
        gamma = float(rng.uniform(*GAMMA))
        amp = rng.uniform(0.0, STAIN)
        cells = rng.standard_normal((size[0] // STAIN_CELL + 1, size[1] // STAIN_CELL + 1))
        stain = (1.0 + amp * np.clip(cells, -2.0, 2.0) / 2.0).astype(np.float32)
        return cls(gain, gamma, stain)

    def apply(self, img: torch.Tensor) -> torch.Tensor:
        """The whole image ``[3, H, W]`` in [0, 1] as repainted (the caller keeps it on objects only)."""
        h, w = img.shape[-2:]
        stain = _field(self.stain, h, w, img.dtype)
        gain = torch.tensor(self.gain, dtype=img.dtype)[:, None, None]
        return (img.clamp(0.0, 1.0) ** self.gamma * gain * stain).clamp_(0.0, 1.0)


@dataclass(frozen=True)
class SeeThrough:
    """One sample's see-through: the frame shifted by ``shift`` (rows down, columns right; the
    content at ``(y - dy, x - dx)`` shows at ``(y, x)``, wrapping around the edges), tinted by
    ``tint`` and blended in by the field ``alpha`` (cells, in [0, 1])."""

    shift: tuple[int, int]
    tint: float
    alpha: np.ndarray          # [h, w] float32 in [0, 1]

    @classmethod
    def draw(cls, rng: np.random.Generator, size: tuple[int, int]) -> SeeThrough:
        """A see-through for an image of ``size`` (H, W), drawn from ``rng`` in a fixed order."""
        h, w = size
        dy = round(rng.uniform(*THROUGH_UP) * h)
        dx = round(rng.uniform(-THROUGH_SIDE, THROUGH_SIDE) * w)
        tint = float(rng.uniform(*THROUGH_TINT))
        top = rng.uniform(*THROUGH_ALPHA)
        cells = rng.standard_normal((h // THROUGH_CELL + 1, w // THROUGH_CELL + 1))
        alpha = (top / (1.0 + np.exp(-2.0 * cells))).astype(np.float32)
        return cls((dy, dx), tint, alpha)

    def apply(self, img: torch.Tensor) -> torch.Tensor:
        """The whole image ``[3, H, W]`` in [0, 1] with the shifted scene blended in (the caller keeps
        it on objects only)."""
        h, w = img.shape[-2:]
        alpha = _field(self.alpha, h, w, img.dtype)
        shown = torch.roll(img, shifts=self.shift, dims=(-2, -1)) * self.tint
        return img * (1.0 - alpha) + shown * alpha


Look = TypeVar("Look", bound="Drawable")


class Drawable(Protocol):
    """A sample's look, drawn for an image size from a generator in a fixed order."""

    @classmethod
    def draw(cls, rng: np.random.Generator, size: tuple[int, int]) -> Self: ...


def draw_share(kind: type[Look], rng: np.random.Generator, share: float, size: tuple[int, int]) -> Look | None:
    """With probability ``share`` a ``kind`` drawn for ``size``, else None; draws nothing when ``share``
    is 0, so the rest of an augmentation stream is the same as without it."""
    if share <= 0.0:
        return None
    hit = rng.random() < share
    return kind.draw(rng, size) if hit else None


def draw_repaint(rng: np.random.Generator, share: float, size: tuple[int, int]) -> Repaint | None:
    """With probability ``share`` a :class:`Repaint`, else None; draws nothing when ``share`` is 0."""
    return draw_share(Repaint, rng, share, size)


def draw_see_through(rng: np.random.Generator, share: float, size: tuple[int, int]) -> SeeThrough | None:
    """With probability ``share`` a :class:`SeeThrough`, else None; draws nothing when ``share`` is 0."""
    return draw_share(SeeThrough, rng, share, size)


def _on_objects(rgb: torch.Tensor, semantic: torch.Tensor, looks: Sequence[Repaint | SeeThrough | None],
                what: str) -> torch.Tensor:
    if len(looks) != rgb.shape[0]:
        raise ValueError(f"{len(looks)} {what} for a batch of {rgb.shape[0]}")
    out = rgb.clone()
    ids = torch.tensor(sm.ROAD_USERS, device=semantic.device)
    for r, look in enumerate(looks):
        if look is None:
            continue
        obj = torch.isin(semantic[r], ids)
        if bool(obj.any()):
            out[r] = torch.where(obj[None], look.apply(rgb[r]), rgb[r])
    return out


def repaint(rgb: torch.Tensor, semantic: torch.Tensor, paints: Sequence[Repaint | None]) -> torch.Tensor:
    """``rgb`` ``[B, 3, H, W]`` in [0, 1] with the vehicle and person pixels of ``semantic`` ``[B, H, W]``
    (trainIds) repainted by ``paints`` (one per sample, None: as it is). Returns a new tensor."""
    return _on_objects(rgb, semantic, paints, "repaints")


def see_through(rgb: torch.Tensor, semantic: torch.Tensor, throughs: Sequence[SeeThrough | None]) -> torch.Tensor:
    """``rgb`` ``[B, 3, H, W]`` in [0, 1] with the scene from elsewhere in each frame blended into the
    vehicle and person pixels of ``semantic`` ``[B, H, W]`` by ``throughs`` (one per sample, None: as
    it is). Returns a new tensor."""
    return _on_objects(rgb, semantic, throughs, "see-throughs")
