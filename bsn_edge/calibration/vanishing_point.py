"""Pitch and yaw from one picture: the vanishing point of the road's lines.

Lane markings, kerbs and the edges of the buildings along a straight road are parallel to the
car's direction of travel, so in the picture they meet at one point: where that direction is seen.
It is the focus of expansion online calibration waits for (:mod:`bsn_edge.calibration.mount_fit`),
found from a single frame, so it serves a still and the first seconds of a drive. Lines are taken
from the lower part of the picture (edges, then a probabilistic Hough transform), those leaning
neither flat nor upright; the point is the one that most of their length points at (each
crossing of a left- and a right-leaning line, each line counted when its direction passes within a
small angle of the point), refined by least squares on those lines. It is reported only when lines
on both sides of the point (leaning left and leaning right) agree on it: one kerb, or a building's
facade alone, says nothing. A curve, or a picture taken across the road, gives a wrong point, so this is a
first guess that online calibration replaces.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from bsn_edge.camera import Intrinsics
from bsn_edge.mounting import Mounting


@dataclass(frozen=True)
class VanishingConfig:
    """How the vanishing point is looked for.

    work_width:  pictures are looked at this wide (grey, area-shrunk)
    band:        rows searched, shares of the height from the top (the road and what lines it)
    min_length:  lines shorter than this share of the width are left out
    lean_deg:    lines leaning between these angles from the horizontal are kept
    tol_deg:     a line points at a point when its direction passes within this angle of it
    min_side:    each side (left-leaning, right-leaning lines) must put this share of the width
                 of line length on the point, in at least ``min_lines`` lines
    max_lines:   the longest lines of each side whose crossings are tried
    """

    work_width: int = 480
    band: tuple[float, float] = (0.35, 0.95)
    min_length: float = 0.05
    lean_deg: tuple[float, float] = (12.0, 78.0)
    tol_deg: float = 1.0
    min_side: float = 0.25
    min_lines: int = 2
    max_lines: int = 24

    def __post_init__(self) -> None:
        if self.work_width < 64 or not 0 <= self.band[0] < self.band[1] <= 1:
            raise ValueError("work_width must be >= 64 and band two shares 0 <= top < bottom <= 1")
        if not 0 < self.lean_deg[0] < self.lean_deg[1] < 90 or self.tol_deg <= 0 or self.max_lines < 1:
            raise ValueError("lean_deg must be 0 < low < high < 90, tol_deg positive, max_lines >= 1")


@dataclass(frozen=True)
class VanishingPoint:
    """Where the road's lines meet, in the picture's pixels (None: no point both sides agree on).

    lines:   lines that point at it (left-leaning, right-leaning)
    spread:  robust scatter (1.4826 MAD) of those lines' distances from it, pixels
    """

    point: tuple[float, float] | None
    lines: tuple[int, int]
    spread: float

    @property
    def found(self) -> bool:
        return self.point is not None

    def mounting(self, intrinsics: Intrinsics, height_m: float, roll_deg: float = 0.0,
                 dist: tuple[float, ...] = ()) -> Mounting | None:
        """Pitch and yaw that put the car's forward axis at the point (the picture's own
        ``intrinsics`` and lens distortion ``dist``); None when none was found or it is off every
        mounting (beyond ``ANGLE_LIMIT_DEG``)."""
        if self.point is None:
            return None
        if any(dist):
            n = cv2.undistortPoints(np.array([[self.point]], np.float64), intrinsics.K, np.array(dist, np.float64))
            ray = np.array([n[0, 0, 0], n[0, 0, 1], 1.0])
        else:
            u, v = self.point
            ray = np.array([(u - intrinsics.cx) / intrinsics.fx, (v - intrinsics.cy) / intrinsics.fy, 1.0])
        if not np.isfinite(ray).all():
            return None
        try:
            return Mounting.from_forward(ray, height_m, roll_deg)
        except ValueError:          # beyond every mounting (ANGLE_LIMIT_DEG): lines that are not the road's
            return None


class VanishingGuess:
    """The first guess of pitch and yaw while online calibration has none: the median over the
    first ``frames`` frames whose vanishing point was found (:func:`find_vanishing_point`), looked
    for in at most ``looks`` frames, used only once it knows: at least ``agree`` frames found and their
    pitches and yaws each within ``max_spread_deg`` (1.4826 x their median absolute deviation) of
    one another. Frames of one camera on a straight road agree within a degree (rendered cameras
    0.1-0.6, the real highway, Udacity and mountain clips 0.2-1.3); city streets seen a second apart,
    or photos from different cars, scatter by 4-12 degrees of yaw, and a guess from them is worse
    than none (``benchmarks/results/camvid.md``). Not thread-safe: its owner serialises :meth:`record`."""

    def __init__(self, frames: int = 9, looks: int = 60, cfg: VanishingConfig | None = None, agree: int = 5,
                 max_spread_deg: float = 1.5) -> None:
        if not 1 <= agree <= frames <= looks:
            raise ValueError(f"need 1 <= agree <= frames <= looks, got {agree}, {frames} and {looks}")
        if not max_spread_deg > 0:
            raise ValueError(f"max_spread_deg must be positive, got {max_spread_deg}")
        self.frames, self.looks, self.cfg = frames, looks, cfg or VanishingConfig()
        self.agree, self.max_spread_deg = agree, max_spread_deg
        self.found: list[tuple[float, float]] = []       # (pitch, yaw) in degrees
        self.looked = 0

    @property
    def done(self) -> bool:
        return len(self.found) >= self.frames or self.looked >= self.looks

    def look(self, frame: np.ndarray, intrinsics: Intrinsics,
             dist: tuple[float, ...] = ()) -> tuple[float, float] | None:
        """Pitch and yaw from this frame (``intrinsics``: at its size), or None. It changes nothing
        (:meth:`record` does), so the work can run outside the owner's lock."""
        m = find_vanishing_point(frame, self.cfg).mounting(intrinsics, 1.0, 0.0, dist)
        return None if m is None else (m.pitch_deg, m.yaw_deg)

    def record(self, pitch_yaw: tuple[float, float] | None) -> None:
        """Count a look, and keep what it found."""
        self.looked += 1
        if pitch_yaw is not None and len(self.found) < self.frames:
            self.found.append(pitch_yaw)

    @property
    def spread_deg(self) -> tuple[float, float] | None:
        """How far the frames found disagree: 1.4826 x the median absolute deviation of their pitches
        and of their yaws (None before two are found)."""
        if len(self.found) < 2:
            return None
        a = np.array(self.found)
        mad = np.median(np.abs(a - np.median(a, axis=0)), axis=0)
        return float(1.4826 * mad[0]), float(1.4826 * mad[1])

    @property
    def agreed(self) -> bool:
        """Whether enough frames were found and agree to be used."""
        spread = self.spread_deg
        return len(self.found) >= self.agree and spread is not None and max(spread) <= self.max_spread_deg

    def mounting(self, height_m: float, roll_deg: float = 0.0) -> Mounting | None:
        """The median pitch and yaw of the frames found, once they agree (:attr:`agreed`); else None."""
        if not self.agreed:
            return None
        pitch, yaw = np.median(np.array(self.found), axis=0)
        return Mounting(height_m, float(pitch), float(yaw), roll_deg)

    def provisional(self, assumed: Mounting) -> Mounting | None:
        """The pose to warp with from the first frame whose vanishing point is found, ``assumed`` (the
        model camera's pose) filling in: the agreed guess (:meth:`mounting`) once there is one; before that,
        while the looking goes on, each angle's median over the frames found so far as long as that angle's
        own spread is within ``max_spread_deg`` (the assumed angle where it is not). None when nothing is
        found, when neither angle agrees, or once the looks ran out without agreeing.

        Measured on the real clips' first 9 frames found: pitch spreads 0.1-2.1 degrees (a city drive a
        second apart included), yaw up to 6 on a highway's first frames and 5-12 in a city. Pitch is what
        moves the horizon the model reads the road by: warped at the model camera's pitch, the real highway
        clip's camera (3 degrees down) has its distant road edge taken for blind spots in every sector,
        where its first frame's pitch (0.2 degrees from the converged one) shows none."""
        if self.agreed:
            return self.mounting(assumed.height_m, assumed.roll_deg)
        if not self.found or self.done:
            return None
        medians = np.median(np.array(self.found), axis=0)
        spread = self.spread_deg or (0.0, 0.0)
        use = [s <= self.max_spread_deg for s in spread]
        if not any(use):
            return None
        pitch = float(medians[0]) if use[0] else assumed.pitch_deg
        yaw = float(medians[1]) if use[1] else assumed.yaw_deg
        return Mounting(assumed.height_m, pitch, yaw, assumed.roll_deg)

    def state(self) -> str:
        """What the guess is, in words: used, used provisionally, waiting for frames, or refused."""
        spread = self.spread_deg
        if self.agreed:
            return "used"
        if self.found and not self.done and (spread is None or min(spread) <= self.max_spread_deg):
            return f"used provisionally: {len(self.found)} frames found, {self.agree} agreeing needed"
        if spread is not None and max(spread) > self.max_spread_deg:
            return f"not used: the frames disagree by {max(spread):.1f} deg (at most {self.max_spread_deg:g})"
        if self.done:
            return f"not used: {len(self.found)} frames found, {self.agree} needed"
        return f"not used yet: {len(self.found)} of the {self.agree} frames it needs"

    def to_dict(self) -> dict[str, object]:
        m = self.mounting(1.0)
        spread = self.spread_deg
        return {"method": "vanishing point of the road's lines", "frames_found": len(self.found),
                "frames_looked": self.looked, "used": m is not None, "state": self.state(),
                "spread_deg": None if spread is None else [round(spread[0], 2), round(spread[1], 2)],
                "pitch_deg": None if m is None else round(m.pitch_deg, 3),
                "yaw_deg": None if m is None else round(m.yaw_deg, 3)}


