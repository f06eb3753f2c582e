"""A synthetic world: road layout, static boxes, moving agents and the clip's look."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from bsn_edge.synth.boxes import Agents, Boxes
from bsn_edge.synth.layout import RoadLayout

LIGHTS = {"sun": 0.5, "overcast": 0.25, "dusk": 0.13, "night": 0.12}   # share of clips


@dataclass(frozen=True)
class Look:
    """Lighting and surfaces of one clip (colours BGR in [0, 1]; light in radiance units, where a
    white surface facing a full sun is about 1)."""

    light: str = "sun"                                     # one of LIGHTS
    sun: tuple[float, float, float] = (0.4, 0.3, 0.85)     # unit vector towards the sun (world)
    sun_color: tuple[float, float, float] = (1.0, 1.0, 1.0)
    sun_strength: float = 0.55
    ambient: float = 0.45                                   # light from the sky on a horizontal surface
    sky_zenith: tuple[float, float, float] = (0.85, 0.55, 0.35)
    sky_horizon: tuple[float, float, float] = (0.95, 0.85, 0.78)
    clouds: float = 0.3                                     # share of the sky under cloud
    haze: tuple[float, float, float] = (0.85, 0.80, 0.76)
    fog_distance: float = 200.0
    road: tuple[float, float, float] = (0.36, 0.36, 0.37)
    sidewalk: tuple[float, float, float] = (0.62, 0.64, 0.66)
    terrain: tuple[float, float, float] = (0.25, 0.50, 0.38)
    marking: tuple[float, float, float] = (0.88, 0.90, 0.90)
    wear: float = 0.3                                       # how worn markings and asphalt are, 0-1

    def __post_init__(self) -> None:
        if self.light not in LIGHTS:
            raise ValueError(f"Look.light must be one of {', '.join(LIGHTS)}, got {self.light!r}")

    @property
    def night(self) -> bool:
        return self.light == "night"

    @classmethod
    def random(cls, rng: np.random.Generator, fog_range: tuple[float, float]) -> Look:
        names = list(LIGHTS)
        light = names[rng.choice(len(names), p=np.array([LIGHTS[k] for k in names]))]
        az = rng.uniform(0, 2 * np.pi)
        el = np.radians({"sun": rng.uniform(20, 65), "overcast": rng.uniform(30, 60),
                         "dusk": rng.uniform(4, 12), "night": rng.uniform(20, 40)}[light])
        sun = (np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el))

        def jitter(c, s):
            return tuple(float(v) for v in np.clip(np.asarray(c) + rng.normal(0, s, 3), 0, 1))
        grey = rng.uniform(0.22, 0.46)
        common = dict(
            light=light, sun=tuple(float(v) for v in sun),
            road=jitter((grey, grey, grey + 0.01), 0.015), sidewalk=jitter((0.60, 0.62, 0.64), 0.06),
            terrain=jitter((0.22, 0.46, 0.36), 0.06), marking=jitter((0.86, 0.9, 0.9), 0.03),
            wear=float(rng.uniform(0.0, 0.8)), fog_distance=float(rng.uniform(*fog_range)),
        )
        if light == "sun":
            return cls(**common, sun_color=jitter((0.97, 1.0, 1.0), 0.02), sun_strength=float(rng.uniform(0.5, 0.75)),
                       ambient=float(rng.uniform(0.32, 0.5)), sky_zenith=jitter((0.85, 0.55, 0.35), 0.06),
                       sky_horizon=jitter((0.95, 0.86, 0.78), 0.04), clouds=float(rng.uniform(0.0, 0.6)),
                       haze=jitter((0.85, 0.80, 0.76), 0.04))
        if light == "overcast":
            g = rng.uniform(0.7, 0.85)
            return cls(**common, sun_color=(1.0, 1.0, 1.0), sun_strength=float(rng.uniform(0.03, 0.12)),
                       ambient=float(rng.uniform(0.7, 0.85)), sky_zenith=jitter((g, g, g - 0.02), 0.03),
                       sky_horizon=jitter((g + 0.08, g + 0.08, g + 0.07), 0.02), clouds=float(rng.uniform(0.85, 1.0)),
                       haze=jitter((g, g, g), 0.03))
        if light == "dusk":
            return cls(**common, sun_color=jitter((0.45, 0.72, 1.0), 0.05), sun_strength=float(rng.uniform(0.45, 0.7)),
                       ambient=float(rng.uniform(0.22, 0.34)), sky_zenith=jitter((0.55, 0.35, 0.25), 0.05),
                       sky_horizon=jitter((0.45, 0.65, 0.95), 0.05), clouds=float(rng.uniform(0.1, 0.6)),
                       haze=jitter((0.5, 0.58, 0.72), 0.04))
        return cls(**{**common, "fog_distance": float(rng.uniform(60, 120))}, sun_color=(1.0, 1.0, 1.0),
                   sun_strength=0.0, ambient=float(rng.uniform(0.03, 0.07)),
                   sky_zenith=jitter((0.06, 0.04, 0.03), 0.01), sky_horizon=jitter((0.10, 0.12, 0.16), 0.02),
                   clouds=float(rng.uniform(0.0, 0.8)), haze=jitter((0.06, 0.07, 0.09), 0.01))


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
