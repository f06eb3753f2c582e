"""Cityscapes trainIds, the class vocabulary every part of bsn-edge speaks.

A user's Cityscapes segmenter plugs in unchanged; traversable means road or
sidewalk, as in the BlindSpotNet paper.
"""

from __future__ import annotations

import numpy as np

ROAD = 0
SIDEWALK = 1
BUILDING = 2
WALL = 3
FENCE = 4
POLE = 5
TRAFFIC_LIGHT = 6
TRAFFIC_SIGN = 7
VEGETATION = 8
TERRAIN = 9
SKY = 10
PERSON = 11
RIDER = 12
CAR = 13
TRUCK = 14
BUS = 15
TRAIN = 16
MOTORCYCLE = 17
BICYCLE = 18
IGNORE = 255

NAMES: tuple[str, ...] = (
    "road", "sidewalk", "building", "wall", "fence", "pole", "traffic light",
    "traffic sign", "vegetation", "terrain", "sky", "person", "rider", "car",
    "truck", "bus", "train", "motorcycle", "bicycle",
)
NUM_CLASSES = len(NAMES)

TRAVERSABLE: tuple[int, ...] = (ROAD, SIDEWALK)
VEHICLES: tuple[int, ...] = (CAR, TRUCK, BUS, TRAIN, MOTORCYCLE, BICYCLE)
VULNERABLE: tuple[int, ...] = (PERSON, RIDER)
ROAD_USERS: tuple[int, ...] = VEHICLES + VULNERABLE   # what hides road and moves on it
# people and what they ride: the road users the labels teach least (a few pixels each, in few frames)
PEOPLE_AND_CYCLES: tuple[int, ...] = (*VULNERABLE, BICYCLE, MOTORCYCLE)

# Cityscapes colours, RGB.
_PALETTE_RGB = np.array(
    [
        (128, 64, 128), (244, 35, 232), (70, 70, 70), (102, 102, 156), (190, 153, 153),
        (153, 153, 153), (250, 170, 30), (220, 220, 0), (107, 142, 35), (152, 251, 152),
        (70, 130, 180), (220, 20, 60), (255, 0, 0), (0, 0, 142), (0, 0, 70),
        (0, 60, 100), (0, 80, 100), (0, 0, 230), (119, 11, 32),
    ],
    dtype=np.uint8,
)


def is_traversable(sem: np.ndarray) -> np.ndarray:
    """Boolean mask of road or sidewalk pixels in a trainId image."""
    return (sem == ROAD) | (sem == SIDEWALK)


def is_static(sem: np.ndarray) -> np.ndarray:
    """Boolean mask of pixels whose class stays put in the world (not sky, not a road user, not ignore):
    what the camera's motion is read from."""
    return (sem < NUM_CLASSES) & (sem != SKY) & ~np.isin(sem, ROAD_USERS)


def colorize(sem: np.ndarray) -> np.ndarray:
    """BGR colour image of a trainId image (ignore and unknown ids are black)."""
    lut = np.zeros((256, 3), dtype=np.uint8)
    lut[:NUM_CLASSES] = _PALETTE_RGB[:, ::-1]
    return lut[sem.astype(np.uint8)]
