"""The car's own hood across the bottom of the picture, found from a few seconds of driving.

A dashcam mounted low sees the hood: a region at the bottom that moves with the camera, so it
does not change while the road does. Per column, the hood is the run of rows at the bottom whose
grey level barely changes over the frames (temporal spread under a share of the road's own, above
it), ending at an edge: the hood's outline, which the mean picture shows as a step in brightness or
the spread as a line (the outline shakes with the car). A column whose bottom row moves shows no
hood: the outline passes below the picture there (a hood seen in one corner only, as a wide lens
mounted to one side sees it). Untextured asphalt can be as steady as the hood, so one column proves
nothing: the hood is taken to be there only when most columns agree on one smooth arch (a quadratic
across the picture, fitted robustly; a column without hood agrees when the arch passes below the
picture there) and enough of them show it; the scatter of the outlines about it is its uncertainty.
Measured on synthetic clips with painted hoods, on a corner hood painted on a clip without one, on
real clips without one and on a real corner hood (``tests/calibration/test_hood.py``).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np

from bsn_edge.fields import number

EDGE_ROWS = 3   # an outline is told from the mean picture 3 rows either side of it
# a camera file's hood may mask at most this share of the picture, judged on the mask its arch draws: a
# hood over more would leave the model too little road to see, and blind the run while it says OK
MAX_MASKED = 0.35
_JUDGED_AT = (90, 160)    # the grid the drawn mask is judged on (height, width)


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
    min_columns:   share of columns that must agree on the arch for a hood to be reported ...
    min_seen:      ... of which this share of all columns show the hood (not only pass below it)
    fit_px:        a column agrees when its outline lies within this of the arch (work pixels)
    min_frames:    frames needed before anything is said
    frames:        frames a :class:`HoodFinder` takes (about 3 s at online calibration's rate)
    """

    work_width: int = 320
    max_share: float = 0.35
    steady_grey: float = 6.0
    steady_share: float = 0.35
    road_band: tuple[float, float] = (0.6, 0.8)
    min_step: float = 6.0
    outline_spread: float = 3.0
    min_columns: float = 0.6
    min_seen: float = 0.2
    fit_px: float = 2.5
    min_frames: int = 20
    frames: int = 40

    def __post_init__(self) -> None:
        if self.work_width < 64 or not 0 < self.max_share < 1 or not 0 < self.min_seen <= self.min_columns <= 1:
            raise ValueError("work_width must be >= 64, max_share in (0, 1), and 0 < min_seen <= min_columns <= 1")
        if not 2 <= self.min_frames <= self.frames:
            raise ValueError(f"min_frames must be >= 2 and at most frames, got {self.min_frames}, {self.frames}")


@dataclass(frozen=True)
class Hood:
    """The hood found (or not) in frames of one camera.

    share:     the largest share of the rows the hood covers in a column (at the centre column for
               a hood across the picture; 0: no hood found)
    spread:    robust scatter (1.4826 MAD) of the columns' outlines about the arch, share of rows:
               the estimate's uncertainty
    columns:   share of the columns that agree on the arch (showing it, or passing below it)
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
        return (f"{100 * self.share:.1f} % of the rows at most (+- {100 * self.spread:.1f} %, "
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
        if not (isinstance(arch, list) and len(arch) in (0, 3)
                and all(isinstance(a, int | float) and not isinstance(a, bool) and math.isfinite(a) for a in arch)):
            raise ValueError(f"{where}: arch must be three finite numbers (or none), got {arch!r}")
        if not (0 <= share < 1 and spread >= 0 and 0 <= columns <= 1) or (share > 0) != bool(arch):
            raise ValueError(f"{where}: share in [0, 1) with an arch when above 0, spread >= 0, columns in [0, 1]")
        hood = cls(share, spread, columns, tuple(float(a) for a in arch), int(number(d, "frames", where, int)))
        masked = float(hood.mask(_JUDGED_AT[1], _JUDGED_AT[0]).mean())
        if masked > MAX_MASKED:
            raise ValueError(f"{where}: its arch masks {100 * masked:.0f} % of the picture (at most "
                             f"{100 * MAX_MASKED:.0f} %): the model would see too little road")
        return hood


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
    rows, clear = _outlines(mean, spread, steady, top, cfg)
    arch = _fit_arch(rows, clear, h, cfg.fit_px)
    if arch is None:
        return Hood.none(len(frames), float((rows >= 0).mean()))
    xs = (np.arange(w) + 0.5 - w / 2.0) / (w / 2.0)
    shown, below, against = _agreeing(arch, xs, rows, clear, h, cfg.fit_px)
    columns = float((shown | below).sum() / max(int((shown | below | against).sum()), 1))
    if columns < cfg.min_columns or shown.mean() < cfg.min_seen:
        return Hood.none(len(frames), columns)
    res = rows[shown] - np.polyval(arch, xs[shown])
    mad = 1.4826 * float(np.median(np.abs(res - np.median(res))))
    share = 1.0 - float(np.polyval(arch, xs).min()) / h
    if share <= 0:
        return Hood.none(len(frames), columns)
    return Hood(share, mad / h, columns, tuple(float(a) / h for a in arch), len(frames))


def _agreeing(arch: np.ndarray, xs: np.ndarray, rows: np.ndarray, clear: np.ndarray, h: int,
              fit_px: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The columns that agree with ``arch``: those whose outline lies on it, and those with no hood
    above their bottom rows (:func:`_outlines`) that it passes below or through; and the columns
    against it: an outline off it, or the arch inside the picture where a column shows no hood or
    no outline. A column that says nothing is neither where the arch passes below the picture."""
    on = np.polyval(arch, xs)
    inside = on < h - EDGE_ROWS - fit_px
    shown = (rows >= 0) & (np.abs(on - rows) < fit_px)
    below = clear & ~inside
    return shown, below, ~shown & ~below & ((rows >= 0) | inside)