def find_vanishing_point(frame: np.ndarray, cfg: VanishingConfig | None = None) -> VanishingPoint:
    """The vanishing point of the road's lines in ``frame`` (BGR or grey)."""
    cfg = cfg or VanishingConfig()
    grey = cv2.cvtColor(frame, cv2.COLOR_BGR2GRAY) if frame.ndim == 3 else frame
    scale = min(1.0, cfg.work_width / grey.shape[1])
    if scale < 1.0:
        grey = cv2.resize(grey, (cfg.work_width, max(1, round(grey.shape[0] * scale))), interpolation=cv2.INTER_AREA)
    segs = _segments(grey, cfg)
    none = VanishingPoint(None, (0, 0), 0.0)
    if len(segs) < 2:
        return none
    mid = (segs[:, :2] + segs[:, 2:]) / 2
    d = segs[:, 2:] - segs[:, :2]
    length = np.hypot(d[:, 0], d[:, 1])
    d = d / length[:, None]
    left = d[:, 0] * d[:, 1] < 0          # rows grow downwards: a line rising to the right leans right
    longest = np.argsort(-length)
    li = [i for i in longest if left[i]][:cfg.max_lines]
    ri = [i for i in longest if not left[i]][:cfg.max_lines]
    points = _crossings(segs[li], segs[ri])
    if len(points) == 0:
        return none
    # every crossing of a left- and a right-leaning line, scored by the line length pointing at it
    # on its weaker side
    on = _pointing(points, mid, d, cfg.tol_deg)
    w = np.minimum((on * (length * left)).sum(axis=1), (on * (length * ~left)).sum(axis=1))
    best = points[int(np.argmax(w))]
    on = _pointing(best, mid, d, cfg.tol_deg)
    best = _least_squares(mid[on], d[on], length[on])
    on = _pointing(best, mid, d, cfg.tol_deg)
    sides = (int((on & left).sum()), int((on & ~left).sum()))
    need = cfg.min_side * grey.shape[1]
    if min(sides) < cfg.min_lines or length[on & left].sum() < need or length[on & ~left].sum() < need:
        return VanishingPoint(None, sides, 0.0)
    dist = np.abs((best[0] - mid[on, 0]) * d[on, 1] - (best[1] - mid[on, 1]) * d[on, 0])
    spread = 1.4826 * float(np.median(np.abs(dist - np.median(dist)))) / scale
    return VanishingPoint((float(best[0]) / scale, float(best[1]) / scale), sides, spread)


