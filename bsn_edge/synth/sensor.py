"""What a real dashcam does to the light that reaches it: one clip's sensor and its effects.

Applied after rendering (and after the lens), in the order a camera applies them: exposure
and white balance, vignetting, motion blur from the car's own speed (a zoom blur about the
focus of expansion), defocus, the tone curve (gamma), noise (read noise plus shot noise that
grows with the signal), quantization to 8 bits and, on most clips, JPEG compression. None of
it touches depth, semantics or blind spots.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import cv2
import numpy as np

NOISE_PAD = 97        # each frame reads a window of a larger noise tile at its own offset
BLUR_TAPS = 4         # zoom-blur samples


@dataclass(frozen=True)
class Sensor:
    """One clip's camera response (all effects off at the defaults except plain 8-bit output)."""

    exposure: float = 1.0                 # gain on the scene's radiance
    white_balance: tuple[float, float, float] = (1.0, 1.0, 1.0)   # BGR gains
    gamma: float = 1.0                    # output = input ** (1 / gamma)
    vignette: float = 0.0                 # light lost in the corners, share
    shutter_s: float = 0.0                # exposure time, for motion blur
    defocus_px: float = 0.0               # Gaussian sigma, pixels
    read_noise: float = 0.0               # sigma, 8-bit levels
    shot_noise: float = 0.0               # sigma at full scale, 8-bit levels (scales with sqrt(signal))
    jpeg_quality: int = 0                 # 0 = no compression

    def __post_init__(self) -> None:
        if not 0.05 <= self.exposure <= 10:
            raise ValueError(f"exposure must be in [0.05, 10], got {self.exposure}")
        if not 0.3 <= self.gamma <= 3:
            raise ValueError(f"gamma must be in [0.3, 3], got {self.gamma}")
        if not 0 <= self.vignette < 1:
            raise ValueError(f"vignette must be in [0, 1), got {self.vignette}")
        if self.jpeg_quality and not 5 <= self.jpeg_quality <= 100:
            raise ValueError(f"jpeg_quality must be 0 (off) or in [5, 100], got {self.jpeg_quality}")
        if min(self.shutter_s, self.defocus_px, self.read_noise, self.shot_noise) < 0:
            raise ValueError("shutter, defocus and noise must be >= 0")

    @classmethod
    def draw(cls, rng: np.random.Generator, dark: bool = False) -> Sensor:
        """A random dashcam; ``dark`` scenes get longer shutters, more gain and more noise."""
        wb = rng.uniform(0.9, 1.1, 3)
        r, g, b = (float(v) for v in wb / wb.mean())
        return cls(
            exposure=float(rng.uniform(2.2, 4.0) if dark else rng.uniform(0.8, 1.25)),
            white_balance=(r, g, b),
            gamma=float(rng.uniform(0.85, 1.25)),
            vignette=float(rng.uniform(0.0, 0.35)),
            shutter_s=float(rng.uniform(1 / 60, 1 / 25) if dark else rng.uniform(1 / 1000, 1 / 120)),
            defocus_px=float(rng.uniform(0.0, 0.9)) if rng.random() < 0.5 else 0.0,
            read_noise=float(rng.uniform(2.0, 5.0) if dark else rng.uniform(0.5, 2.5)),
            shot_noise=float(rng.uniform(1.0, 4.0)),
            jpeg_quality=int(rng.integers(35, 92)) if rng.random() < 0.75 else 0,
        )

    def to_dict(self) -> dict:
        return asdict(self)


class SensorModel:
    """Applies a :class:`Sensor` to frames of one size; ``foe`` is the focus of expansion in pixels
    (where straight-ahead motion comes from) and ``focal_px`` the focal length."""

    def __init__(self, sensor: Sensor, width: int, height: int, foe: tuple[float, float], focal_px: float,
                 seed: int = 0) -> None:
        self.sensor, self.w, self.h = sensor, width, height
        self.foe, self.focal = (float(foe[0]), float(foe[1])), float(focal_px)
        yy, xx = np.mgrid[0:height, 0:width].astype(np.float32)
        r2 = ((xx - width / 2) / (width / 2)) ** 2 + ((yy - height / 2) / (height / 2)) ** 2
        gain = (1.0 - sensor.vignette * r2 / 2)[..., None] * np.asarray(sensor.white_balance, np.float32)
        self.gain = (gain * np.float32(sensor.exposure)).astype(np.float32)
        rng = np.random.default_rng([seed, 0x6E6F6973])
        # fresh-looking noise without drawing it every frame: noise that stood still in the image
        # would give a feature tracker corners that never move
        self.noise = rng.standard_normal((height + NOISE_PAD, width + NOISE_PAD, 3)).astype(np.float32)

    def _zoom_blur(self, img: np.ndarray, speed_mps: float) -> np.ndarray:
        # A point at depth Z moves in the image by (r / Z) * v * t; at a reference depth of 8 m
        # that is the scale change of the whole frame during the exposure.
        scale = speed_mps * self.sensor.shutter_s / 8.0
        if scale * max(self.w, self.h) / 2 < 0.5:
            return img
        acc = img.copy()
        u0, v0 = self.foe
        for k in range(1, BLUR_TAPS):
            s = 1.0 + scale * k / (BLUR_TAPS - 1)
            m = np.array([[s, 0, u0 * (1 - s)], [0, s, v0 * (1 - s)]], np.float32)
            acc += cv2.warpAffine(img, m, (self.w, self.h), flags=cv2.INTER_LINEAR,
                                  borderMode=cv2.BORDER_REPLICATE)
        return acc / np.float32(BLUR_TAPS)

    def develop(self, radiance: np.ndarray, frame_index: int = 0, speed_mps: float = 0.0) -> np.ndarray:
        """Scene radiance ``[H, W, 3]`` float (1.0 = white at exposure 1) -> BGR uint8."""
        s = self.sensor
        img = radiance * self.gain
        if s.shutter_s > 0 and speed_mps > 0:
            img = self._zoom_blur(img, speed_mps)
        if s.defocus_px > 0.05:
            img = cv2.GaussianBlur(img, (0, 0), s.defocus_px)
        lin = np.clip(img, 0.0, 1.0)
        out = lin ** np.float32(1.0 / s.gamma) * np.float32(255.0) if s.gamma != 1.0 else lin * np.float32(255.0)
        if s.read_noise > 0 or s.shot_noise > 0:
            dy, dx = (frame_index * 37) % NOISE_PAD, (frame_index * 61 + 13) % NOISE_PAD
            sigma = np.float32(s.read_noise) + np.float32(s.shot_noise) * np.sqrt(lin)
            out += self.noise[dy:dy + self.h, dx:dx + self.w] * sigma
        u8 = np.clip(out + 0.5, 0, 255).astype(np.uint8)
        if s.jpeg_quality:
            ok, buf = cv2.imencode(".jpg", u8, [cv2.IMWRITE_JPEG_QUALITY, s.jpeg_quality])
            if not ok:
                raise RuntimeError("OpenCV could not JPEG-encode a frame")
            u8 = cv2.imdecode(buf, cv2.IMREAD_COLOR)
        return u8
