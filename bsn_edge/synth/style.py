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
    building_prob: float = 1.0            # share of lots with buildings
    verge: bool = False                   # the strip beside the carriageway is grass, not sidewalk
    barriers: bool = False                # concrete barriers on the centre line and the verge
    boundary: float = 0.0                 # chance a lot's front has a hedge, fence or wall
    horizon: bool = False                 # hills and tree lines far away
    crossings_per_100m: float = 0.0       # pedestrians crossing at the zebras, per road per 100 m
    group: tuple[int, int] = (1, 2)       # pedestrians walk in groups of this many
    two_wheelers: bool = True             # bicycles and motorbikes in traffic


TOWN = Style(
    name="town", block=(45.0, 75.0), main_road_prob=0.3, lanes_main=2, lanes_side=1,
    lane_width=3.0, parking_width=2.2, sidewalk_width=2.5, setback=(0.0, 0.5),
    building_width=(8.0, 22.0), building_depth=(10.0, 16.0), building_height=(8.0, 24.0),
    gap_small=(0.0, 1.0), gap_large=(3.0, 9.0), gap_large_prob=0.2,
    parked_density=0.65, traffic_per_100m=1.2, pedestrians_per_100m=2.5,
    tree_spacing=14.0, tree_prob=0.25, ego_speed=(7.0, 10.0), traffic_speed=(6.0, 11.0),
    fog_distance=(140.0, 260.0), boundary=0.15, crossings_per_100m=0.6, group=(1, 3),
)

SUBURB = Style(
    name="suburb", block=(80.0, 130.0), main_road_prob=0.4, lanes_main=2, lanes_side=1,
    lane_width=3.5, parking_width=2.5, sidewalk_width=3.0, setback=(4.0, 9.0),
    building_width=(9.0, 15.0), building_depth=(8.0, 12.0), building_height=(4.5, 8.0),
    gap_small=(5.0, 9.0), gap_large=(10.0, 20.0), gap_large_prob=0.3,
    parked_density=0.3, traffic_per_100m=0.8, pedestrians_per_100m=0.8,
    tree_spacing=12.0, tree_prob=0.5, ego_speed=(10.0, 13.0), traffic_speed=(9.0, 15.0),
    fog_distance=(220.0, 400.0), boundary=0.6, horizon=True, crossings_per_100m=0.2, group=(1, 2),
)

HIGHWAY = Style(
    name="highway", block=(350.0, 650.0), main_road_prob=1.0, lanes_main=3, lanes_side=2,
    lane_width=3.6, parking_width=2.8, sidewalk_width=2.5, setback=(10.0, 25.0),
    building_width=(15.0, 40.0), building_depth=(15.0, 30.0), building_height=(5.0, 14.0),
    gap_small=(10.0, 30.0), gap_large=(40.0, 120.0), gap_large_prob=0.5,
    parked_density=0.0, traffic_per_100m=1.6, pedestrians_per_100m=0.0,
    tree_spacing=9.0, tree_prob=0.55, ego_speed=(20.0, 28.0), traffic_speed=(18.0, 31.0),
    fog_distance=(250.0, 500.0), building_prob=0.2, verge=True, barriers=True, horizon=True,
    two_wheelers=False,
)

URBAN = Style(
    name="urban", block=(35.0, 60.0), main_road_prob=0.35, lanes_main=2, lanes_side=1,
    lane_width=2.9, parking_width=2.1, sidewalk_width=3.2, setback=(0.0, 0.0),
    building_width=(6.0, 16.0), building_depth=(10.0, 16.0), building_height=(12.0, 32.0),
    gap_small=(0.0, 0.3), gap_large=(2.0, 5.0), gap_large_prob=0.1,
    parked_density=0.92, traffic_per_100m=1.4, pedestrians_per_100m=8.0,
    tree_spacing=11.0, tree_prob=0.2, ego_speed=(5.0, 9.0), traffic_speed=(4.0, 9.0),
    fog_distance=(120.0, 220.0), boundary=0.05, crossings_per_100m=1.5, group=(1, 4),
)

STYLES: dict[str, Style] = {s.name: s for s in (TOWN, SUBURB, HIGHWAY, URBAN)}


def get_style(name: str) -> Style:
    """Look a style up by name; the error lists the valid names."""
    try:
        return STYLES[name]
    except KeyError:
        raise ValueError(f"unknown style {name!r}; valid styles: {', '.join(sorted(STYLES))}") from None
