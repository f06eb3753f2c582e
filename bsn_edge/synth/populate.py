"""Procedural generation of a world and an ego route from a style and a seed."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from bsn_edge import semantics as sm
from bsn_edge.synth.boxes import (
    KIND_BARRIER,
    KIND_BUILDING,
    KIND_CROWN,
    KIND_FENCE,
    KIND_HEDGE,
    KIND_HILL,
    KIND_POLE,
    KIND_TRUNK,
    KIND_WALL,
    Agents,
    Boxes,
)
from bsn_edge.synth.config import SynthConfig
from bsn_edge.synth.layout import RoadLayout
from bsn_edge.synth.people import person_parts
from bsn_edge.synth.platoon import clear_of_ego, platoon, traffic_mix
from bsn_edge.synth.route import Route, build_route
from bsn_edge.synth.style import Style, get_style
from bsn_edge.synth.vehicles import PARKED_MIX, Placed, draw_size, draw_types, vehicle_parts
from bsn_edge.synth.world import Look, World

MARGIN = 160.0          # objects exist this far around the route
INTERSECTION_CLEAR = 6.0  # no parked vehicle this close to a crossing's carriageway
# A clip in slow traffic (SynthConfig.queue): the ego creeps behind a platoon at walking pace,
# the way a dashcam spends much of its time in towns, so the car ahead is often within 10 m.
QUEUE_SPEED = (1.5, 4.0)       # the ego's speed in a queue, m/s

FACADES = np.array([(0.55, 0.62, 0.70), (0.45, 0.50, 0.62), (0.62, 0.66, 0.68), (0.40, 0.42, 0.48),
                    (0.70, 0.74, 0.78), (0.38, 0.45, 0.55), (0.55, 0.55, 0.52), (0.30, 0.35, 0.50),
                    (0.25, 0.32, 0.55), (0.80, 0.82, 0.84), (0.50, 0.45, 0.40), (0.35, 0.38, 0.40)])
HEDGE = (0.12, 0.32, 0.16)
FENCE = ((0.55, 0.58, 0.60), (0.25, 0.35, 0.45), (0.15, 0.15, 0.15))
WALL = ((0.60, 0.62, 0.62), (0.35, 0.40, 0.55), (0.72, 0.75, 0.78))
HILL_GREEN = (0.18, 0.36, 0.22)


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
                    if rng.random() >= style.building_prob:
                        cur += w + rng.uniform(*style.gap_large)
                        continue
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


def _parked(rng, style: Style, layout: RoadLayout, bounds, density: float) -> Boxes:
    parts: list[Boxes] = []
    for axis, c, lanes, a0, a1 in _segments(layout, bounds):
        off = lanes * layout.lane_width + layout.parking_width / 2
        for side in (-1.0, 1.0):
            cur = a0 + INTERSECTION_CLEAR
            # right-hand traffic: cars at the curb face the way their side's lanes run
            sign = side if axis == 1 else -side
            while cur < a1 - INTERSECTION_CLEAR - 5.0:
                if rng.random() < style.parked_density * density:
                    vt = draw_types(rng, 1, PARKED_MIX)[0]
                    size = draw_size(rng, vt)
                    if cur + size[0] > a1 - INTERSECTION_CLEAR:
                        break
                    across = c + side * (off + rng.uniform(-0.15, 0.15))
                    at = Placed(axis, across, cur + size[0] / 2, sign)
                    parts.append(vehicle_parts(rng, vt, at, size, len(parts)))
                    cur += size[0] + rng.uniform(0.6, 2.5)
                else:
                    cur += rng.uniform(3.0, 8.0)
    return Boxes.concat(parts)


def _oriented(axis: int, across: float, along: float, length, width, height):
    """Box corners of a thing centred at (across, along) on a road along ``axis``."""
    if axis == 1:
        return (across - width / 2, along - length / 2, 0.0), (across + width / 2, along + length / 2, height)
    return (along - length / 2, across - width / 2, 0.0), (along + length / 2, across + width / 2, height)


class _Parts:
    """Collects boxes of objects, one track id per object."""

    def __init__(self) -> None:
        self.lo: list[Any] = []
        self.hi: list[Any] = []
        self.cls: list[Any] = []
        self.kind: list[Any] = []
        self.color: list[Any] = []
        self.track: list[Any] = []
        self.objects = 0

    def add(self, lo, hi, cls, kind, color, obj=None) -> int:
        """Add one box; a new object unless ``obj`` names one added before. Returns its id."""
        if obj is None:
            obj = self.objects
            self.objects += 1
        self.lo.append(lo)
        self.hi.append(hi)
        self.cls.append(cls)
        self.kind.append(kind)
        self.color.append(color)
        self.track.append(obj)
        return obj

    def boxes(self, rng) -> Boxes:
        n = len(self.lo)
        if not n:
            return Boxes.empty()
        col = np.clip(np.asarray(self.color, np.float64) + rng.normal(0, 0.03, (n, 3)), 0, 1).astype(np.float32)
        return Boxes.make(np.reshape(self.lo, (n, 3)), np.reshape(self.hi, (n, 3)), np.array(self.cls, np.uint8),
                          np.array(self.kind, np.uint8), col, track=np.array(self.track))


def _street_furniture(rng, style: Style, layout: RoadLayout, bounds) -> Boxes:
    """Poles at the curb, trees (trunk and leafy clumps that let the sky through), hedges, fences and
    walls along the lots, and concrete barriers on roads that have them."""
    out = _Parts()
    sw = layout.sidewalk_width
    for axis, c, lanes, a0, a1 in _segments(layout, bounds):
        hw = lanes * layout.lane_width + layout.parking_width
        if style.barriers:
            for a in np.arange(a0 + 2.0, a1 - 2.0, 12.0):
                seg = min(12.0, a1 - 2.0 - a)
                lo, hi = _oriented(axis, c, a + seg / 2, seg, 0.5, 0.85)
                out.add(lo, hi, sm.WALL, KIND_BARRIER, (0.66, 0.68, 0.68))
                for side in (-1.0, 1.0):
                    lo, hi = _oriented(axis, c + side * (hw + 0.5), a + seg / 2, seg, 0.4, 0.8)
                    out.add(lo, hi, sm.WALL, KIND_BARRIER, (0.66, 0.68, 0.68))
        for side in (-1.0, 1.0):
            cur = a0 + rng.uniform(2.0, 10.0)
            while cur < a1 - 2.0:
                across = c + side * (hw + (1.2 if style.barriers else 0.45))
                lo, hi = _oriented(axis, across, cur, 0.22, 0.22, rng.uniform(6.0, 9.0))
                out.add(lo, hi, sm.POLE, KIND_POLE, (0.45, 0.47, 0.48))
                cur += rng.uniform(25.0, 35.0)
            cur = a0 + rng.uniform(2.0, style.tree_spacing)
            while cur < a1 - 2.0:
                if rng.random() < style.tree_prob:
                    across = c + side * (hw + sw - 0.6 + rng.uniform(0, 2.0 + (6.0 if style.verge else 0.0)))
                    h_trunk = rng.uniform(2.0, 3.4)
                    lo, hi = _oriented(axis, across, cur, 0.35, 0.35, h_trunk)
                    tree = out.add(lo, hi, sm.VEGETATION, KIND_TRUNK, (0.12, 0.22, 0.30))
                    r = rng.uniform(1.3, 2.6)
                    green = np.array((0.12, 0.38, 0.2)) + rng.uniform(-0.06, 0.06, 3)
                    for _ in range(int(rng.integers(2, 5))):
                        dr = rng.uniform(0.55, 0.85) * r
                        ca, cb = rng.uniform(-0.6, 0.6, 2) * r
                        z0 = h_trunk - 0.3 + rng.uniform(0, 1.2)
                        lo, hi = _oriented(axis, across + ca, cur + cb, 2 * dr, 2 * dr * rng.uniform(0.8, 1.2),
                                           z0 + rng.uniform(1.5, 3.2))
                        out.add((lo[0], lo[1], z0), hi, sm.VEGETATION, KIND_CROWN, green, obj=tree)
                cur += style.tree_spacing * rng.uniform(0.7, 1.3)
            # lot fronts: a hedge, a fence or a wall at the back of the sidewalk, with gaps for drives
            cur = a0 + 1.0
            edge = hw + sw + 0.35
            while cur < a1 - 3.0:
                run = min(rng.uniform(6.0, 25.0), a1 - 1.0 - cur)
                if run > 1.0 and rng.random() < style.boundary:
                    what = rng.integers(3)
                    if what == 0:
                        lo, hi = _oriented(axis, c + side * edge, cur + run / 2, run, 0.7, rng.uniform(0.8, 1.8))
                        out.add(lo, hi, sm.VEGETATION, KIND_HEDGE, HEDGE)
                    elif what == 1:
                        lo, hi = _oriented(axis, c + side * edge, cur + run / 2, run, 0.08, rng.uniform(1.0, 1.9))
                        out.add(lo, hi, sm.FENCE, KIND_FENCE, FENCE[rng.integers(len(FENCE))])
                    else:
                        lo, hi = _oriented(axis, c + side * edge, cur + run / 2, run, 0.3, rng.uniform(0.6, 2.0))
                        out.add(lo, hi, sm.WALL, KIND_WALL, WALL[rng.integers(len(WALL))])
                cur += run + rng.uniform(2.5, 5.0)
    return out.boxes(rng)


def _horizon(rng, bounds) -> Boxes:
    """Hills and tree lines just outside the populated area, so open roads meet a horizon."""
    out = _Parts()
    x0, y0, x1, y1 = bounds
    for edge in range(4):
        span = (x0, x1) if edge < 2 else (y0, y1)
        cur = span[0] - 60.0
        while cur < span[1] + 60.0:
            w = rng.uniform(40.0, 140.0)
            depth = rng.uniform(20.0, 60.0)
            gap = rng.uniform(5.0, 40.0)
            far = rng.uniform(5.0, 40.0)
            hill = rng.random() < 0.5
            h = rng.uniform(15.0, 45.0) if hill else rng.uniform(8.0, 18.0)
            if edge == 0:
                lo, hi = (cur, y0 - far - depth, 0.0), (cur + w, y0 - far, h)
            elif edge == 1:
                lo, hi = (cur, y1 + far, 0.0), (cur + w, y1 + far + depth, h)
            elif edge == 2:
                lo, hi = (x0 - far - depth, cur, 0.0), (x0 - far, cur + w, h)
            else:
                lo, hi = (x1 + far, cur, 0.0), (x1 + far + depth, cur + w, h)
            colour = np.array(HILL_GREEN) * rng.uniform(0.8, 1.2)
            out.add(lo, hi, sm.TERRAIN if hill else sm.VEGETATION, KIND_HILL, tuple(colour))
            cur += w + gap
    return out.boxes(rng)


def _agents(rng, style: Style, layout: RoadLayout, bounds, traffic: float, pedestrians: float) -> Agents:
    parts: list[Agents] = []     # one per object: its index is the object's track id

    def add(b: Boxes, v, lo, hi) -> None:
        parts.append(Agents.moving(b, v, lo, hi))

    mix = traffic_mix(style)
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
                    along = a_lo + (np.sort(rng.random(n)) + rng.random()) % 1.0 * span
                    across = c + side * (lane + 0.5) * layout.lane_width
                    for k, vt in enumerate(draw_types(rng, n, mix)):
                        at = Placed(axis, across, float(along[k]), direction)
                        v = [0.0, 0.0]
                        v[axis] = direction * speed
                        add(vehicle_parts(rng, vt, at, draw_size(rng, vt), len(parts)), v, a_lo, a_hi)
                hw = lanes * layout.lane_width + layout.parking_width
                n = rng.poisson(style.pedestrians_per_100m * pedestrians * span / 100.0 / np.mean(style.group))
                for _ in range(n):
                    base = rng.uniform(a_lo, a_hi)
                    walk = rng.choice([-1.0, 1.0])
                    pace = rng.uniform(0.9, 1.6)
                    offset = layout.sidewalk_width * rng.uniform(0.25, 0.7)
                    for m in range(int(rng.integers(style.group[0], style.group[1] + 1))):
                        across = c + side * (hw + offset + (m % 2) * 0.6 * -np.sign(offset))
                        along = base + (m // 2) * rng.uniform(0.8, 1.4) * walk
                        v = [0.0, 0.0]
                        v[axis] = walk * pace
                        add(person_parts(rng, Placed(axis, across, along, walk), len(parts)), v, a_lo, a_hi)
            # pedestrians on the zebra crossings at this road's intersections, walking across it
            cross_pos, cross_hw = (layout.ys, layout.hw_y) if axis == 1 else (layout.xs, layout.hw_x)
            hw = lanes * layout.lane_width + layout.parking_width
            for q, qhw in zip(cross_pos, cross_hw, strict=True):
                if not a_lo <= q <= a_hi:
                    continue
                n = rng.poisson(style.crossings_per_100m * pedestrians * 2 * hw / 100.0 * 6)
                for _ in range(n):
                    at_along = q + rng.choice([-1.0, 1.0]) * (qhw + rng.uniform(1.2, 3.4))
                    walk = rng.choice([-1.0, 1.0])
                    across = c + rng.uniform(-hw, hw)
                    v = [0.0, 0.0]
                    v[1 - axis] = walk * rng.uniform(0.9, 1.5)
                    # walking across: the person's "road" runs along the other axis
                    b = person_parts(rng, Placed(1 - axis, at_along, across, walk), len(parts))
                    add(b, v, c - hw - layout.sidewalk_width, c + hw + layout.sidewalk_width)
    return Agents.concat(parts)


def _renumber(parts: list[Boxes]) -> list[Boxes]:
    """Give every object one track id, unique across the parts (static first)."""
    out, base = [], 0
    for b in parts:
        if not len(b):
            out.append(b)
            continue
        _, local = np.unique(b.track, return_inverse=True)
        out.append(b.replace(track=(base + local).astype(np.int32)))
        base += int(local.max()) + 1
    return out


def build_scenario(cfg: SynthConfig) -> Scenario:
    """Generate the world and the ego's route for ``cfg`` (deterministic in ``cfg.seed``)."""
    style = get_style(cfg.style)
    rng = np.random.default_rng([cfg.seed, 0x6273_6E])
    speed = float(rng.uniform(*style.ego_speed))
    # the queue and the platoon draw from their own streams: a seed they pass by is the same world
    # (a queued clip drives slower, so its route and everything around it differ)
    queue_rng = np.random.default_rng([cfg.seed, 0x71_7565_7565])
    queued = cfg.traffic > 0 and queue_rng.random() < cfg.queue
    if queued:
        speed = float(queue_rng.uniform(*QUEUE_SPEED))
    length = cfg.frames / cfg.fps * speed + 1.0
    # the route starts mid-network and may go straight through two blocks before it turns, so
    # the network reaches the route's length plus two of the longest blocks from its middle
    extent = 2 * (length + 2 * style.block[1]) + 4 * MARGIN
    lw, pw, sw = style.lane_width, style.parking_width, style.sidewalk_width
    xs, lanes_x = _grid(rng, style, extent, lw, pw, sw)
    ys, lanes_y = _grid(rng, style, extent, lw, pw, sw)
    layout = RoadLayout(xs, lanes_x, ys, lanes_y, lw, pw, sw, verge=style.verge)
    route = build_route(layout, length, rng)
    times = np.arange(cfg.frames) / cfg.fps
    ego_xy, _ = route.at(times * speed)
    bounds = (ego_xy[:, 0].min() - MARGIN, ego_xy[:, 1].min() - MARGIN,
              ego_xy[:, 0].max() + MARGIN, ego_xy[:, 1].max() + MARGIN)
    buildings = _buildings(rng, style, layout, bounds)
    parked = _parked(rng, style, layout, bounds, cfg.parked)
    furniture = _street_furniture(rng, style, layout, bounds)
    horizon = _horizon(rng, bounds) if style.horizon else Boxes.empty()
    agents = _agents(rng, style, layout, bounds, cfg.traffic, cfg.pedestrians)
    lead_rng = np.random.default_rng([cfg.seed, 0x6C_6561_64])
    if (lead_rng.random() < cfg.lead or queued) and cfg.traffic > 0:
        agents = platoon(lead_rng, style, route, speed, bounds, agents)
    agents = clear_of_ego(rng, agents, ego_xy, times)
    *static_parts, moving = _renumber([buildings, parked, furniture, horizon, agents.boxes])
    static = Boxes.concat(static_parts)
    agents = Agents(moving, agents.velocity, agents.wrap_lo, agents.wrap_hi, agents.anchor)
    look = Look.random(rng, style.fog_distance)
    return Scenario(World(layout, static, agents, look), route, speed, 0.0)
