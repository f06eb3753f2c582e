"""The traffic around the ego of a rendered clip: the platoon it follows, the mix of vehicles, and every moving
object kept clear of its footprint."""

from __future__ import annotations

import numpy as np

from bsn_edge.synth.boxes import Agents
from bsn_edge.synth.route import Route
from bsn_edge.synth.style import Style
from bsn_edge.synth.vehicles import TRAFFIC_MIX, Placed, draw_size, draw_types, vehicle_parts

EGO_CLEARANCE = 3.0     # moving objects keep this far from the ego footprint, metres
# The platoon ahead of the ego (SynthConfig.lead): following the car in front is the commonest
# scene of real driving and the one whose distance matters most on the bus.
EGO_NOSE = 2.0          # the ego's front bumper ahead of its camera, metres
LEAD_STANDSTILL = (2.0, 5.0)   # bumper-to-bumper gap at standstill, metres
LEAD_HEADWAY = (0.3, 2.0)      # time gap on top of it, seconds at the ego's speed
LEAD_SPEED = (1.0, 1.1)        # the platoon's speed over the ego's (never closing in on it)
LEAD_VEHICLES = (1, 3)         # vehicles in the platoon


def traffic_mix(style: Style) -> dict[str, float]:
    if style.two_wheelers:
        return TRAFFIC_MIX
    return {k: v for k, v in TRAFFIC_MIX.items() if k not in ("motorbike", "bicycle")}


def platoon(rng: np.random.Generator, style: Style, route: Route, speed: float, bounds, agents: Agents) -> Agents:
    """A platoon of vehicles in the ego's lane, ahead of it at a following distance, driving on
    along the route's first road; the same-direction traffic of that lane gives way to it."""
    xy, yaw = route.at(0.0)
    heading = np.array([np.cos(yaw[0]), np.sin(yaw[0])])
    axis = int(np.argmax(np.abs(heading)))
    sign = float(np.sign(heading[axis]))
    across = float(xy[0, 1 - axis])
    v = speed * float(rng.uniform(*LEAD_SPEED))
    lo_b, hi_b = (bounds[1], bounds[3]) if axis == 1 else (bounds[0], bounds[2])
    # the lane's own traffic would drive through the platoon
    lane = (np.sign(agents.velocity[:, axis]) == sign) & (np.abs(agents.anchors[:, 1 - axis] - across)
                                                          < 0.5 * style.lane_width)
    agents = agents.take(np.flatnonzero(~lane))
    parts = [agents]
    vel = np.zeros(2)
    vel[axis] = sign * v
    front = float(xy[0, axis]) + sign * EGO_NOSE    # the front of the last vehicle in line
    n = int(rng.integers(LEAD_VEHICLES[0], LEAD_VEHICLES[1] + 1))
    track0 = int(agents.boxes.track.max()) + 1 if len(agents) else 0
    for k, vt in enumerate(draw_types(rng, n, traffic_mix(style))):
        size = draw_size(rng, vt)
        gap = rng.uniform(*LEAD_STANDSTILL) + rng.uniform(*LEAD_HEADWAY) * speed
        centre = front + sign * (gap + 0.5 * size[0])
        front = centre + sign * 0.5 * size[0]
        parts.append(Agents.moving(vehicle_parts(rng, vt, Placed(axis, across, centre, sign), size, track0 + k),
                                   vel, lo_b, hi_b))
    return Agents.concat(parts)


def clear_of_ego(rng, agents: Agents, ego_xy: np.ndarray, times: np.ndarray, tries: int = 8) -> Agents:
    """Re-phase objects that would touch the ego car during the clip; drop those that still do.

    An object (all boxes of one track) moves and is kept or dropped as one."""
    if not len(agents):
        return agents
    objs, inv = np.unique(agents.boxes.track, return_inverse=True)
    half = 0.5 * (agents.boxes.hi[:, :2] - agents.boxes.lo[:, :2])
    radius = np.linalg.norm(half, axis=1) + EGO_CLEARANCE
    ok = np.zeros(len(objs), bool)
    cur = agents
    for _ in range(tries):
        c = cur.centres_at(times)
        dist = np.linalg.norm(c - ego_xy[None], axis=2).min(axis=1)
        clear = np.ones(len(objs), bool)
        np.logical_and.at(clear, inv, dist > radius)
        ok |= clear
        bad = ~ok
        if not bad.any():
            break
        shift_obj = rng.uniform(10.0, 60.0, len(objs)) * rng.choice([-1.0, 1.0], len(objs)) * bad
        shift = shift_obj[inv]
        axis = np.abs(agents.velocity).argmax(axis=1)
        rows = np.arange(len(agents))
        lo, hi, anc = cur.boxes.lo.copy(), cur.boxes.hi.copy(), cur.anchors.copy()
        lo[rows, axis] += shift
        hi[rows, axis] += shift
        anc[rows, axis] += shift
        cur = Agents(cur.boxes.replace(lo=lo, hi=hi), agents.velocity, agents.wrap_lo, agents.wrap_hi, anc)
    return cur.take(np.flatnonzero(ok[inv]))
