"""Procedural generation of a world and an ego route from a style and a seed."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from bsn_edge import semantics as sm
from bsn_edge.synth.boxes import (
    KIND_BUILDING,
    KIND_CROWN,
    KIND_PERSON,
    KIND_POLE,
    KIND_TRUNK,
    KIND_VEHICLE,
    Agents,
    Boxes,
)
from bsn_edge.synth.config import SynthConfig
from bsn_edge.synth.layout import RoadLayout
from bsn_edge.synth.route import Route, build_route
from bsn_edge.synth.style import Style, get_style
from bsn_edge.synth.world import Look, World

MARGIN = 160.0          # objects exist this far around the route
INTERSECTION_CLEAR = 6.0  # no parked vehicle this close to a crossing's carriageway
EGO_CLEARANCE = 3.0     # moving objects keep this far from the ego footprint, metres

FACADES = np.array([(0.55, 0.62, 0.70), (0.45, 0.50, 0.62), (0.62, 0.66, 0.68), (0.40, 0.42, 0.48),
                    (0.70, 0.74, 0.78), (0.38, 0.45, 0.55), (0.55, 0.55, 0.52), (0.30, 0.35, 0.50)])
CAR_PAINT = np.array([(0.85, 0.85, 0.85), (0.12, 0.12, 0.12), (0.55, 0.55, 0.55), (0.15, 0.15, 0.65),
                      (0.60, 0.25, 0.10), (0.20, 0.50, 0.20), (0.10, 0.60, 0.85), (0.70, 0.70, 0.65)])
CLOTHES = np.array([(0.20, 0.15, 0.12), (0.55, 0.30, 0.20), (0.15, 0.15, 0.55), (0.70, 0.70, 0.70),
                    (0.20, 0.45, 0.20), (0.10, 0.10, 0.10)])


@dataclass(frozen=True)
class Scenario:
    """A generated world with the ego's route and speed."""

    world: World
    route: Route
    speed: float
    start_s: float


def _grid(rng: np.random.Generator, style: Style, extent: float, lane_w: float, park_w: float,
          sw: float) -> tuple[np.ndarray, np.ndarray]:
    pos, lanes = [0.0], [style.lanes_main if rng.random() < style.main_road_prob else style.lanes_side]
    while pos[-1] < extent:
        ln = style.lanes_main if rng.random() < style.main_road_prob else style.lanes_side
        gap = rng.uniform(*style.block) + 2 * sw + (lanes[-1] + ln) * lane_w + 2 * park_w
        pos.append(pos[-1] + gap)
        lanes.append(ln)
    p = np.array(pos) - extent / 2
    return p, np.array(lanes)


def _colors(rng: np.random.Generator, palette: np.ndarray, n: int, jitter: float) -> np.ndarray:
    c = palette[rng.integers(0, len(palette), n)] + rng.normal(0, jitter, (n, 3))
    return np.clip(c, 0.03, 1.0).astype(np.float32)


def _buildings(rng, style: Style, layout: RoadLayout, bounds) -> Boxes:
    xs, ys = layout.xs, layout.ys
    hwx, hwy = layout.hw_x, layout.hw_y
    sw = layout.sidewalk_width
    lo_all, hi_all = [], []
    for i in range(len(xs) - 1):
        for j in range(len(ys) - 1):
            x0 = xs[i] + hwx[i] + sw + rng.uniform(*style.setback)
            x1 = xs[i + 1] - hwx[i + 1] - sw - rng.uniform(*style.setback)
            y0 = ys[j] + hwy[j] + sw + rng.uniform(*style.setback)
            y1 = ys[j + 1] - hwy[j + 1] - sw - rng.uniform(*style.setback)
            if x1 < bounds[0] or x0 > bounds[2] or y1 < bounds[1] or y0 > bounds[3]:
                continue
            dmax = style.building_depth[1]
            # south and north rows span the block; west and east rows fill between them
            for axis, a0, a1, b0, b1, flip in (
                (0, x0, x1, y0, y1, False), (0, x0, x1, y0, y1, True),
                (1, y0 + dmax, y1 - dmax, x0, x1, False), (1, y0 + dmax, y1 - dmax, x0, x1, True),
            ):
                cur = a0 + (rng.uniform(*style.gap_small) if style.setback[0] > 0 else 0.0)
                while cur < a1 - 4.0:
                    w = min(rng.uniform(*style.building_width), a1 - cur)
                    d = min(rng.uniform(*style.building_depth), (b1 - b0) / 2)
                    h = rng.uniform(*style.building_height)
                    c0, c1 = (b1 - d, b1) if flip else (b0, b0 + d)
                    if axis == 0:
                        lo_all.append((cur, c0, 0.0))
                        hi_all.append((cur + w, c1, h))
                    else:
                        lo_all.append((c0, cur, 0.0))
                        hi_all.append((c1, cur + w, h))
                    gap = style.gap_large if rng.random() < style.gap_large_prob else style.gap_small
                    cur += w + rng.uniform(*gap)
    n = len(lo_all)
    return Boxes.make(lo_all, hi_all, sm.BUILDING, KIND_BUILDING,
                      _colors(rng, FACADES, n, 0.05), True)


