"""Cast shadows, contact shadows and night lights, as top-down maps of the ground around the camera.

Every box casts a shadow on the ground: for a sun direction ``s`` (towards the sun, ``s_z > 0``)
the shadow of a box on ``z = 0`` is the convex hull of its corners moved along ``-s`` down to the
ground. The hulls are drawn into a map of the ground around the camera; each cell keeps the
tallest box whose shadow covers it (its top, and its object's track). A ground point is in shadow
where any hull covers it; a point on an object at height ``z`` is in shadow where the cell below it
along the sun's ray holds another object taller than ``z`` (the tallest-occluder approximation:
shading only, never geometry). Contact shadows darken the ground around the footprints of vehicles
and people; at night, street lights and headlights add pools of light in a third map.

The static part of the maps is drawn once per window and reused while the camera stays inside it.
"""

from __future__ import annotations

import cv2
import numpy as np

from bsn_edge.synth.boxes import FACING_AXES, KIND_POLE, KIND_VEHICLE, Boxes

RES = 0.125          # metres per map cell
HALF = 110.0         # the map covers the camera's position +- this, metres
REUSE = 30.0         # the static part is redrawn when the camera enters another cell of this size
SHIFT = 2            # sub-cell precision of the polygon corners, bits
AO_STEPS = ((0.45, 70), (0.25, 140), (0.06, 210))   # (margin m, darkness 0-255): stepped, then sampled bilinearly
LAMP_RADII = ((9.0, 40), (6.0, 90), (3.5, 150), (1.8, 210))   # street-light pool: (radius m, light 0-255)
HEADLIGHT_REACH = (30.0, 18.0, 9.0)                           # beam lengths, metres
HEADLIGHT_LEVEL = (60, 120, 190)
REMAP_COLS = 1024
# Corner order of a shadow hexagon, by the quadrant of the sweep (dx < 0) + 2 (dy < 0); corners
# 0-3 are the bottom's shadow (x0y0, x1y0, x1y1, x0y1), 4-7 the top's.
HEX_ORDER = np.array([[0, 1, 5, 6, 7, 3], [0, 1, 2, 6, 7, 4], [0, 4, 5, 6, 2, 3], [4, 5, 1, 2, 3, 7]])


