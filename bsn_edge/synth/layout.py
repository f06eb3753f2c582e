"""The road network: a grid of straight roads with lanes, parking strips and sidewalks.

Roads along the y axis sit at ``x = xs[k]``, roads along the x axis at ``y = ys[k]``.
Traffic keeps to the right. Each road has ``lanes`` driving lanes per direction and a
parking strip on each side, then a sidewalk; block interiors are terrain.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from bsn_edge import semantics as sm


@dataclass(frozen=True)
class RoadLayout:
    xs: np.ndarray          # centre lines of roads running along y
    lanes_x: np.ndarray     # driving lanes per direction of each
    ys: np.ndarray          # centre lines of roads running along x
    lanes_y: np.ndarray
    lane_width: float = 3.2
    parking_width: float = 2.2
    sidewalk_width: float = 2.5
    verge: bool = False     # the strip beside the carriageway is grass (terrain), not sidewalk

    def __post_init__(self) -> None:
        for a, b, name in ((self.xs, self.lanes_x, "x"), (self.ys, self.lanes_y, "y")):
            if len(a) != len(b):
                raise ValueError(f"roads along {name}: {len(a)} positions but {len(b)} lane counts")
            if len(a) > 1 and np.any(np.diff(a) <= 0):
                raise ValueError(f"road positions along {name} must be strictly increasing")
        if min(self.lane_width, self.parking_width, self.sidewalk_width) <= 0:
            raise ValueError("lane, parking and sidewalk widths must be positive")

    @property
    def hw_x(self) -> np.ndarray:
        """Half width of the carriageway (lanes and parking) of each road along y."""
        return self.lanes_x * self.lane_width + self.parking_width

    @property
    def hw_y(self) -> np.ndarray:
        return self.lanes_y * self.lane_width + self.parking_width

    def lane_offset(self, lanes: int) -> float:
        """Distance from the centre line to the middle of the rightmost driving lane."""
        return (lanes - 0.5) * self.lane_width

    @staticmethod
    def _nearest(p: np.ndarray, centres: np.ndarray, hw: np.ndarray):
        """Signed offset from, half width of, and index of the nearest road (by edge distance)."""
        if len(centres) == 0:
            inf = np.full(p.shape, np.inf, dtype=np.float32)
            return inf, np.zeros(p.shape, np.float32), np.zeros(p.shape, np.intp)
        k = np.searchsorted(centres, p)
        lo = np.clip(k - 1, 0, len(centres) - 1)
        hi = np.clip(k, 0, len(centres) - 1)
        d_lo = np.abs(p - centres[lo]) - hw[lo]
        d_hi = np.abs(p - centres[hi]) - hw[hi]
        idx = np.where(d_hi < d_lo, hi, lo)
        return (p - centres[idx]).astype(np.float32), hw[idx].astype(np.float32), idx

    def ground(self, gx: np.ndarray, gy: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Class, lane-marking mask and curb mask of ground points ``(gx, gy)``.

        Returns ``(trainId uint8, marking bool, curb bool)`` arrays shaped like ``gx``.
        """
        with np.errstate(invalid="ignore"):
            return self._ground(gx, gy)

    def _ground(self, gx: np.ndarray, gy: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        rx, hwx, ix = self._nearest(gx, self.xs, self.hw_x.astype(np.float64))
        ry, hwy, iy = self._nearest(gy, self.ys, self.hw_y.astype(np.float64))
        ax, ay = np.abs(rx), np.abs(ry)
        in_x, in_y = ax < hwx, ay < hwy
        road = in_x | in_y
        edge = np.minimum(ax - hwx, ay - hwy)  # distance past the nearest carriageway edge
        side = ~road & (edge < self.sidewalk_width)
        cls = np.full(gx.shape, sm.TERRAIN, np.uint8)
        if not self.verge:
            cls[side] = sm.SIDEWALK
        cls[road] = sm.ROAD
        curb = side & (edge < 0.25) & (not self.verge)

        lw = self.lane_width
        mark = np.zeros(gx.shape, bool)
        for rel, along, lanes_of, idx, own, other in (
            (ax, gy, self.lanes_x, ix, in_x, in_y),
            (ay, gx, self.lanes_y, iy, in_y, in_x),
        ):
            if not len(lanes_of):
                continue
            lanes = lanes_of[idx]
            straight = own & ~other
            dashed = np.mod(along, 6.0) < 3.0
            m = (rel < 0.08) & dashed  # centre line
            lane_k = np.round(rel / lw)
            m |= (lane_k >= 1) & (lane_k < lanes) & (np.abs(rel - lane_k * lw) < 0.06) & \
                (np.mod(along, 9.0) < 3.0)
            m |= np.abs(rel - lanes * lw) < 0.07  # parking strip edge, solid
            mark |= straight & m
        # zebra crossings where a road meets a crossing road's edge
        for rel_own, hw_own, rel_other, hw_other, own in (
            (ax, hwx, ay, hwy, in_x), (ay, hwy, ax, hwx, in_y),
        ):
            band = (rel_other - hw_other > 0.8) & (rel_other - hw_other < 3.8)
            stripes = np.mod(rel_own, 1.2) < 0.6
            mark |= own & band & stripes & (rel_own < hw_own - 0.4)
        return cls, mark, curb

    def classify(self, gx: np.ndarray, gy: np.ndarray) -> np.ndarray:
        """trainId of ground points (road, sidewalk or terrain)."""
        return self.ground(gx, gy)[0]
