"""Blind-spot masks -> one hazard reading per sector, by bearing from the intrinsics.

The sectors are data: the vehicle file's ``[sectors] layout`` (:class:`Sector` records, left to right, each
ending at the bearing ``to_deg``; the last runs to the field's edge) sizes the geometry, the alerts, the frame
log, the report and the bus (whose DBC is generated from it, :mod:`bsn_edge.alerts.dbc`).
"""

from __future__ import annotations

import dataclasses
import math
import re
from dataclasses import dataclass
from typing import Any

import numpy as np

from bsn_edge.camera import Intrinsics
from bsn_edge.config_toml import check_fields, setting, shown
from bsn_edge.model_frame import ModelFrame

EDGE_DEG = 89.0          # a bearing at +-89 degrees is as far as a pinhole camera's columns go
MAX_SECTORS = 9          # three hazard frames of three sectors each (the DBC's ids 0x500, 0x502, 0x503)
NAME = re.compile(r"^[A-Z][A-Z0-9_]{0,11}$")    # a DBC signal's prefix: Far_Left_Level fits 32 characters


@dataclass(frozen=True)
class Sector:
    """One sector of the layout: its ``name`` (capitals, digits, underscores: ``FAR_LEFT``) and ``to_deg``, the
    bearing of its right edge in degrees (negative = left of the camera's axis); None for the last sector."""

    name: str
    to_deg: float | None = None

    @classmethod
    def of(cls, item: Any, k: int) -> Sector:
        """A layout entry as the vehicle file writes it (a table ``{name = "LEFT", to_deg = -12.0}``) or as code
        makes it; ``ValueError`` naming entry ``k`` when it is neither."""
        if isinstance(item, Sector):
            return item
        if not isinstance(item, dict):
            raise ValueError(f"layout[{k}] = {shown(item)} must be a table: {{name = \"LEFT\", to_deg = -12.0}}")
        bad = sorted(set(item) - {"name", "to_deg"})
        if bad:
            raise ValueError(f"layout[{k}] has unknown key(s) {', '.join(map(repr, bad))}; a sector has name and "
                             "to_deg")
        if "name" not in item:
            raise ValueError(f"layout[{k}] has no name")
        return cls(item["name"], item.get("to_deg"))


DEFAULT_LAYOUT = (Sector("LEFT", -12.0), Sector("CENTRE", 12.0), Sector("RIGHT"))


def check_layout(layout: tuple[Sector, ...]) -> None:
    """``ValueError`` naming the first thing wrong with ``layout``: from 1 to :data:`MAX_SECTORS` sectors with
    distinct names of :data:`NAME`'s form, every edge but the last a finite bearing inside +-89 degrees, each
    right of the one before; the last with none."""
    if not 1 <= len(layout) <= MAX_SECTORS:
        raise ValueError(f"layout has {len(layout)} sectors; from 1 to {MAX_SECTORS}")
    names = [s.name for s in layout]
    for k, s in enumerate(layout):
        if not isinstance(s.name, str) or not NAME.match(s.name):
            raise ValueError(f"layout[{k}].name = {shown(s.name)} must be 1-12 capitals, digits or underscores, "
                             "starting with a capital (FAR_LEFT)")
        if names.count(s.name) > 1:
            raise ValueError(f"layout names {s.name!r} twice")
        last = k == len(layout) - 1
        if last and s.to_deg is not None:
            raise ValueError(f"layout[{k}] ({s.name}) is the last sector: it runs to the field's edge, so it has no "
                             "to_deg")
        if last:
            continue
        edge = s.to_deg
        # compared, not converted: a 400-digit whole number is refused, not an overflow; NaN fails the test
        number = isinstance(edge, int | float) and not isinstance(edge, bool)
        if not number or not -EDGE_DEG < edge < EDGE_DEG:  # type: ignore[operator]
            raise ValueError(f"layout[{k}].to_deg = {shown(edge)} ({s.name}) must be a bearing between "
                             f"-{EDGE_DEG:g} and {EDGE_DEG:g} degrees")
        if k and edge <= layout[k - 1].to_deg:  # type: ignore[operator]
            raise ValueError(f"layout[{k}].to_deg = {edge:g} ({s.name}) must be right of the sector before it "
                             f"({layout[k - 1].to_deg:g})")