def _segments(grey: np.ndarray, cfg: VanishingConfig) -> np.ndarray:
    """``[N, 4]`` line segments (x0, y0, x1, y1) in the band, leaning as ``cfg.lean_deg`` says."""
    h, w = grey.shape
    top, bottom = int(h * cfg.band[0]), int(h * cfg.band[1])
    edges = cv2.Canny(cv2.GaussianBlur(grey, (3, 3), 0), 60, 160)
    edges[:top], edges[bottom:] = 0, 0
    min_len = max(8, int(cfg.min_length * w))
    found = cv2.HoughLinesP(edges, 1, np.pi / 360, threshold=max(10, min_len // 2), minLineLength=min_len,
                            maxLineGap=max(2, min_len // 4))
    if found is None:
        return np.zeros((0, 4))
    segs = found.reshape(-1, 4).astype(np.float64)
    lean = np.degrees(np.arctan2(np.abs(segs[:, 3] - segs[:, 1]), np.abs(segs[:, 2] - segs[:, 0])))
    return segs[(lean >= cfg.lean_deg[0]) & (lean <= cfg.lean_deg[1])]


def _crossings(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``[K, 2]``: where the line through each segment of ``a`` crosses the line through each of ``b``
    (parallel pairs left out)."""
    def lines(s: np.ndarray) -> np.ndarray:
        one = np.ones((len(s), 1))
        return np.cross(np.hstack([s[:, :2], one]), np.hstack([s[:, 2:], one]))

    x = np.cross(lines(a)[:, None, :], lines(b)[None, :, :]).reshape(-1, 3)
    x = x[np.abs(x[:, 2]) > 1e-9]
    return x[:, :2] / x[:, 2:]


def _pointing(p: np.ndarray, mid: np.ndarray, d: np.ndarray, tol_deg: float) -> np.ndarray:
    """Whether the line of each segment (midpoints ``mid``, unit directions ``d``) passes within
    ``tol_deg`` of ``p``: ``[N]`` for one point, ``[K, N]`` for ``[K, 2]`` points."""
    to = p[..., None, :] - mid
    far = np.hypot(to[..., 0], to[..., 1])
    sin = np.abs(to[..., 0] * d[:, 1] - to[..., 1] * d[:, 0]) / np.maximum(far, 1e-9)
    return sin < math.sin(math.radians(tol_deg))


def _least_squares(mid: np.ndarray, d: np.ndarray, weight: np.ndarray) -> np.ndarray:
    """The point nearest to the lines (through ``mid`` along ``d``), weighted by ``weight``."""
    n = np.stack([d[:, 1], -d[:, 0]], axis=1)            # unit normals
    a = (n * weight[:, None]).T @ n
    b = (n * weight[:, None]).T @ (n * mid).sum(axis=1)
    return np.linalg.solve(a, b)
