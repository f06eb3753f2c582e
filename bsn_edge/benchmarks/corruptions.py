"""A camera that fails, made from real footage: what ``bench_camera_health`` injects and the tests reuse.

Each corruption takes a BGR frame, its severity (1 mild to 5 strongest; ImageNet-C's scale where it has one:
Hendrycks and Dietterich, 2019) and a random generator, and returns the frame the failed camera would give.
Frozen is not a picture but a sequence: the frame at the failure repeated (:func:`frozen`).
"""

from __future__ import annotations

from collections.abc import Callable

import cv2
import numpy as np

Corruption = Callable[[np.ndarray, int, np.random.Generator], np.ndarray]
SEVERITIES = (1, 2, 3, 4, 5)
SIDES = ("left", "centre", "right")
COVER_SHARES = (0.1, 0.25, 0.5, 0.75, 1.0)     # of the picture's width, full height: severity 1 to 5
MUD_BGR = (38, 52, 66)                          # a brown, dull cover


def _u8(x: np.ndarray) -> np.ndarray:
    return np.clip(x, 0, 255).astype(np.uint8)


def fog(frame: np.ndarray, severity: int, rng: np.random.Generator) -> np.ndarray:
    """A bright haze over the picture, thicker towards the horizon (ImageNet-C's fog, made with a blend)."""
    a = (0.35, 0.5, 0.65, 0.8, 0.9)[severity - 1]
    h = frame.shape[0]
    thick = a * (0.75 + 0.25 * np.cos(np.linspace(0, np.pi, h)))[:, None, None]
    return _u8(frame * (1 - thick) + 205 * thick)


def noise(frame: np.ndarray, severity: int, rng: np.random.Generator) -> np.ndarray:
    """Gaussian noise, ImageNet-C's standard deviations (0.08 to 0.38 of full scale)."""
    sigma = 255 * (0.08, 0.12, 0.18, 0.26, 0.38)[severity - 1]
    return _u8(frame + rng.normal(0, sigma, frame.shape))


def blur(frame: np.ndarray, severity: int, rng: np.random.Generator) -> np.ndarray:
    """A defocused or smeared lens: Gaussian blur, its sigma a share of the picture's width."""
    sigma = frame.shape[1] * (0.002, 0.004, 0.007, 0.011, 0.016)[severity - 1]
    return cv2.GaussianBlur(frame, (0, 0), sigma)


def brightness(frame: np.ndarray, severity: int, rng: np.random.Generator) -> np.ndarray:
    """ImageNet-C's brightness: the value channel raised by 0.1 to 0.5 of full scale."""
    hsv = cv2.cvtColor(frame, cv2.COLOR_BGR2HSV).astype(np.float32)
    hsv[..., 2] += 255 * (0.1, 0.2, 0.3, 0.4, 0.5)[severity - 1]
    return cv2.cvtColor(_u8(hsv), cv2.COLOR_HSV2BGR)


def contrast(frame: np.ndarray, severity: int, rng: np.random.Generator) -> np.ndarray:
    """ImageNet-C's contrast: the picture pulled towards its mean, to 0.4 to 0.05 of its spread."""
    c = (0.4, 0.3, 0.2, 0.1, 0.05)[severity - 1]
    mean = frame.mean(axis=(0, 1), keepdims=True)
    return _u8((frame - mean) * c + mean)


def cover(side: str) -> Corruption:
    """Mud or a sticker over the lens on ``side``: a dull uniform cover, full height, over
    :data:`COVER_SHARES` of the width (the centre's grows both ways from the middle)."""
    if side not in SIDES:
        raise ValueError(f"side must be one of {SIDES}, got {side!r}")

    def covered(frame: np.ndarray, severity: int, rng: np.random.Generator) -> np.ndarray:
        out = frame.copy()
        w = frame.shape[1]
        n = round(w * COVER_SHARES[severity - 1])
        x0 = {"left": 0, "right": w - n, "centre": (w - n) // 2}[side]
        out[:, x0:x0 + n] = MUD_BGR
        return out

    return covered


def glare(frame: np.ndarray, severity: int, rng: np.random.Generator) -> np.ndarray:
    """The sun in the lens: a saturated disc with a soft rim, its radius 0.1 to 0.5 of the width, in the
    upper middle of the picture."""
    h, w = frame.shape[:2]
    r = w * (0.1, 0.2, 0.3, 0.4, 0.5)[severity - 1]
    yy, xx = np.mgrid[0:h, 0:w]
    d = np.hypot(xx - 0.5 * w, yy - 0.35 * h)
    a = np.clip((1.25 * r - d) / (0.25 * r), 0, 1)[..., None]
    return _u8(frame * (1 - a) + 255 * a)


def flat(level: int) -> Corruption:
    """A picture of one grey level: black (0), grey (128) or white (255): a dead sensor, a cap, a white-out."""
    def one(frame: np.ndarray, severity: int, rng: np.random.Generator) -> np.ndarray:
        return np.full_like(frame, level)

    return one


def pure_noise(frame: np.ndarray, severity: int, rng: np.random.Generator) -> np.ndarray:
    """A broken link: noise and nothing of the scene."""
    return rng.integers(0, 256, frame.shape, dtype=np.uint8)


def sensor_noise(frame: np.ndarray, rng: np.random.Generator, sigma: float = 2.0) -> np.ndarray:
    """A real sensor's frame-to-frame noise (about 2 grey levels): what a standing car's frames differ by."""
    return _u8(frame + rng.normal(0, sigma, frame.shape))


CORRUPTIONS: dict[str, Corruption] = {
    "fog": fog, "noise": noise, "blur": blur, "brightness": brightness, "contrast": contrast,
    **{f"cover_{s}": cover(s) for s in SIDES}, "glare": glare,
    "black": flat(0), "grey": flat(128), "white": flat(255), "pure_noise": pure_noise}
# one severity only: a flat picture or pure noise is as bad as it gets
ONE_SEVERITY = ("black", "grey", "white", "pure_noise")
