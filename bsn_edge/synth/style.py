"""Scene styles: the dials that make a clip a dense town or an open suburb."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Style:
    """Geometry and traffic of one kind of street scene (lengths in metres, speeds in m/s)."""

    name: str
    block: tuple[float, float]            # block length between road edges
    main_road_prob: float                 # share of roads that are main roads
    lanes_main: int
    lanes_side: int
    lane_width: float
    parking_width: float
    sidewalk_width: float
    setback: tuple[float, float]          # lawn between sidewalk and buildings
    building_width: tuple[float, float]
    building_depth: tuple[float, float]
    building_height: tuple[float, float]
    gap_small: tuple[float, float]
    gap_large: tuple[float, float]
    gap_large_prob: float
    parked_density: float                 # chance a curb slot holds a vehicle
    traffic_per_100m: float               # moving vehicles per lane per 100 m
    pedestrians_per_100m: float           # per sidewalk per 100 m
    tree_spacing: float
    tree_prob: float
    ego_speed: tuple[float, float]
    traffic_speed: tuple[float, float]
    fog_distance: tuple[float, float]


TOWN = Style(
    name="town", block=(45.0, 75.0), main_road_prob=0.3, lanes_main=2, lanes_side=1,
    lane_width=3.0, parking_width=2.2, sidewalk_width=2.5, setback=(0.0, 0.5),
    building_width=(8.0, 22.0), building_depth=(10.0, 16.0), building_height=(8.0, 24.0),
    gap_small=(0.0, 1.0), gap_large=(3.0, 9.0), gap_large_prob=0.2,
    parked_density=0.65, traffic_per_100m=1.2, pedestrians_per_100m=2.5,
    tree_spacing=14.0, tree_prob=0.25, ego_speed=(7.0, 10.0), traffic_speed=(6.0, 11.0),
    fog_distance=(140.0, 260.0),
)

SUBURB = Style(
    name="suburb", block=(80.0, 130.0), main_road_prob=0.4, lanes_main=2, lanes_side=1,
    lane_width=3.5, parking_width=2.5, sidewalk_width=3.0, setback=(4.0, 9.0),
    building_width=(9.0, 15.0), building_depth=(8.0, 12.0), building_height=(4.5, 8.0),
    gap_small=(5.0, 9.0), gap_large=(10.0, 20.0), gap_large_prob=0.3,
    parked_density=0.3, traffic_per_100m=0.8, pedestrians_per_100m=0.8,
    tree_spacing=12.0, tree_prob=0.5, ego_speed=(10.0, 13.0), traffic_speed=(9.0, 15.0),
    fog_distance=(220.0, 400.0),
)

STYLES: dict[str, Style] = {s.name: s for s in (TOWN, SUBURB)}


def get_style(name: str) -> Style:
    """Look a style up by name; the error lists the valid names."""
    try:
        return STYLES[name]
    except KeyError:
        raise ValueError(f"unknown style {name!r}; valid styles: {', '.join(sorted(STYLES))}") from None
