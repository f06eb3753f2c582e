"""What a real camera does to the whole picture: domain randomisation of the sensor and its processing.

The renderer's camera is ideal: neutral white balance, one tone curve, sharp everywhere, no noise. A
dashcam has its own white balance, contrast, colour saturation and tone curve, is soft in focus or
blurred by motion, and is noisy in the dark. A :class:`CameraLook` is one such camera, drawn per
sample and applied to the whole frame after the objects' own looks (:mod:`~bsn_edge.data.repaint`),
as a camera sees the painted scene; depth, semantics and blind spots stay as they are. The dataset
and the sample cache draw and apply it through the same code, so both give the same batches.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import torch
import torch.nn.functional as F

from bsn_edge.data.repaint import draw_share

WHITE_BALANCE = (0.8, 1.25)   # per-channel gain range, about a neutral grey
CONTRAST = (0.6, 1.4)         # scale of the distance from the frame's mean
SATURATION = (0.3, 1.5)       # scale of the distance from the pixel's luma
GAMMA = (0.7, 1.5)            # tone-curve exponent range
BLUR = (0.0, 1.5)             # Gaussian blur's standard deviation, pixels of the training frame
NOISE = (0.0, 0.04)           # additive Gaussian noise's standard deviation, share of full scale
LUMA = (0.299, 0.587, 0.114)  # ITU-R BT.601 weights of R, G, B
SHARP = 0.2                   # a blur under this many pixels is left out (its kernel would be a dot)


@dataclass(frozen=True)
class CameraLook:
    """One sample's camera: white-balance gains (R, G, B), contrast, saturation, tone-curve
    exponent, blur (pixels) and noise (its standard deviation, and the seed of its pattern)."""

    white_balance: tuple[float, float, float]
    contrast: float
    saturation: float
    gamma: float
    blur: float
    noise: float
    noise_seed: int

    @classmethod
    def draw(cls, rng: np.random.Generator, size: tuple[int, int]) -> CameraLook:
        """A camera for an image of ``size`` (H, W; every image gets the same kind of camera), drawn
        from ``rng`` in a fixed order."""
        r, g, b = (float(x) for x in rng.uniform(*WHITE_BALANCE, 3))
        wb = (r, g, b)
        return cls(wb, float(rng.uniform(*CONTRAST)), float(rng.uniform(*SATURATION)), float(rng.uniform(*GAMMA)),
                   float(rng.uniform(*BLUR)), float(rng.uniform(*NOISE)), int(rng.integers(2**31 - 1)))

    def apply(self, img: torch.Tensor) -> torch.Tensor:
        """The image ``[3, H, W]`` in [0, 1] as this camera shows it, in [0, 1]."""
        x = img.clamp(0.0, 1.0) * torch.tensor(self.white_balance, dtype=img.dtype)[:, None, None]
        x = x.clamp_(0.0, 1.0) ** self.gamma
        luma = (x * torch.tensor(LUMA, dtype=img.dtype)[:, None, None]).sum(0, keepdim=True)
        x = luma + self.saturation * (x - luma)
        mean = x.mean()
        x = mean + self.contrast * (x - mean)
        if self.blur >= SHARP:
            x = gaussian_blur(x, self.blur)
        if self.noise > 0.0:
            g = torch.Generator().manual_seed(self.noise_seed)
            x = x + self.noise * torch.randn(x.shape, generator=g, dtype=x.dtype)
        return x.clamp_(0.0, 1.0)


def gaussian_blur(img: torch.Tensor, sigma: float) -> torch.Tensor:
    """``img`` ``[C, H, W]`` blurred by a Gaussian of ``sigma`` pixels (separable, 3 sigma each side,
    edges mirrored)."""
    r = max(1, int(np.ceil(3.0 * sigma)))
    t = torch.arange(-r, r + 1, dtype=img.dtype)
    k = torch.exp(-0.5 * (t / sigma) ** 2)
    k = k / k.sum()
    c = img.shape[0]
    x = F.pad(img[None], (r, r, r, r), mode="reflect")
    x = F.conv2d(x, k.view(1, 1, 1, -1).expand(c, 1, 1, -1), groups=c)
    x = F.conv2d(x, k.view(1, 1, -1, 1).expand(c, 1, -1, 1), groups=c)
    return x[0]


def draw_camera_look(rng: np.random.Generator, share: float, size: tuple[int, int]) -> CameraLook | None:
    """With probability ``share`` a :class:`CameraLook`, else None; draws nothing when ``share`` is 0,
    so the rest of an augmentation stream is the same as without it."""
    return draw_share(CameraLook, rng, share, size)


def camera_look(rgb: torch.Tensor, looks: Sequence[CameraLook | None]) -> torch.Tensor:
    """``rgb`` ``[B, 3, H, W]`` in [0, 1], each sample as its camera in ``looks`` shows it (None: as it
    is). Returns a new tensor."""
    if len(looks) != rgb.shape[0]:
        raise ValueError(f"{len(looks)} camera looks for a batch of {rgb.shape[0]}")
    out = rgb.clone()
    for r, look in enumerate(looks):
        if look is not None:
            out[r] = look.apply(rgb[r])
    return out
