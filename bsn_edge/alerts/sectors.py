"""Blind-spot masks -> one hazard reading per sector (``SECTORS``: left, centre, right), by bearing from the
intrinsics."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from bsn_edge.camera import Intrinsics
from bsn_edge.config_toml import check_fields, setting
from bsn_edge.model_frame import ModelFrame

SECTORS = ("LEFT", "CENTRE", "RIGHT")   # the one list of sectors, left to right: the bus, the alert and the geometry


@dataclass(frozen=True)
class SectorConfig:
    """Sector boundaries are bearings in degrees (negative = left of the optical axis).

    range_m:   blind spots farther than this are ignored.
    full_area: share of a sector's pixels that, at zero distance, makes its score 1.
    """

    left_edge_deg: float = setting(-12.0, -89.0, 89.0, "deg")
    right_edge_deg: float = setting(12.0, -89.0, 89.0, "deg")
    # at least 10 m: nearer, a level could never be raised on a blind spot the car can still stop for
    range_m: float = setting(30.0, 10.0, 200.0, "m")
    # at most 5 %: more, and a sector could need more blind-spot pixels than it has to reach a level
    full_area: float = setting(0.02, 0.001, 0.05)

    def __post_init__(self) -> None:
        check_fields(self)
        if not -89 < self.left_edge_deg < self.right_edge_deg < 89:
            raise ValueError(f"need -89 < left_edge_deg < right_edge_deg < 89 degrees, got {self.left_edge_deg}, "
                             f"{self.right_edge_deg}")
        if not self.range_m > 0 or not 0 < self.full_area <= 1:
            raise ValueError("range_m must be positive and full_area in (0, 1]")

    @property
    def edges_deg(self) -> tuple[float, ...]:
        """The bearings between neighbouring sectors, left to right (one fewer than ``SECTORS``)."""
        return self.left_edge_deg, self.right_edge_deg


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
        if len(edges) != len(SECTORS) - 1:
            raise ValueError(f"{len(edges)} sector edges for the {len(SECTORS)} sectors {SECTORS}")
        bearing = np.degrees(np.arctan2(np.arange(intrinsics.width) - intrinsics.cx, intrinsics.fx))
        # a column exactly on an edge belongs to the sector on its right
        self.column_sector = np.digitize(bearing, edges).astype(np.int8)
        self.height = intrinsics.height
        self.sector_pixels = np.bincount(self.column_sector, minlength=len(SECTORS)) * intrinsics.height
        self.sector_columns = [np.nonzero(self.column_sector == s)[0] for s in range(len(SECTORS))]

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
