"""Whether the camera still sees: a covered, blinded, frozen, noisy or fogged picture, as a whole and per
sector, with a named reason (:class:`Blindness`), onset and recovery held by time (hysteresis).

What each reason looks like, measured on every frame (numpy and OpenCV only, a few hundred microseconds):

- on a sparse grid of the source frame's own pixels (no filter: a sensor's noise and a frozen ISP show
  there, a blur of the warp would hide both): the light (mean, share dark), the structure (mean gradient,
  the picture's spread), the correlation of neighbouring pixels (a scene's are alike, a broken link's
  noise is not) and whether the grid is exactly the last frame's (a real sensor never repeats itself to
  the grey level; a car standing at a light still differs by its noise);
- on the frame the model sees, cut in cells: each cell's spread and saturation, against its own running
  baseline, so a covered region (mud, a sticker, a wiper) is found in the sector it covers, and a cell that
  never had structure (sky, a blank wall) is no evidence either way.

Night is not a fault: a lit road at night has lights and edges, so it is neither dark and flat (covered) nor
flat against its own baseline. The picture's sharpness is judged against this camera's own running
baseline (fog, dirt, heavy blur: far below what the camera showed), which is learnt from frames judged
clear, so a camera covered from its first frame is caught by the absolute checks (dark and flat, one grey,
saturated, frozen, noise) and not by the relative ones.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import cv2
import numpy as np

from bsn_edge.alerts.blindness import WHOLE, Blindness
from bsn_edge.config_toml import check_fields, setting


@dataclass(frozen=True)
class VisibilityConfig:
    """Thresholds and times of the camera-health check (``[visibility]`` of the vehicle file).

    enabled:        false turns the check off (a camera whose picture is judged elsewhere)
    onset_s:        a reason must hold this long before it is raised (one odd frame raises nothing)
    clear_s:        a picture must be clear this long before the reason is cleared
    dark_level:     grey level under which the picture is dark; covered when also flat
    flat_gradient:  mean gradient (grey levels a grid step) under which the picture has no structure
    flat_spread:    standard deviation of grey under which the picture is one flat grey
    saturated_share: share of the picture at full scale (glare, white-out) that blinds it as a whole
    sector_saturated: share of a sector's cells saturated or covered that blinds that sector
    frozen_s:       the same picture, exactly, this long: frozen
    noise_correlation: neighbouring pixels correlated less than this: noise, not a scene
    blur_ratio:     the picture's gradient under this share of the camera's running baseline, with its
                    spread under ``contrast_ratio`` of its own (fog, dirt) or its fine detail under
                    ``fine_ratio`` of its own (blur): fog, dirt or blur
    blur_hold_s:    how long fog, dirt or blur must hold before it is raised (they come on slowly; a scene
                    with little contrast passes)
    baseline_s:     time constant of the running baselines (sharpness, each cell's spread)
    cell_flat:      a cell's spread under this (grey levels) with a baseline over three times it: covered
    """

    enabled: bool = True
    onset_s: float = setting(0.3, 0.0, 1.0, "s")
    clear_s: float = setting(1.0, 0.1, 2.0, "s")
    dark_level: float = setting(25.0, 0.0, 128.0, "grey")
    flat_gradient: float = setting(1.5, 0.0, 20.0, "grey")
    flat_spread: float = setting(4.0, 0.0, 64.0, "grey")
    saturated_share: float = setting(0.5, 0.1, 1.0)
    sector_saturated: float = setting(0.5, 0.1, 1.0)
    frozen_s: float = setting(0.5, 0.1, 5.0, "s")
    noise_correlation: float = setting(0.35, 0.0, 0.9)
    blur_ratio: float = setting(0.6, 0.05, 0.9)
    contrast_ratio: float = setting(0.7, 0.05, 0.95)
    fine_ratio: float = setting(0.75, 0.05, 0.95)
    blur_hold_s: float = setting(3.0, 0.3, 10.0, "s")
    baseline_s: float = setting(10.0, 1.0, 120.0, "s")
    cell_flat: float = setting(2.0, 0.1, 32.0, "grey")

    def __post_init__(self) -> None:
        check_fields(self)


GRID_WIDTH = 160      # the source frame's pixels are read on a grid about this wide
CELLS = (8, 16)       # rows, columns of cells over the model's frame
SATURATED = 250       # grey level at or over which a pixel is at full scale
FINE_ROWS = 32       # rows of the source frame read at full resolution for its fine detail
WARM_S = 1.0          # seconds of clear frames before the relative checks (blur, covered cells) judge


@dataclass(frozen=True)
class Visibility:
    """One frame's word on the camera: the reason raised (after hysteresis), each sector's whether it can
    see, and the figures it came from (``score``: 1 clear, 0 blind; ``raw``: the reason this frame alone
    would give)."""

    reason: Blindness
    unseen: tuple[bool, ...]
    score: float
    raw: Blindness = Blindness.CLEAR

    @property
    def whole(self) -> bool:
        """The picture as a whole cannot be seen (UNAVAILABLE); else at most some sectors (DEGRADED)."""
        return self.reason in WHOLE


@dataclass
class _Held:
    """A reason's onset and recovery, held by time."""

    since: float | None = None       # the raw reason has held since
    clear_since: float | None = None
    raised: Blindness = Blindness.CLEAR


@dataclass
class CameraHealth:
    """The camera-health check: feed every frame (its time, the source frame and the model's frame) to
    :meth:`look`; pure but for its own state, and time comes from the caller."""

    cfg: VisibilityConfig
    columns: np.ndarray              # each model-frame column's sector (``SectorGeometry.column_sector``)
    sectors: int
    _last_grid: np.ndarray | None = None
    _same_since: float | None = None
    _last_shown: float = 0.0
    _sharp: np.ndarray | None = None  # running baselines of the picture's gradient, spread and fine detail
    _cells: np.ndarray | None = None  # running baseline of each cell's spread
    _clear_s: float = 0.0
    _last_t: float | None = None
    _held: _Held = field(default_factory=_Held)
    _held_sectors: list[_Held] = field(default_factory=list)
    _cell_cols: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int8))

    def __post_init__(self) -> None:
        # the sector of each cell column (the model-frame column at its centre) and each sector's hold: fixed
        # for the run, made once, not on every frame
        w, n = len(self.columns), CELLS[1]
        self._cell_cols = self.columns[np.clip(((np.arange(n) + 0.5) * w / n).astype(int), 0, w - 1)]
        self._held_sectors = [_Held() for _ in range(self.sectors)]

    def look(self, t: float, frame: np.ndarray, model_frame: np.ndarray) -> Visibility:
        """The camera's word at time ``t``: ``frame`` the source frame (BGR or grey), ``model_frame`` what the
        model sees (its input, ``H x W x 3``)."""
        if not self.cfg.enabled:
            return Visibility(Blindness.CLEAR, (False,) * self.sectors, 1.0)
        dt = 0.0 if self._last_t is None else max(t - self._last_t, 0.0)
        self._last_t = t
        grid = _grid(frame)
        whole, score, sharp = self._whole(t, grid, frame)
        cells, cell_sat = _cells(model_frame)
        # a cover takes the picture's edges too: while a slow reason (BLUR) is still being held, the sectors
        # are judged as on a clear picture, so the cover shows as PARTIAL at once
        unseen_now = self._sector_blind(cells, cell_sat, whole in (Blindness.CLEAR, Blindness.BLUR))
        raw = whole if whole is not Blindness.CLEAR else (Blindness.PARTIAL if any(unseen_now) else Blindness.CLEAR)
        if raw is Blindness.CLEAR:
            self._learn(sharp, cells, dt)
        reason = _hold(self._held, raw, t, self.cfg)
        marks = [_hold(h, Blindness.PARTIAL if u else Blindness.CLEAR, t, self.cfg) is not Blindness.CLEAR
                 for h, u in zip(self._held_sectors, unseen_now, strict=True)]
        if reason in WHOLE:
            marks = [True] * self.sectors
        elif reason is Blindness.CLEAR and any(marks):
            reason = Blindness.PARTIAL         # a sector still held blind keeps the picture partial
        return Visibility(reason, tuple(marks), score, raw)

    def _whole(self, t: float, grid: np.ndarray, frame: np.ndarray) -> tuple[Blindness, float, np.ndarray]:
        """The picture as a whole: the first reason that holds this frame (CLEAR if none), a score, and the
        picture's gradient, spread and fine detail (for the baselines)."""
        cfg = self.cfg
        g = grid.astype(np.float32)
        mean, spread = float(g.mean()), float(g.std())
        gradient = _gradient(g)
        same = self._last_grid is not None and self._last_grid.shape == grid.shape and \
            np.array_equal(self._last_grid, grid)
        # frozen since the first of the identical pictures was shown
        self._same_since = (self._same_since if self._same_since is not None else self._last_shown) if same else None
        self._last_grid, self._last_shown = grid, t
        sharp = np.array([gradient, spread, _fine(frame) / (gradient + 1e-3)], np.float64)
        ratio = None if self._sharp is None else sharp / np.maximum(self._sharp, 1e-6)
        score = 1.0 if ratio is None else float(min(1.0, ratio[0]))
        # saturation first: a white-out is one flat grey too, but it is glare, not a cover
        if float((grid >= SATURATED).mean()) >= cfg.saturated_share:
            return Blindness.SATURATED, 0.0, sharp
        if (mean < cfg.dark_level and gradient < cfg.flat_gradient) or spread < cfg.flat_spread:
            return Blindness.COVERED, 0.0, sharp
        if self._same_since is not None and t - self._same_since >= cfg.frozen_s:
            return Blindness.FROZEN, 0.0, sharp
        if _neighbour_correlation(g) < cfg.noise_correlation:
            return Blindness.NOISE, 0.0, sharp
        # fog takes the picture's contrast and its edges, blur its edges and most of its fine detail; a scene
        # with less texture (an open square after a street) takes edges alone, and is no fault
        if ratio is not None and self._clear_s >= WARM_S and ratio[0] < cfg.blur_ratio \
                and (ratio[1] < cfg.contrast_ratio or ratio[2] < cfg.fine_ratio):
            return Blindness.BLUR, score, sharp
        return Blindness.CLEAR, score, sharp

    def _sector_blind(self, cells: np.ndarray, saturated: np.ndarray, judge: bool) -> list[bool]:
        """Each sector: whether the share of its cells covered (flat against their own baseline) or
        saturated passes ``sector_saturated``."""
        cfg = self.cfg
        covered = np.zeros_like(cells, dtype=bool)
        known = np.ones_like(cells, dtype=bool)
        if self._cells is not None and self._clear_s >= WARM_S and judge:
            known = self._cells > 3 * cfg.cell_flat
            covered = known & (cells < cfg.cell_flat)
        blind = covered | saturated
        out = []
        for s in range(self.sectors):
            mine = self._cell_cols == s
            weight = (known | saturated)[:, mine].sum()
            out.append(bool(weight) and blind[:, mine].sum() / max(weight, 1) >= cfg.sector_saturated)
        return out

    def _learn(self, sharp: np.ndarray, cells: np.ndarray, dt: float) -> None:
        """A clear frame teaches the running baselines (sharpness, each cell's spread)."""
        a = min(1.0, dt / self.cfg.baseline_s) if self._sharp is not None else 1.0
        self._sharp = sharp if self._sharp is None else (1 - a) * self._sharp + a * sharp
        # each cell's baseline rises at once and falls slowly: a car passing in front of a wall's cell does
        # not teach the cell to be flat
        if self._cells is None or self._cells.shape != cells.shape:
            self._cells = cells.copy()
        else:
            self._cells = np.maximum(cells, (1 - a) * self._cells + a * cells)
        self._clear_s += dt