@dataclass(frozen=True)
class SectorConfig:
    """The sectors, left to right (``layout``), and how their blind spots count.

    range_m:   blind spots farther than this are ignored.
    full_area: share of a sector's pixels that, at zero distance, makes its score 1.
    """

    # the vehicle file's list of tables is made into Sector records here, the one place it is read
    layout: tuple[Sector, ...] = dataclasses.field(default=DEFAULT_LAYOUT, metadata={"also": (list, tuple)})
    # at least 10 m: nearer, a level could never be raised on a blind spot the car can still stop for
    range_m: float = setting(30.0, 10.0, 200.0, "m")
    # at most 5 %: more, and a sector could need more blind-spot pixels than it has to reach a level
    full_area: float = setting(0.02, 0.001, 0.05)

    def __post_init__(self) -> None:
        check_fields(self)
        if not isinstance(self.layout, list | tuple):
            raise ValueError(f"layout = {shown(self.layout)} must be a list of sectors")
        if isinstance(self.layout, list) or not all(isinstance(s, Sector) for s in self.layout):
            object.__setattr__(self, "layout", tuple(Sector.of(item, k) for k, item in enumerate(self.layout)))
        check_layout(self.layout)
        # -12 and -12.0 are one layout (one digest)
        object.__setattr__(self, "layout", tuple(Sector(s.name, None if s.to_deg is None else float(s.to_deg))
                                                 for s in self.layout))
        if not self.range_m > 0 or not 0 < self.full_area <= 1:
            raise ValueError("range_m must be positive and full_area in (0, 1]")

    @property
    def names(self) -> tuple[str, ...]:
        """The sectors' names, left to right: the order of every per-sector tuple (alerts, bus, log)."""
        return tuple(s.name for s in self.layout)

    @property
    def edges_deg(self) -> tuple[float, ...]:
        """The bearings between neighbouring sectors, left to right (one fewer than the sectors)."""
        return tuple(float(s.to_deg) for s in self.layout[:-1])  # type: ignore[arg-type]


SECTORS = SectorConfig().names   # the default layout's names (LEFT, CENTRE, RIGHT), for what reads no vehicle file


@dataclass(frozen=True)
class SectorReading:
    """One sector of one frame: score in [0, 1] and the distance to the nearest blind spot in range."""

    score: float
    distance_m: float | None


class SectorGeometry:
    """Column -> sector lookup and per-sector pixel counts for one camera; built once per model."""

    def __init__(self, intrinsics: Intrinsics, cfg: SectorConfig | None = None) -> None:
        self.cfg = cfg or SectorConfig()
        edges = self.cfg.edges_deg
        n = len(self.cfg.layout)
        bearing = np.degrees(np.arctan2(np.arange(intrinsics.width) - intrinsics.cx, intrinsics.fx))
        # a column exactly on an edge belongs to the sector on its right
        self.column_sector = np.digitize(bearing, edges).astype(np.int8)
        self.height = intrinsics.height
        self.sector_pixels = np.bincount(self.column_sector, minlength=n) * intrinsics.height
        self.sector_columns = [np.nonzero(self.column_sector == s)[0] for s in range(n)]

    def read(self, mask: np.ndarray, depth: np.ndarray) -> tuple[SectorReading, ...]:
        """Score each sector: blind-spot pixels within range, each weighted by nearness
        (1 at the camera, 0 at ``range_m``), over ``full_area`` of the sector."""
        rng = self.cfg.range_m
        # one pass over the frame: per column, the nearest blind spot in range and the summed nearness
        dist = np.where(mask & (depth > 0) & (depth < rng), depth, np.float32(np.inf))
        nearest = dist.min(axis=0)
        weights = np.maximum(1.0 - dist / np.float32(rng), 0.0).sum(axis=0, dtype=np.float64)
        out = []
        for s, cols in enumerate(self.sector_columns):
            d = float(nearest[cols].min()) if len(cols) else math.inf
            if not math.isfinite(d):
                out.append(SectorReading(0.0, None))
                continue
            score = float(weights[cols].sum()) / (self.cfg.full_area * self.sector_pixels[s])
            out.append(SectorReading(min(score, 1.0), d))
        return tuple(out)


def bearing_deg(u: float, intrinsics: Intrinsics) -> float:
    """Bearing of image column ``u``, degrees, negative to the left."""
    return math.degrees(math.atan2(u - intrinsics.cx, intrinsics.fx))


def blind_spots(prob: np.ndarray, threshold: float, mf: ModelFrame) -> np.ndarray:
    """The blind-spot mask the sectors read, the first step of post-processing: above the card's threshold
    and where the camera sees. Where a camera narrower than the model camera sees nothing, the model's
    input is the frame mirrored from its edge; a blind spot found in a mirrored car is not in the world."""
    return (prob >= threshold) & mf.seen