class GroundMaps:
    """Shadow, contact-shadow and light maps of the ground around one camera position."""

    def __init__(self, sun: tuple[float, float, float], night: bool) -> None:
        s = np.asarray(sun, np.float64)
        self.shadows = s[2] > 0.05
        self.sun = s / np.linalg.norm(s)
        self.night = night
        n = round(2 * HALF / RES)
        self.n = n
        self._static_key: tuple | None = None
        self._static: tuple[np.ndarray, ...] | None = None
        self.origin = np.zeros(2)
        self.occ = np.zeros((n, n), np.uint8)
        self.ao = np.zeros((n, n), np.uint8)
        self.light = np.zeros((n, n), np.uint8)
        self.top: np.ndarray | None = None     # the static objects' tops and owners, once drawn
        self.owner: np.ndarray | None = None

    # -- drawing ------------------------------------------------------------------------------
    def _px(self, xy: np.ndarray, origin: np.ndarray) -> np.ndarray:
        return np.round((xy - origin) * ((1 << SHIFT) / RES)).astype(np.int32)

    def _hexagons(self, lo: np.ndarray, hi: np.ndarray, origin: np.ndarray) -> np.ndarray:
        """``[N, 6, 2]`` shadow outlines (map pixels, sub-cell bits): each box's footprint swept along
        the sun's ray from its bottom's shadow to its top's, i.e. the hull of its eight corners."""
        k = -self.sun[:2] / self.sun[2]
        t0 = lo[:, 2:3] * k
        d = (hi[:, 2:3] - lo[:, 2:3]) * k
        rect = np.stack([lo[:, :2], np.stack([hi[:, 0], lo[:, 1]], 1), hi[:, :2],
                         np.stack([lo[:, 0], hi[:, 1]], 1)], 1) + t0[:, None, :]
        pts = np.concatenate([rect, rect + d[:, None, :]], 1)             # [N, 8, 2]
        quadrant = (d[:, 0] < 0).astype(int) + 2 * (d[:, 1] < 0)
        idx = HEX_ORDER[quadrant]                                         # [N, 6]
        hexes = np.take_along_axis(pts, idx[..., None], 1)
        return self._px(hexes, origin)

    def _draw_static(self, boxes: Boxes, origin: np.ndarray) -> tuple[np.ndarray, ...]:
        n = self.n
        top, owner = np.zeros((n, n), np.uint8), np.zeros((n, n), np.uint16)
        occ, ao, light = np.zeros((n, n), np.uint8), np.zeros((n, n), np.uint8), np.zeros((n, n), np.uint8)
        lo, hi, track = _per_object(boxes)
        if self.shadows and len(lo):
            order = np.argsort(hi[:, 2], kind="stable")      # taller last: each cell keeps the tallest
            hexes = self._hexagons(lo[order], hi[order], origin)
            tops = np.minimum(255, hi[order, 2] * 10).astype(int)
            for h, val, tr in zip(hexes, tops, track[order], strict=True):
                cv2.fillConvexPoly(top, h, int(val), cv2.LINE_8, SHIFT)
                cv2.fillConvexPoly(owner, h, int(tr) & 0xFFFF, cv2.LINE_8, SHIFT)
            occ[top > 0] = 255
        self._draw_contact(ao, lo, hi, origin)
        if self.night:
            poles = np.flatnonzero(boxes.kind == KIND_POLE)
            centres = self._px(0.5 * (boxes.lo[poles, :2] + boxes.hi[poles, :2]), origin)
            for radius, val in LAMP_RADII:
                r = int(radius / RES * (1 << SHIFT))
                for c in centres:
                    cv2.circle(light, (int(c[0]), int(c[1])), r, val, -1, cv2.LINE_8, SHIFT)
            self._draw_beams(light, boxes, origin)
        return top, owner, occ, ao, light

    def _draw_contact(self, ao: np.ndarray, lo: np.ndarray, hi: np.ndarray, origin: np.ndarray) -> None:
        size = hi - lo
        near_ground = (lo[:, 2] < 0.6) & (size[:, 2] < 5.0) & (size[:, 0] * size[:, 1] < 150.0)
        lo, hi = lo[near_ground, :2], hi[near_ground, :2]
        for margin, val in AO_STEPS:
            a, b = lo - margin, hi + margin
            rects = np.stack([a, np.stack([b[:, 0], a[:, 1]], 1), b, np.stack([a[:, 0], b[:, 1]], 1)], 1)
            if len(rects):
                cv2.fillPoly(ao, list(self._px(rects, origin)), val, cv2.LINE_8, SHIFT)

    def _draw_beams(self, light: np.ndarray, boxes: Boxes, origin: np.ndarray) -> None:
        for k in np.flatnonzero((boxes.kind == KIND_VEHICLE) & (boxes.fronts != 0)):
            axis, sign = FACING_AXES[int(boxes.fronts[k])]
            front = 0.5 * (boxes.lo[k, :2] + boxes.hi[k, :2])
            front[axis] = boxes.hi[k, axis] if sign > 0 else boxes.lo[k, axis]
            fwd = np.zeros(2)
            fwd[axis] = sign
            self._beam(light, origin, front, fwd)

    def _beam(self, light: np.ndarray, origin: np.ndarray, at: np.ndarray, fwd: np.ndarray) -> None:
        side = np.array([-fwd[1], fwd[0]])
        for reach, val in zip(HEADLIGHT_REACH, HEADLIGHT_LEVEL, strict=True):
            tri = np.stack([at + side * 0.8, at - side * 0.8,
                            at + fwd * reach - side * reach * 0.3, at + fwd * reach + side * reach * 0.3])
            cv2.fillConvexPoly(light, self._px(tri, origin), val, cv2.LINE_8, SHIFT)

    def update(self, static: Boxes, moving: Boxes, camera_xy: np.ndarray,
               ego_forward: np.ndarray | None = None) -> None:
        """Draw the maps for a camera at ``camera_xy`` (static part reused while it stays near).

        Moving objects cast shadows on the ground and darken it where they stand; only static
        objects shade other objects."""
        centre = np.asarray(camera_xy, np.float64)
        # the window depends on the position alone (not on the frames before), so frames can be
        # rendered in any order or in several processes and come out the same
        origin = (np.floor(centre / REUSE) + 0.5) * REUSE - HALF
        drawn = self._static
        if drawn is None or self._static_key != tuple(origin):
            drawn = self._static = self._draw_static(_near(static, origin + HALF, HALF + 60.0), origin)
            self._static_key, self.origin = tuple(origin), origin
            self.top, self.owner = drawn[0], drawn[1]
        _, _, occ, ao, light = drawn
        np.copyto(self.occ, occ)
        np.copyto(self.ao, ao)
        moving = _near(moving, self.origin + HALF, HALF + 30.0)
        lo, hi, _ = _per_object(moving)
        if self.shadows and len(lo):
            cv2.fillPoly(self.occ, list(self._hexagons(lo, hi, self.origin)), 255, cv2.LINE_8, SHIFT)
        self._draw_contact(self.ao, lo, hi, self.origin)
        if self.night:
            np.copyto(self.light, light)
            self._draw_beams(self.light, moving, self.origin)
            if ego_forward is not None:
                fwd = np.asarray(ego_forward, np.float64)
                self._beam(self.light, self.origin, centre + fwd, fwd)

    # -- sampling -----------------------------------------------------------------------------
    def _cells(self, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        u = ((x - self.origin[0]) / RES - 0.5).astype(np.float32)
        return u, ((y - self.origin[1]) / RES - 0.5).astype(np.float32)

    def _bilinear(self, m: np.ndarray, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        u, v = self._cells(x, y)
        n = len(u)
        rows = -(-n // REMAP_COLS)
        pad = rows * REMAP_COLS - n     # remap wants 2-D maps under 32767 on a side
        uu = np.pad(u, (0, pad)).reshape(rows, REMAP_COLS)
        vv = np.pad(v, (0, pad)).reshape(rows, REMAP_COLS)
        out = cv2.remap(m, uu, vv, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=0)
        return out.reshape(-1)[:n].astype(np.float32) * np.float32(1 / 255)

    def ground_light(self, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
        """At ground points: sun visibility (0 shadow - 1 lit), contact darkness and night light, 0-1 (None by
        day)."""
        lit = 1.0 - self._bilinear(self.occ, x, y) if self.shadows else np.ones(x.shape, np.float32)
        return lit, self._bilinear(self.ao, x, y), self._bilinear(self.light, x, y) if self.night else None

    def object_lit(self, x: np.ndarray, y: np.ndarray, z: np.ndarray, track: np.ndarray) -> np.ndarray:
        """1 where an object point at ``(x, y, z)`` sees the sun past other objects, else 0."""
        if not self.shadows or self.top is None or self.owner is None:
            return np.ones(x.shape, np.float32)      # no sun, or nothing drawn yet to cast a shadow
        t = z / self.sun[2]
        u, v = self._cells(x - self.sun[0] * t, y - self.sun[1] * t)
        iu = np.clip(np.rint(u).astype(np.int32), 0, self.n - 1)
        iv = np.clip(np.rint(v).astype(np.int32), 0, self.n - 1)
        inside = (u >= 0) & (u < self.n) & (v >= 0) & (v < self.n)
        top = self.top[iv, iu].astype(np.float32) * np.float32(0.1)
        other = self.owner[iv, iu] != (track & 0xFFFF).astype(np.uint16)
        return np.where(inside & other & (top > z + 0.05), np.float32(0.0), np.float32(1.0))

    def object_light(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """Night light reaching object points from the pools on the ground below them."""
        return self._bilinear(self.light, x, y)


def _per_object(boxes: Boxes) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """One bounding box per object (consecutive boxes of one track): ``lo``, ``hi``, ``track``."""
    if not len(boxes):
        return np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0, np.int32)
    starts = np.flatnonzero(np.r_[True, np.diff(boxes.track) != 0])
    return (np.minimum.reduceat(boxes.lo, starts, axis=0), np.maximum.reduceat(boxes.hi, starts, axis=0),
            boxes.track[starts])


def _near(boxes: Boxes, centre: np.ndarray, radius: float) -> Boxes:
    if not len(boxes):
        return boxes
    lo, hi = boxes.lo[:, :2], boxes.hi[:, :2]
    gap = np.maximum(np.maximum(lo - centre, centre - hi), 0.0)
    return boxes.take(np.flatnonzero(gap.max(axis=1) < radius))