def _hold(h: _Held, raw: Blindness, t: float, cfg: VisibilityConfig) -> Blindness:
    """``raw`` once it has held ``onset_s``; the raised reason kept until the picture is clear ``clear_s``."""
    if raw is Blindness.CLEAR:
        h.since = None
        if h.raised is not Blindness.CLEAR:
            h.clear_since = t if h.clear_since is None else h.clear_since
            if t - h.clear_since >= cfg.clear_s:
                h.raised, h.clear_since = Blindness.CLEAR, None
        return h.raised
    h.clear_since = None
    h.since = t if h.since is None else h.since
    # a frozen picture has held frozen_s already: its evidence is its own duration; fog, dirt and blur come
    # on slowly and a low-contrast scene (a glass front filling the view) comes and goes: they must hold longer
    held = raw is Blindness.FROZEN or t - h.since >= (cfg.blur_hold_s if raw is Blindness.BLUR else cfg.onset_s)
    if held and (h.raised is Blindness.CLEAR or raw < h.raised or raw in WHOLE):
        h.raised = raw
    return h.raised


def _grid(frame: np.ndarray) -> np.ndarray:
    """The source frame's own grey pixels on a grid about :data:`GRID_WIDTH` wide (no filter)."""
    step = max(1, frame.shape[1] // GRID_WIDTH)
    sub = frame[::step, ::step]
    if sub.ndim == 3:
        # a channel, not a mix: a mix averages a sensor's noise down; green carries most of the light
        sub = sub[..., 1] if sub.shape[2] >= 3 else sub[..., 0]
    return np.ascontiguousarray(sub)


def _gradient(g: np.ndarray) -> float:
    """Mean absolute difference of neighbouring grid pixels, across and down."""
    return float((np.abs(np.diff(g, axis=1)).mean() + np.abs(np.diff(g, axis=0)).mean()) / 2)


def _fine(frame: np.ndarray) -> float:
    """Mean absolute difference of neighbouring pixels at the frame's own resolution, on about
    :data:`FINE_ROWS` rows of its green channel: the detail a blur takes first."""
    rows = frame[::max(1, frame.shape[0] // FINE_ROWS)]
    g = rows[..., 1] if rows.ndim == 3 and rows.shape[2] >= 3 else (rows[..., 0] if rows.ndim == 3 else rows)
    return float(np.abs(np.diff(g.astype(np.int16), axis=1)).mean())


def _neighbour_correlation(g: np.ndarray) -> float:
    """Correlation of each grid pixel with its right-hand neighbour (1 for a smooth scene, 0 for noise)."""
    a, b = g[:, :-1].ravel(), g[:, 1:].ravel()
    a, b = a - a.mean(), b - b.mean()
    den = float(np.sqrt((a * a).sum() * (b * b).sum()))
    return float((a * b).sum() / den) if den > 0 else 1.0


def _cells(model_frame: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Each cell of the model's frame (:data:`CELLS`): its grey spread, and whether most of it is at full
    scale. Read on every second pixel of the green channel (a cell is 16 by 16 of them at 256x512), its
    moments by OpenCV's area resampling: a fraction of a millisecond."""
    g = model_frame[::2, ::2, 1] if model_frame.ndim == 3 else model_frame[::2, ::2]
    rows, cols = CELLS
    h, w = g.shape[0] // rows * rows, g.shape[1] // cols * cols
    x = np.ascontiguousarray(g[:h, :w], dtype=np.float32)
    mean = cv2.resize(x, (cols, rows), interpolation=cv2.INTER_AREA)
    square = cv2.resize(x * x, (cols, rows), interpolation=cv2.INTER_AREA)
    spread = np.sqrt(np.maximum(square - mean * mean, 0.0))
    full = cv2.resize((x >= SATURATED).astype(np.float32), (cols, rows), interpolation=cv2.INTER_AREA)
    return spread, full >= 0.5


@dataclass
class BlindnessLog:
    """What the camera-health check raised over a run, for its summary: seconds and frames per reason, and
    each stretch (reason, from, to) on the frames' clock."""

    seconds: dict[str, float] = field(default_factory=dict)
    frames: dict[str, int] = field(default_factory=dict)
    stretches: list[list] = field(default_factory=list)
    _last: tuple[float, Blindness] | None = None

    MAX_STRETCHES = 100     # a flickering camera's stretches are counted, the first ones kept

    def add(self, t: float, reason: Blindness) -> None:
        if self._last is not None:
            t0, prev = self._last
            if prev is not Blindness.CLEAR:
                self.seconds[prev.name] = round(self.seconds.get(prev.name, 0.0) + max(t - t0, 0.0), 3)
        if reason is not Blindness.CLEAR:
            self.frames[reason.name] = self.frames.get(reason.name, 0) + 1
            if self.stretches and self.stretches[-1][0] == reason.name and self._last is not None \
                    and self._last[1] is reason:
                self.stretches[-1][2] = round(t, 3)
            elif len(self.stretches) < self.MAX_STRETCHES:
                self.stretches.append([reason.name, round(t, 3), round(t, 3)])
        self._last = (t, reason)

    def to_json(self) -> dict:
        return {"frames": dict(self.frames), "seconds": dict(self.seconds),
                "stretches": [{"reason": r, "from_s": a, "to_s": b} for r, a, b in self.stretches]}
