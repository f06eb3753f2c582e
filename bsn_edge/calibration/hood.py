"""The car's own hood across the bottom of the picture, found from a few seconds of driving.

A dashcam mounted low sees the hood: a region at the bottom that moves with the camera, so it
does not change while the road does. Per column, the hood is the run of rows at the bottom whose
grey level barely changes over the frames (temporal spread under a share of the road's own, above
it), ending at an edge: the hood's outline, which the mean picture shows as a step in brightness or
the spread as a line (the outline shakes with the car). Untextured asphalt can be as steady as the
hood, so one column proves nothing: the hood is taken to be there only when most columns agree on
one smooth arch (a quadratic across the picture, fitted robustly), and the columns' scatter about it
is its uncertainty. Measured on synthetic clips with painted hoods and on real clips without one
(``tests/calibration/test_hood.py``); a real hood that mirrors the scenery can go unfound (the
estimate then says none, and nothing is masked).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np

from bsn_edge.fields import number


@dataclass(frozen=True)
class HoodConfig:
    """How the hood is looked for.

    work_width:    frames are looked at about this wide (grey, area-shrunk)
    max_share:     the hood covers at most this share of the rows (the search stops there)
    steady_grey:   a pixel is steady when its temporal spread (standard deviation, grey levels) is
                   under this ...
    steady_share:  ... and under this share of the median spread of the road (rows ``road_band``,
                   shares of the height)
    min_step:      the outline: mean brightness across it differs by this much (grey levels), or the
                   spread on it is ``outline_spread`` times ``steady_grey``
    min_columns:   share of columns that must agree on the arch for a hood to be reported
    fit_px:        a column agrees when its outline lies within this of the arch (work pixels)
    min_frames:    frames needed before anything is said
    frames:        frames a :class:`HoodFinder` takes (about 3 s at online calibration's rate)
    """

    work_width: int = 320
    max_share: float = 0.35
    steady_grey: float = 4.0
    steady_share: float = 0.35
    road_band: tuple[float, float] = (0.6, 0.8)
    min_step: float = 6.0
    outline_spread: float = 3.0
    min_columns: float = 0.6
    fit_px: float = 2.5
    min_frames: int = 20
    frames: int = 40

    def __post_init__(self) -> None:
        if self.work_width < 64 or not 0 < self.max_share < 1 or not 0 < self.min_columns <= 1:
            raise ValueError("work_width must be >= 64, max_share in (0, 1) and min_columns in (0, 1]")
        if not 2 <= self.min_frames <= self.frames:
            raise ValueError(f"min_frames must be >= 2 and at most frames, got {self.min_frames}, {self.frames}")


@dataclass(frozen=True)
class Hood:
    """The hood found (or not) in frames of one camera.

    share:     share of the rows the hood covers at the centre column (0: no hood found)
    spread:    robust scatter (1.4826 MAD) of the columns' outlines about the arch, share of rows:
               the estimate's uncertainty
    columns:   share of the columns that agree on the arch
    arch:      the outline's row as a share of the height, ``a + b x + c x^2`` with ``x`` from -1 (left
               edge) to 1 (right edge); empty when none was found
    frames:    frames looked at
    """

    share: float
    spread: float
    columns: float
    arch: tuple[float, ...]
    frames: int

    @property
    def found(self) -> bool:
        return self.share > 0

    def mask(self, width: int, height: int) -> np.ndarray:
        """``[height, width]`` bool: True on the hood (all False when none was found)."""
        if not self.found:
            return np.zeros((height, width), bool)
        x = (np.arange(width) + 0.5 - width / 2.0) / (width / 2.0)
        top = np.polyval(self.arch, x) * height
        return np.arange(height)[:, None] + 0.5 >= top[None, :]

    def describe(self) -> str:
        """In words, for a person: how much of the picture the hood takes and how sure that is."""
        if not self.found:
            return f"none found in {self.frames} frames (nothing masked)"
        return (f"{100 * self.share:.1f} % of the rows at the centre (+- {100 * self.spread:.1f} %, "
                f"{100 * self.columns:.0f} % of the columns agree), masked")

    def to_dict(self) -> dict[str, object]:
        return {"share": round(self.share, 4), "spread": round(self.spread, 4), "columns": round(self.columns, 3),
                "arch": [round(a, 6) for a in self.arch], "frames": self.frames}

    @classmethod
    def none(cls, frames: int = 0, columns: float = 0.0) -> Hood:
        return cls(0.0, 0.0, columns, (), frames)

    @classmethod
    def from_dict(cls, d: Mapping[str, Any], where: str = "hood") -> Hood:
        """As :meth:`to_dict` wrote it; ``ValueError`` naming ``where`` and the field otherwise."""
        share, spread, columns = (number(d, k, where) for k in ("share", "spread", "columns"))
        arch = d.get("arch", [])
        if not (isinstance(arch, list) and len(arch) in (0, 3) and all(isinstance(a, int | float) for a in arch)):
            raise ValueError(f"{where}: arch must be three numbers (or none), got {arch!r}")
        if not (0 <= share < 1 and spread >= 0 and 0 <= columns <= 1) or (share > 0) != bool(arch):
            raise ValueError(f"{where}: share in [0, 1) with an arch when above 0, spread >= 0, columns in [0, 1]")
        return cls(share, spread, columns, tuple(float(a) for a in arch), int(number(d, "frames", where, int)))


class HoodFinder:
    """Frames fed one at a time (each shrunk to grey at once, so little is kept); :meth:`result` once
    :attr:`ready`. ``find_hood`` over a list does the same."""

    def __init__(self, cfg: HoodConfig | None = None) -> None:
        self.cfg = cfg or HoodConfig()
        self.frames: list[np.ndarray] = []

    @property
    def ready(self) -> bool:
        return len(self.frames) >= self.cfg.frames

    def add(self, frame: np.ndarray) -> None:
        if not self.ready:
            self.frames.append(_grey(frame, self.cfg.work_width))

    def result(self) -> Hood:
        return find_hood(self.frames, self.cfg)


def find_hood(frames: Sequence[np.ndarray], cfg: HoodConfig | None = None) -> Hood:
    """The hood in ``frames`` (BGR or grey, one camera, in order, the car moving); ``Hood.none`` when
    the columns do not agree on one (or there are fewer than ``cfg.min_frames`` frames)."""
    cfg = cfg or HoodConfig()
    if len(frames) < cfg.min_frames:
        return Hood.none(len(frames))
    stack = np.stack([_grey(f, cfg.work_width) for f in frames])
    mean, spread = stack.mean(axis=0), stack.std(axis=0)
    h, w = mean.shape
    top = int(h * (1 - cfg.max_share))
    road = float(np.median(spread[int(h * cfg.road_band[0]):int(h * cfg.road_band[1])]))
    steady = spread < min(cfg.steady_grey, cfg.steady_share * road)
    rows = _outlines(mean, spread, steady, top, cfg).astype(float)
    ok = rows >= 0
    xs = (np.arange(w) + 0.5 - w / 2.0) / (w / 2.0)
    if ok.mean() < cfg.min_columns:
        return Hood.none(len(frames), float(ok.mean()))
    keep = ok
    for _ in range(5):
        arch = np.polyfit(xs[keep], rows[keep], 2)
        keep = ok & (np.abs(np.polyval(arch, xs) - rows) < cfg.fit_px)
        if keep.sum() < 3:
            return Hood.none(len(frames), float(keep.mean()))
    if keep.mean() < cfg.min_columns:
        return Hood.none(len(frames), float(keep.mean()))
    res = rows[keep] - np.polyval(arch, xs[keep])
    mad = 1.4826 * float(np.median(np.abs(res - np.median(res))))
    share = 1.0 - float(np.polyval(arch, 0.0)) / h
    return Hood(share, mad / h, float(keep.mean()), tuple(float(a) / h for a in arch), len(frames))


def _grey(frame: np.ndarray, width: int) -> np.ndarray:
    """Grey float32, area-shrunk to ``width`` (a frame that narrow or narrower is kept at its size)."""
    g = cv2.cvtColor(frame, cv2.COLOR_BGR2GRAY) if frame.ndim == 3 else frame
    if g.shape[1] > width:
        g = cv2.resize(g, (width, max(1, round(g.shape[0] * width / g.shape[1]))), interpolation=cv2.INTER_AREA)
    return g.astype(np.float32)


def _outlines(mean: np.ndarray, spread: np.ndarray, steady: np.ndarray, top: int, cfg: HoodConfig) -> np.ndarray:
    """Per column, the row where its steady run from the bottom ends, if an outline ends it; else -1."""
    h, w = mean.shape
    moving = ~steady[top:][::-1]                    # from the bottom row up to the search's end
    first = np.where(moving.any(axis=0), moving.argmax(axis=0), -1)
    y = h - 1 - first                               # the lowest row that moves: the outline is just below it
    # steady to the search's end (asphalt), or no steady run at all (the bottom row moves)
    ok = (first > 0) & (y >= 3) & (y <= h - 4)
    y = np.clip(y, 3, h - 4)
    cols = np.arange(w)
    above = np.mean([mean[y - k, cols] for k in (1, 2, 3)], axis=0)
    below = np.mean([mean[y + k, cols] for k in (1, 2, 3)], axis=0)
    shakes = np.max([spread[y + k, cols] for k in (-1, 0, 1)], axis=0) > cfg.outline_spread * cfg.steady_grey
    ok &= (np.abs(above - below) >= cfg.min_step) | shakes
    return np.where(ok, y + 1, -1)
