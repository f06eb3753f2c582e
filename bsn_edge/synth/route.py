"""The ego car's route through the grid: straight runs and turns at intersections.

The route is a dense polyline (every few centimetres) with headings, sampled by
arc length; turns are quarter circles tangent to the two lanes they join.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from bsn_edge.synth.layout import RoadLayout

STEP = 0.05            # polyline spacing, metres
RIGHT_RADIUS = 7.0     # turn radii, metres
LEFT_EXTRA = 3.0       # a left turn's radius is the two lane offsets plus this


@dataclass(frozen=True)
class Route:
    """Ego path: ``xy [M, 2]``, heading ``yaw [M]`` (radians, unwrapped), arc length ``s [M]``."""

    xy: np.ndarray
    yaw: np.ndarray
    s: np.ndarray
    turns: list[dict] = field(default_factory=list)

    @property
    def length(self) -> float:
        return float(self.s[-1])

    def at(self, s: np.ndarray | float) -> tuple[np.ndarray, np.ndarray]:
        """Positions ``[N, 2]`` and headings ``[N]`` at arc lengths ``s``."""
        s = np.atleast_1d(np.asarray(s, dtype=np.float64))
        if np.any(s < 0) or np.any(s > self.s[-1] + 1e-9):
            raise ValueError(f"arc length outside the route [0, {self.length:.1f}] m")
        x = np.interp(s, self.s, self.xy[:, 0])
        y = np.interp(s, self.s, self.xy[:, 1])
        return np.stack([x, y], axis=1), np.interp(s, self.s, self.yaw)


def _right(f: np.ndarray) -> np.ndarray:
    return np.array([f[1], -f[0]])


def _line(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    n = max(int(np.ceil(np.linalg.norm(b - a) / STEP)), 1)
    return a + (b - a) * (np.arange(n) / n)[:, None]


def _arc(a: np.ndarray, b: np.ndarray, centre: np.ndarray, radius: float) -> np.ndarray:
    n = max(int(np.ceil(0.5 * np.pi * radius / STEP)), 2)
    phi = (np.arange(n) / n * 0.5 * np.pi)[:, None]
    return centre + np.cos(phi) * (a - centre) + np.sin(phi) * (b - centre)


def build_route(layout: RoadLayout, length: float, rng: np.random.Generator,
                turn_prob: float = 0.4) -> Route:
    """A route of at least ``length`` metres starting mid-block on a road along y.

    At each intersection the car goes straight or turns left or right; if no turn
    has happened by the second intersection, it turns there, so every clip long
    enough to reach two intersections includes a turn.
    """
    if len(layout.xs) < 3 or len(layout.ys) < 3:
        raise ValueError("the layout needs at least 3 roads along each axis for a route")
    # state: which family of roads we are on (0: along y at x = xs[k]; 1: along x at y = ys[k])
    fam = 0
    # start near the middle of the network so the route has room in every direction
    k = len(layout.xs) // 2 + int(rng.integers(-1, 1))
    f = np.array([0.0, 1.0]) if rng.random() < 0.5 else np.array([0.0, -1.0])
    j = len(layout.ys) // 2 + int(rng.integers(-1, 1))
    lanes_here = int(layout.lanes_x[k])
    o = layout.lane_offset(lanes_here)
    start_along = 0.5 * (layout.ys[j] + layout.ys[j + 1]) if j + 1 < len(layout.ys) else layout.ys[j]
    pos = np.array([layout.xs[k], start_along]) + _right(f) * o

    pieces: list[np.ndarray] = []
    total, crossings_seen, turned = 0.0, 0, False
    turns: list[dict] = []
    while total < length:
        cross_pos = layout.ys if fam == 0 else layout.xs
        cross_lanes = layout.lanes_y if fam == 0 else layout.lanes_x
        along_axis = 1 if fam == 0 else 0
        sgn = f[along_axis]
        here = pos[along_axis]
        ahead = (cross_pos - here) * sgn
        max_r = RIGHT_RADIUS + LEFT_EXTRA + 4 * layout.lane_width
        cand = np.where(ahead > max_r)[0]
        if not len(cand):
            break  # ran off the generated network; callers size the network generously
        c = cand[np.argmin(ahead[cand])]
        crossings_seen += 1
        action = _choose_action(rng.random(), turned, crossings_seen, turn_prob)
        if action == "straight":
            # run through the intersection to just past its far side
            target = pos.copy()
            target[along_axis] = cross_pos[c] + sgn * (layout.lane_width * cross_lanes[c] + 1.0)
            pieces.append(_line(pos, target))
            total += float(np.linalg.norm(target - pos))
            pos = target
            continue
        o_a = layout.lane_offset(lanes_here)
        o_b = layout.lane_offset(int(cross_lanes[c]))
        f_new = _right(f) if action == "right" else -_right(f)
        radius = RIGHT_RADIUS if action == "right" else o_a + o_b + LEFT_EXTRA
        a, b = _corner(pos, f, f_new, along_axis, float(cross_pos[c]), o_b, radius)
        pieces.append(_line(pos, a))
        pieces.append(_arc(a, b, a + f_new * radius, radius))
        total += float(np.linalg.norm(a - pos)) + 0.5 * np.pi * radius
        turns.append({"at_m": round(total - 0.25 * np.pi * radius, 2), "direction": action})
        pos, f, fam, lanes_here, turned = b, f_new, 1 - fam, int(cross_lanes[c]), True
    pieces.append(pos[None])
    return _route(np.concatenate(pieces), turns, length)


def _choose_action(r: float, turned: bool, crossings_seen: int, turn_prob: float) -> str:
    """What the car does at a crossing, from the uniform draw ``r``: it turns at the second crossing at
    the latest, else turns left or right with ``turn_prob`` in all."""
    if not turned and crossings_seen >= 2:
        return "right" if r < 0.5 else "left"
    if r < turn_prob / 2:
        return "right"
    if r < turn_prob:
        return "left"
    return "straight"


def _corner(pos: np.ndarray, f: np.ndarray, f_new: np.ndarray, along_axis: int, cross_at: float, o_b: float,
            radius: float) -> tuple[np.ndarray, np.ndarray]:
    """Where a turn's arc begins and ends: around the corner where the current lane line meets the new one."""
    lane_line_new = np.zeros(2)
    lane_line_new[along_axis] = cross_at
    lane_line_new = lane_line_new + _right(f_new) * o_b
    q = pos.copy()
    q[along_axis] = lane_line_new[along_axis]
    return q - f * radius, q + f_new * radius


def _route(xy: np.ndarray, turns: list[dict], length: float) -> Route:
    """The route through points ``xy`` (repeats dropped), its heading and arc length."""
    seg = np.linalg.norm(np.diff(xy, axis=0), axis=1)
    keep = np.concatenate([[True], seg > 1e-9])
    xy = xy[keep]
    s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(xy, axis=0), axis=1))])
    d = np.diff(xy, axis=0)
    yaw = np.arctan2(d[:, 1], d[:, 0])
    yaw = np.unwrap(np.concatenate([yaw, yaw[-1:]]))
    if s[-1] < length:
        raise ValueError(f"route ran off the road network after {s[-1]:.0f} m of {length:.0f} m")
    return Route(xy=xy, yaw=yaw, s=s, turns=turns)
