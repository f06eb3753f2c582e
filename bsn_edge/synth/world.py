"""A synthetic world: road layout, static boxes, moving agents and the clip's look."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from bsn_edge.synth.boxes import Agents, Boxes
from bsn_edge.synth.layout import RoadLayout


@dataclass(frozen=True)
class Look:
    """Lighting and colour of one clip (colours BGR in [0, 1])."""

    sun: tuple[float, float, float] = (0.4, 0.3, 0.85)   # unit vector towards the sun (world)
    ambient: float = 0.55
    sky_zenith: tuple[float, float, float] = (0.85, 0.55, 0.35)
    sky_horizon: tuple[float, float, float] = (0.95, 0.85, 0.78)
    haze: tuple[float, float, float] = (0.85, 0.80, 0.76)
    fog_distance: float = 200.0
    road: tuple[float, float, float] = (0.36, 0.36, 0.37)
    sidewalk: tuple[float, float, float] = (0.62, 0.64, 0.66)
    terrain: tuple[float, float, float] = (0.25, 0.50, 0.38)
    marking: tuple[float, float, float] = (0.88, 0.90, 0.90)
    tint: tuple[float, float, float] = (1.0, 1.0, 1.0)
    exposure: float = 1.0
    noise_sigma: float = 2.0   # sensor noise, in 8-bit levels

    @classmethod
    def random(cls, rng: np.random.Generator, fog_range: tuple[float, float]) -> Look:
        az = rng.uniform(0, 2 * np.pi)
        el = np.radians(rng.uniform(25, 65))
        sun = (np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el))
        def jitter(c, s):
            return tuple(float(v) for v in np.clip(np.asarray(c) + rng.normal(0, s, 3), 0, 1))
        grey = rng.uniform(0.26, 0.44)
        return cls(
            sun=tuple(float(v) for v in sun), ambient=float(rng.uniform(0.45, 0.65)),
            sky_zenith=jitter((0.85, 0.55, 0.35), 0.06), sky_horizon=jitter((0.95, 0.86, 0.78), 0.04),
            haze=jitter((0.85, 0.80, 0.76), 0.04), fog_distance=float(rng.uniform(*fog_range)),
            road=jitter((grey, grey, grey + 0.01), 0.015), sidewalk=jitter((0.62, 0.64, 0.66), 0.05),
            terrain=jitter((0.22, 0.48, 0.36), 0.05), marking=jitter((0.88, 0.9, 0.9), 0.02),
            tint=tuple(float(v) for v in rng.uniform(0.92, 1.08, 3)),
            exposure=float(rng.uniform(0.9, 1.1)), noise_sigma=float(rng.uniform(1.0, 3.0)),
        )


@dataclass(frozen=True)
class World:
    """Everything that exists: the ground layout, static boxes, moving agents and the look."""

    layout: RoadLayout
    static: Boxes
    agents: Agents
    look: Look = Look()

    def boxes_at(self, t: float) -> Boxes:
        """All boxes at time ``t`` seconds; indices of static boxes come first and never change."""
        return Boxes.concat([self.static, self.agents.at(t)])