def _fit_arch(rows: np.ndarray, clear: np.ndarray, h: int, fit_px: float, trials: int = 300) -> np.ndarray | None:
    """The quadratic (rows of a picture ``h`` high, ``x`` in -1..1) most columns agree on
    (:func:`_agreeing`), refined by least squares on the outlines on it; None when fewer than three
    columns show an outline. A fixed-seed search over triples of outlines starts it, as wrong
    columns (steady asphalt) can be as many as right ones."""
    idx = np.flatnonzero(rows >= 0)
    if len(idx) < 3:
        return None
    xs = (np.arange(len(rows)) + 0.5 - len(rows) / 2.0) / (len(rows) / 2.0)
    rng = np.random.default_rng(0)

    def score(arch: np.ndarray) -> int:
        shown, below, against = _agreeing(arch, xs, rows, clear, h, fit_px)
        return int(shown.sum() + below.sum() - against.sum())

    best, best_n = None, -len(rows) - 1
    for _ in range(trials):
        pick = rng.choice(idx, 3, replace=False)
        if np.ptp(xs[pick]) < 0.1:                  # three neighbours say nothing of a curve
            continue
        arch = np.polyfit(xs[pick], rows[pick], 2)
        n = score(arch)
        if n > best_n:
            best, best_n = arch, n
    for _ in range(3):   # least squares on its outlines, while no worse
        if best is None:
            break
        shown = _agreeing(best, xs, rows, clear, h, fit_px)[0]
        if shown.sum() < 3:
            break
        refined = np.polyfit(xs[shown], rows[shown], 2)
        n = score(refined)
        if n < best_n:
            break
        best, best_n = refined, n
    return best


def _grey(frame: np.ndarray, width: int) -> np.ndarray:
    """Grey float32, area-shrunk to ``width`` (a frame that narrow or narrower is kept at its size)."""
    g = cv2.cvtColor(frame, cv2.COLOR_BGR2GRAY) if frame.ndim == 3 else frame
    if g.shape[1] > width:
        g = cv2.resize(g, (width, max(1, round(g.shape[0] * width / g.shape[1]))), interpolation=cv2.INTER_AREA)
    return g.astype(np.float32)


def _outlines(mean: np.ndarray, spread: np.ndarray, steady: np.ndarray, top: int,
              cfg: HoodConfig) -> tuple[np.ndarray, np.ndarray]:
    """Per column, the row where its steady run from the bottom ends, if an outline ends it, else -1;
    and whether the column shows no hood above its bottom ``EDGE_ROWS`` rows (they move, or are
    steady for fewer rows than an outline can be told in). A column steady to the search's end, or
    whose run ends in no outline, is neither: it says nothing."""
    h, w = mean.shape
    moving = ~steady[top:][::-1]                    # from the bottom row up to the search's end
    first = np.where(moving.any(axis=0), moving.argmax(axis=0), -1)
    y = h - 1 - first                               # the lowest row that moves: the outline is just below it
    # steady to the search's end (asphalt), or no steady run at all (the bottom row moves)
    ok = (first >= EDGE_ROWS) & (y >= 3) & (y <= h - 4)
    y = np.clip(y, 3, h - 4)
    cols = np.arange(w)
    above = np.mean([mean[y - k, cols] for k in (1, 2, 3)], axis=0)
    below = np.mean([mean[y + k, cols] for k in (1, 2, 3)], axis=0)
    shakes = np.max([spread[y + k, cols] for k in (-1, 0, 1)], axis=0) > cfg.outline_spread * cfg.steady_grey
    ok &= (np.abs(above - below) >= cfg.min_step) | shakes
    return np.where(ok, y + 1, -1).astype(float), (first >= 0) & (first < EDGE_ROWS)
