"""Axis-aligned boxes, the one primitive of the synthetic world.

The road network is a grid, so every building, vehicle, person, pole and tree
is an axis-aligned box in the z-up world frame. Stored as arrays (one row per
box) so culling and shading run vectorized.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

# Appearance kinds: how a box is textured.
KIND_BUILDING = 0
KIND_VEHICLE = 1
KIND_PERSON = 2
KIND_POLE = 3
KIND_TRUNK = 4
KIND_CROWN = 5
KIND_CABIN = 6      # a vehicle's glasshouse
KIND_WHEEL = 7      # a vehicle's axle with its two wheels
KIND_LEGS = 8
KIND_HEAD = 9
KIND_HEDGE = 10
KIND_FENCE = 11
KIND_WALL = 12
KIND_HILL = 13      # far hills and tree lines on the horizon
KIND_RIDER = 14
KIND_BARRIER = 15   # concrete road barrier
GROUND_EPS_M = 1e-6    # a box whose bottom is this low stands on the road (its footprint hides it)

# ``facing``: the way the front of a vehicle points (lights, plates), 0 where it has none.
FACING_NONE = 0
FACING_AXES = {1: (0, 1.0), -1: (0, -1.0), 2: (1, 1.0), -2: (1, -1.0)}  # code -> (axis, sign)


@dataclass(frozen=True)
class Boxes:
    """``N`` axis-aligned boxes.

    lo, hi:   ``[N, 3]`` world corners (x, y, z), metres, ``lo < hi``.
    cls:      ``[N]`` Cityscapes trainId of the box's pixels.
    kind:     ``[N]`` appearance kind (``KIND_*``).
    color:    ``[N, 3]`` float32 base colour, BGR in [0, 1].
    grounded: ``[N]`` the box stands on the ground, so the ground under it is never visible.
    track:    ``[N]`` stable id of the object across frames (all parts of one vehicle or person
              share it).
    facing:   ``[N]`` int8, where the object's front points (``FACING_AXES``); 0 = no front.
    """

    lo: np.ndarray
    hi: np.ndarray
    cls: np.ndarray
    kind: np.ndarray
    color: np.ndarray
    grounded: np.ndarray
    track: np.ndarray
    facing: np.ndarray | None = None

    def __post_init__(self) -> None:
        n = len(self.lo)
        if self.facing is None:
            object.__setattr__(self, "facing", np.zeros(n, np.int8))
        for name in ("hi", "cls", "kind", "color", "grounded", "track", "facing"):
            if len(getattr(self, name)) != n:
                raise ValueError(f"Boxes.{name} has {len(getattr(self, name))} rows, expected {n}")
        if n and not np.all(self.hi > self.lo):
            raise ValueError("every box needs hi > lo on all three axes")

    def __len__(self) -> int:
        return len(self.lo)

    @property
    def fronts(self) -> np.ndarray:
        """``facing`` as made: never None once the boxes exist (no front is 0)."""
        return self.facing if self.facing is not None else np.zeros(len(self), np.int8)

    @classmethod
    def empty(cls) -> Boxes:
        return cls(np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0, np.uint8), np.zeros(0, np.uint8),
                   np.zeros((0, 3), np.float32), np.zeros(0, bool), np.zeros(0, np.int32))

    @classmethod
    def make(cls, lo, hi, sem_cls, kind, color, grounded=None, track=None, facing=0) -> Boxes:
        """Build from per-box values; scalars broadcast over all boxes. ``grounded`` defaults to the
        boxes whose bottom is on the road: the road under a raised part (a car's body, a tree's
        crown) is seen past it, so only what touches the road hides the road under it."""
        lo = np.atleast_2d(np.asarray(lo, dtype=np.float64))
        if grounded is None:
            grounded = lo[:, 2] <= GROUND_EPS_M
        hi = np.atleast_2d(np.asarray(hi, dtype=np.float64))
        n = len(lo)
        color = np.broadcast_to(np.asarray(color, np.float32), (n, 3)).copy()
        track = np.arange(n, dtype=np.int32) if track is None else np.asarray(track, np.int32)
        return cls(lo, hi,
                   np.broadcast_to(np.asarray(sem_cls, np.uint8), (n,)).copy(),
                   np.broadcast_to(np.asarray(kind, np.uint8), (n,)).copy(),
                   color, np.broadcast_to(np.asarray(grounded, bool), (n,)).copy(),
                   np.broadcast_to(track, (n,)).copy(),
                   np.broadcast_to(np.asarray(facing, np.int8), (n,)).copy())

    FIELDS = ("lo", "hi", "cls", "kind", "color", "grounded", "track", "facing")

    def replace(self, **changes) -> Boxes:
        """A copy with some columns replaced."""
        return Boxes(**{f: changes.get(f, getattr(self, f)) for f in Boxes.FIELDS})

    @staticmethod
    def concat(parts: list[Boxes]) -> Boxes:
        parts = [p for p in parts if len(p)]
        if not parts:
            return Boxes.empty()
        return Boxes(*(np.concatenate([getattr(p, f) for p in parts]) for f in Boxes.FIELDS))

    def take(self, idx: np.ndarray) -> Boxes:
        return Boxes(*(getattr(self, f)[idx] for f in Boxes.FIELDS))

    def corners(self) -> np.ndarray:
        """``[N, 8, 3]`` world corners."""
        sel = np.array([[i & 1, (i >> 1) & 1, (i >> 2) & 1] for i in range(8)], dtype=bool)
        return np.where(sel[None], self.hi[:, None, :], self.lo[:, None, :])

    def to_array(self) -> np.ndarray:
        """``[N, 8]`` float32 rows ``trainId, xmin, ymin, zmin, xmax, ymax, zmax, track``."""
        return np.concatenate([self.cls[:, None], self.lo, self.hi, self.track[:, None]],
                              axis=1).astype(np.float32)


@dataclass(frozen=True)
class Agents:
    """Boxes that move in a straight line along a world axis at constant speed.

    ``boxes`` holds their pose at t = 0; ``velocity`` is ``[N, 2]`` m/s in x and y (one of the
    two is zero); positions wrap inside ``[wrap_lo, wrap_hi]`` along the axis of motion so the
    traffic density stays constant for any clip length. ``anchor`` ``[N, 2]`` is the x-y centre
    of the object each box belongs to: the object wraps as one, so its parts never separate.
    """

    boxes: Boxes
    velocity: np.ndarray
    wrap_lo: np.ndarray
    wrap_hi: np.ndarray
    anchor: np.ndarray | None = None

    def __post_init__(self) -> None:
        if self.anchor is None:
            object.__setattr__(self, "anchor", 0.5 * (self.boxes.lo[:, :2] + self.boxes.hi[:, :2]))

    def __len__(self) -> int:
        return len(self.boxes)

    @classmethod
    def empty(cls) -> Agents:
        return cls(Boxes.empty(), np.zeros((0, 2)), np.zeros(0), np.zeros(0))

    @classmethod
    def moving(cls, boxes: Boxes, velocity, wrap_lo: float, wrap_hi: float) -> Agents:
        """One object (all of ``boxes``) moving as one at ``velocity`` (x, y m/s), wrapping in
        ``[wrap_lo, wrap_hi]``, anchored at the mean centre of its parts."""
        n = len(boxes)
        anchor = 0.5 * (boxes.lo[:, :2] + boxes.hi[:, :2]).mean(axis=0)
        return cls(boxes, np.tile(np.asarray(velocity, np.float64), (n, 1)), np.full(n, float(wrap_lo)),
                   np.full(n, float(wrap_hi)), np.tile(anchor, (n, 1)))

    @staticmethod
    def concat(parts: list[Agents]) -> Agents:
        parts = [p for p in parts if len(p)]
        if not parts:
            return Agents.empty()
        velocity, wrap_lo, wrap_hi, anchor = (np.concatenate([getattr(p, f) for p in parts])
                                              for f in ("velocity", "wrap_lo", "wrap_hi", "anchor"))
        return Agents(Boxes.concat([p.boxes for p in parts]), velocity, wrap_lo, wrap_hi, anchor)

    @property
    def anchors(self) -> np.ndarray:
        """``anchor`` as made: never None once the agents exist (each box its own object by default)."""
        return self.anchor if self.anchor is not None else 0.5 * (self.boxes.lo[:, :2] + self.boxes.hi[:, :2])

    def take(self, idx: np.ndarray) -> Agents:
        return Agents(self.boxes.take(idx), self.velocity[idx], self.wrap_lo[idx], self.wrap_hi[idx],
                      self.anchors[idx])

    def centres_at(self, t: np.ndarray | float) -> np.ndarray:
        """``[N, T, 2]`` x-y centres of the boxes at the times ``t`` (seconds)."""
        t = np.atleast_1d(np.asarray(t, dtype=np.float64))
        c0 = 0.5 * (self.boxes.lo[:, :2] + self.boxes.hi[:, :2])
        a = self.anchors[:, None, :] + self.velocity[:, None, :] * t[None, :, None]
        axis = np.abs(self.velocity).argmax(axis=1)
        span = (self.wrap_hi - self.wrap_lo)[:, None]
        rows = np.arange(len(self))
        along = a[rows, :, axis]
        a[rows, :, axis] = self.wrap_lo[:, None] + np.mod(along - self.wrap_lo[:, None], span)
        return a + (c0 - self.anchor)[:, None, :]

    def at(self, t: float) -> Boxes:
        """Their boxes at time ``t``."""
        if not len(self):
            return Boxes.empty()
        c0 = 0.5 * (self.boxes.lo[:, :2] + self.boxes.hi[:, :2])
        shift = self.centres_at(t)[:, 0, :] - c0
        lo = self.boxes.lo.copy()
        hi = self.boxes.hi.copy()
        lo[:, :2] += shift
        hi[:, :2] += shift
        return self.boxes.replace(lo=lo, hi=hi)