def _segments(layout: RoadLayout, bounds):
    """Straight stretches of road between intersections: (axis, centre, lanes, a0, a1)."""
    out = []
    for axis, centres, lanes_of, cross, cross_hw in (
        (1, layout.xs, layout.lanes_x, layout.ys, layout.hw_y),
        (0, layout.ys, layout.lanes_y, layout.xs, layout.hw_x),
    ):
        lo_b, hi_b = (bounds[0], bounds[2]) if axis == 1 else (bounds[1], bounds[3])
        a_lo, a_hi = (bounds[1], bounds[3]) if axis == 1 else (bounds[0], bounds[2])
        for c, ln in zip(centres, lanes_of, strict=True):
            if not lo_b <= c <= hi_b:
                continue
            for m in range(len(cross) - 1):
                a0 = cross[m] + cross_hw[m] + layout.sidewalk_width
                a1 = cross[m + 1] - cross_hw[m + 1] - layout.sidewalk_width
                if a1 > a_lo and a0 < a_hi:
                    out.append((axis, float(c), int(ln), float(a0), float(a1)))
    return out


def _vehicle_dims(rng, n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Length, width, height, trainId of n vehicles (mostly cars, some vans and trucks)."""
    big = rng.random(n) < 0.15
    length = np.where(big, rng.uniform(5.5, 7.5, n), rng.uniform(3.9, 4.9, n))
    width = np.where(big, rng.uniform(2.0, 2.4, n), rng.uniform(1.7, 1.9, n))
    height = np.where(big, rng.uniform(2.2, 3.2, n), rng.uniform(1.4, 1.65, n))
    return length, width, height, np.where(big, sm.TRUCK, sm.CAR).astype(np.uint8)


def _oriented(axis: int, across: float, along: float, length, width, height):
    """Box corners of a vehicle or person centred at (across, along) on a road along ``axis``."""
    if axis == 1:
        return (across - width / 2, along - length / 2, 0.0), (across + width / 2, along + length / 2, height)
    return (along - length / 2, across - width / 2, 0.0), (along + length / 2, across + width / 2, height)


def _parked(rng, style: Style, layout: RoadLayout, bounds, density: float) -> Boxes:
    lo_all, hi_all, cls_all = [], [], []
    for axis, c, lanes, a0, a1 in _segments(layout, bounds):
        off = lanes * layout.lane_width + layout.parking_width / 2
        for side in (-1.0, 1.0):
            cur = a0 + INTERSECTION_CLEAR
            while cur < a1 - INTERSECTION_CLEAR - 5.0:
                if rng.random() < style.parked_density * density:
                    ln, wd, ht, cl = (v[0] for v in _vehicle_dims(rng, 1))
                    if cur + ln > a1 - INTERSECTION_CLEAR:
                        break
                    across = c + side * (off + rng.uniform(-0.15, 0.15))
                    lo, hi = _oriented(axis, across, cur + ln / 2, ln, wd, ht)
                    lo_all.append(lo)
                    hi_all.append(hi)
                    cls_all.append(cl)
                    cur += ln + rng.uniform(0.8, 2.5)
                else:
                    cur += rng.uniform(3.0, 8.0)
    n = len(lo_all)
    return Boxes.make(np.reshape(lo_all, (n, 3)), np.reshape(hi_all, (n, 3)), np.array(cls_all, np.uint8),
                      KIND_VEHICLE, _colors(rng, CAR_PAINT, n, 0.04), True)


def _street_furniture(rng, style: Style, layout: RoadLayout, bounds) -> Boxes:
    """Poles at the curb and trees (trunk + crown) along the sidewalks and lawns."""
    poles_lo, poles_hi, trunks_lo, trunks_hi, crowns_lo, crowns_hi = [], [], [], [], [], []
    for axis, c, lanes, a0, a1 in _segments(layout, bounds):
        hw = lanes * layout.lane_width + layout.parking_width
        for side in (-1.0, 1.0):
            cur = a0 + rng.uniform(2.0, 10.0)
            while cur < a1 - 2.0:
                across = c + side * (hw + 0.45)
                lo, hi = _oriented(axis, across, cur, 0.22, 0.22, rng.uniform(6.0, 8.0))
                poles_lo.append(lo)
                poles_hi.append(hi)
                cur += rng.uniform(25.0, 35.0)
            cur = a0 + rng.uniform(2.0, style.tree_spacing)
            while cur < a1 - 2.0:
                if rng.random() < style.tree_prob:
                    across = c + side * (hw + layout.sidewalk_width - 0.6 + rng.uniform(0, 2.0))
                    h_trunk = rng.uniform(2.2, 3.2)
                    lo, hi = _oriented(axis, across, cur, 0.35, 0.35, h_trunk)
                    trunks_lo.append(lo)
                    trunks_hi.append(hi)
                    r = rng.uniform(1.3, 2.4)
                    lo, hi = _oriented(axis, across, cur, 2 * r, 2 * r, h_trunk + rng.uniform(2.5, 4.5))
                    crowns_lo.append((lo[0], lo[1], h_trunk - 0.3))
                    crowns_hi.append(hi)
                cur += style.tree_spacing * rng.uniform(0.7, 1.3)
    def mk(lo, hi, cls, kind, color, grounded):
        n = len(lo)
        col = np.clip(np.asarray(color) + rng.normal(0, 0.04, (n, 3)), 0, 1).astype(np.float32)
        return Boxes.make(np.reshape(lo, (n, 3)), np.reshape(hi, (n, 3)), cls, kind, col, grounded)
    return Boxes.concat([
        mk(poles_lo, poles_hi, sm.POLE, KIND_POLE, (0.45, 0.47, 0.48), True),
        mk(trunks_lo, trunks_hi, sm.VEGETATION, KIND_TRUNK, (0.12, 0.22, 0.30), True),
        mk(crowns_lo, crowns_hi, sm.VEGETATION, KIND_CROWN, (0.15, 0.42, 0.22), False),
    ])


def _agents(rng, style: Style, layout: RoadLayout, bounds, traffic: float, pedestrians: float) -> Agents:
    lo_all, hi_all, cls_all, kind_all, vel, wlo, whi, colors = [], [], [], [], [], [], [], []
    for axis, centres, lanes_of in ((1, layout.xs, layout.lanes_x), (0, layout.ys, layout.lanes_y)):
        lo_b, hi_b = (bounds[0], bounds[2]) if axis == 1 else (bounds[1], bounds[3])
        a_lo, a_hi = (bounds[1], bounds[3]) if axis == 1 else (bounds[0], bounds[2])
        span = a_hi - a_lo
        for c, lanes in zip(centres, lanes_of, strict=True):
            if not lo_b <= c <= hi_b:
                continue
            for direction in (-1.0, 1.0):
                # right-hand traffic: moving +along puts you on the side of +across for roads along y
                side = direction if axis == 1 else -direction
                for lane in range(int(lanes)):
                    n = rng.poisson(style.traffic_per_100m * traffic * span / 100.0)
                    if not n:
                        continue
                    speed = rng.uniform(*style.traffic_speed)
                    ln, wd, ht, cl = _vehicle_dims(rng, n)
                    along = a_lo + (np.sort(rng.random(n)) + rng.random()) % 1.0 * span
                    across = c + side * (lane + 0.5) * layout.lane_width
                    for k in range(n):
                        lo, hi = _oriented(axis, across, along[k], ln[k], wd[k], ht[k])
                        lo_all.append(lo)
                        hi_all.append(hi)
                        cls_all.append(cl[k])
                        kind_all.append(KIND_VEHICLE)
                        v = [0.0, 0.0]
                        v[axis] = direction * speed
                        vel.append(v)
                        wlo.append(a_lo)
                        whi.append(a_hi)
                    colors.append(_colors(rng, CAR_PAINT, n, 0.04))
                hw = lanes * layout.lane_width + layout.parking_width
                n = rng.poisson(style.pedestrians_per_100m * pedestrians * span / 100.0)
                for _ in range(n):
                    across = c + side * (hw + layout.sidewalk_width * rng.uniform(0.3, 0.75))
                    along = rng.uniform(a_lo, a_hi)
                    h = rng.uniform(1.55, 1.9)
                    lo, hi = _oriented(axis, across, along, 0.35, 0.5, h)
                    lo_all.append(lo)
                    hi_all.append(hi)
                    cls_all.append(sm.PERSON)
                    kind_all.append(KIND_PERSON)
                    v = [0.0, 0.0]
                    v[axis] = rng.choice([-1.0, 1.0]) * rng.uniform(0.9, 1.6)
                    vel.append(v)
                    wlo.append(a_lo)
                    whi.append(a_hi)
                    colors.append(_colors(rng, CLOTHES, 1, 0.05))
    n = len(lo_all)
    if not n:
        return Agents.empty()
    boxes = Boxes.make(np.reshape(lo_all, (n, 3)), np.reshape(hi_all, (n, 3)), np.array(cls_all, np.uint8),
                       np.array(kind_all, np.uint8), np.concatenate(colors), True)
    return Agents(boxes, np.array(vel), np.array(wlo), np.array(whi))


def _clear_of_ego(rng, agents: Agents, ego_xy: np.ndarray, times: np.ndarray, tries: int = 8) -> Agents:
    """Re-phase agents that would touch the ego car during the clip; drop those that still do."""
    if not len(agents):
        return agents
    boxes = agents.boxes
    half = 0.5 * (boxes.hi[:, :2] - boxes.lo[:, :2])
    radius = np.linalg.norm(half, axis=1) + EGO_CLEARANCE
    ok = np.zeros(len(agents), bool)
    lo, hi = boxes.lo.copy(), boxes.hi.copy()
    for _ in range(tries):
        cur = Agents(Boxes(lo, hi, boxes.cls, boxes.kind, boxes.color, boxes.grounded, boxes.track),
                     agents.velocity, agents.wrap_lo, agents.wrap_hi)
        c = cur.centres_at(times)
        dist = np.linalg.norm(c - ego_xy[None], axis=2).min(axis=1)
        good = dist > radius
        ok |= good
        bad = ~ok
        if not bad.any():
            break
        axis = np.abs(agents.velocity[bad]).argmax(axis=1)
        shift = rng.uniform(10.0, 60.0, bad.sum()) * rng.choice([-1.0, 1.0], bad.sum())
        rows = np.where(bad)[0]
        lo[rows, axis] += shift
        hi[rows, axis] += shift
    keep = np.where(ok)[0]
    final = Boxes(lo, hi, boxes.cls, boxes.kind, boxes.color, boxes.grounded, boxes.track).take(keep)
    return Agents(final, agents.velocity[keep], agents.wrap_lo[keep], agents.wrap_hi[keep])


def build_scenario(cfg: SynthConfig) -> Scenario:
    """Generate the world and the ego's route for ``cfg`` (deterministic in ``cfg.seed``)."""
    style = get_style(cfg.style)
    rng = np.random.default_rng([cfg.seed, 0x6273_6E])
    speed = float(rng.uniform(*style.ego_speed))
    length = cfg.frames / cfg.fps * speed + 1.0
    extent = 2 * length + 4 * MARGIN
    lw, pw, sw = style.lane_width, style.parking_width, style.sidewalk_width
    xs, lanes_x = _grid(rng, style, extent, lw, pw, sw)
    ys, lanes_y = _grid(rng, style, extent, lw, pw, sw)
    layout = RoadLayout(xs, lanes_x, ys, lanes_y, lw, pw, sw)
    route = build_route(layout, length, rng)
    times = np.arange(cfg.frames) / cfg.fps
    ego_xy, _ = route.at(times * speed)
    bounds = (ego_xy[:, 0].min() - MARGIN, ego_xy[:, 1].min() - MARGIN,
              ego_xy[:, 0].max() + MARGIN, ego_xy[:, 1].max() + MARGIN)
    static = Boxes.concat([
        _buildings(rng, style, layout, bounds),
        _parked(rng, style, layout, bounds, cfg.parked),
        _street_furniture(rng, style, layout, bounds),
    ])
    agents = _agents(rng, style, layout, bounds, cfg.traffic, cfg.pedestrians)
    agents = _clear_of_ego(rng, agents, ego_xy, times)
    # stable ids: static first, then agents
    static = Boxes(static.lo, static.hi, static.cls, static.kind, static.color, static.grounded,
                   np.arange(len(static), dtype=np.int32))
    ab = agents.boxes
    agents = Agents(Boxes(ab.lo, ab.hi, ab.cls, ab.kind, ab.color, ab.grounded,
                          np.arange(len(static), len(static) + len(ab), dtype=np.int32)),
                    agents.velocity, agents.wrap_lo, agents.wrap_hi)
    look = Look.random(rng, style.fog_distance)
    return Scenario(World(layout, static, agents, look), route, speed, 0.0)
