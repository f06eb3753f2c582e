"""Vehicles built from a few boxes: body, glasshouse, wheels, and riders on two-wheelers.

Every part is an axis-aligned box, so depth, semantics and blind spots stay exact. Sizes
follow real fleets (a compact car is about 4.3 x 1.8 x 1.5 m, a city bus 12 x 2.5 x 3.1 m)
and body colours follow the world's car-colour shares (white, black, grey and silver make
up about three quarters; then blue and red).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from bsn_edge import semantics as sm
from bsn_edge.synth.boxes import (
    KIND_CABIN,
    KIND_HEAD,
    KIND_RIDER,
    KIND_VEHICLE,
    KIND_WHEEL,
    Boxes,
)

# Body paint, BGR, with its share of the fleet.
PAINT = np.array([
    (0.90, 0.90, 0.89), (0.06, 0.06, 0.07), (0.40, 0.41, 0.42), (0.68, 0.69, 0.70),
    (0.55, 0.28, 0.12), (0.12, 0.13, 0.62), (0.52, 0.62, 0.70), (0.22, 0.38, 0.18),
    (0.10, 0.55, 0.85)], np.float32)
PAINT_SHARE = np.array([0.33, 0.19, 0.15, 0.10, 0.08, 0.08, 0.03, 0.02, 0.02])
# Lorries and buses: mostly white or grey boxes, some liveries.
LIVERY = np.array([(0.92, 0.92, 0.92), (0.55, 0.56, 0.58), (0.15, 0.15, 0.65), (0.60, 0.35, 0.12),
                   (0.10, 0.62, 0.85), (0.25, 0.45, 0.20)], np.float32)
LIVERY_SHARE = np.array([0.45, 0.2, 0.12, 0.1, 0.08, 0.05])
CLOTHES = np.array([(0.20, 0.15, 0.12), (0.55, 0.30, 0.20), (0.15, 0.15, 0.55), (0.70, 0.70, 0.70),
                    (0.20, 0.45, 0.20), (0.10, 0.10, 0.10), (0.30, 0.55, 0.75), (0.85, 0.85, 0.85)],
                   np.float32)
DARK = np.array((0.07, 0.07, 0.07), np.float32)   # wheels and chassis (shading draws tyres and rims)
HELMET = np.array([(0.08, 0.08, 0.08), (0.9, 0.9, 0.9), (0.1, 0.1, 0.7), (0.7, 0.4, 0.1)], np.float32)


@dataclass(frozen=True)
class VehicleType:
    """One kind of vehicle: size ranges (metres) and the shape of its parts.

    ``belt`` is the body's top as a share of the height; ``hood`` and ``tail`` are the lengths in
    front of and behind the glasshouse as shares of the length; ``wheel`` is the wheel radius.
    """

    name: str
    cls: int
    length: tuple[float, float]
    width: tuple[float, float]
    height: tuple[float, float]
    belt: float
    hood: float
    tail: float
    wheel: float
    clearance: float
    livery: bool = False          # lorry or bus colours instead of car paint
    two_wheeler: bool = False


CAR = VehicleType("car", sm.CAR, (3.9, 4.9), (1.70, 1.90), (1.40, 1.55), 0.58, 0.28, 0.10, 0.31, 0.22)
HATCH = VehicleType("hatchback", sm.CAR, (3.6, 4.2), (1.65, 1.80), (1.42, 1.55), 0.58, 0.25, 0.04, 0.30, 0.22)
SUV = VehicleType("suv", sm.CAR, (4.3, 5.0), (1.80, 2.00), (1.62, 1.85), 0.56, 0.22, 0.03, 0.36, 0.28)
VAN = VehicleType("van", sm.CAR, (4.8, 6.0), (1.90, 2.10), (1.95, 2.60), 0.45, 0.13, 0.0, 0.34, 0.25)
TRUCK = VehicleType("truck", sm.TRUCK, (6.5, 10.0), (2.30, 2.50), (2.9, 3.8), 0.0, 0.0, 0.0, 0.50, 0.50,
                    livery=True)
BUS = VehicleType("bus", sm.BUS, (10.5, 12.5), (2.50, 2.55), (3.0, 3.2), 0.0, 0.0, 0.0, 0.50, 0.30,
                  livery=True)
MOTORBIKE = VehicleType("motorbike", sm.MOTORCYCLE, (1.9, 2.2), (0.7, 0.85), (1.05, 1.2), 0.0, 0.0, 0.0,
                        0.30, 0.0, two_wheeler=True)
BICYCLE = VehicleType("bicycle", sm.BICYCLE, (1.65, 1.8), (0.5, 0.6), (0.95, 1.05), 0.0, 0.0, 0.0, 0.34, 0.0,
                      two_wheeler=True)

TYPES: dict[str, VehicleType] = {t.name: t for t in (CAR, HATCH, SUV, VAN, TRUCK, BUS, MOTORBIKE, BICYCLE)}
# Shares of moving traffic and of cars parked at the curb.
TRAFFIC_MIX = {"car": 0.36, "hatchback": 0.16, "suv": 0.22, "van": 0.08, "truck": 0.06, "bus": 0.03,
               "motorbike": 0.05, "bicycle": 0.04}
PARKED_MIX = {"car": 0.38, "hatchback": 0.2, "suv": 0.26, "van": 0.12, "truck": 0.04}


def draw_types(rng: np.random.Generator, n: int, mix: dict[str, float]) -> list[VehicleType]:
    """``n`` vehicle types drawn with the shares of ``mix``."""
    names = list(mix)
    p = np.array([mix[k] for k in names], np.float64)
    return [TYPES[names[i]] for i in rng.choice(len(names), size=n, p=p / p.sum())]


def paint(rng: np.random.Generator, vt: VehicleType) -> np.ndarray:
    """A body colour for ``vt``, BGR in [0, 1]."""
    pal, share = (LIVERY, LIVERY_SHARE) if vt.livery else (PAINT, PAINT_SHARE)
    c = pal[rng.choice(len(pal), p=share / share.sum())] + rng.normal(0, 0.025, 3)
    return np.clip(c, 0.02, 1.0).astype(np.float32)


@dataclass(frozen=True)
class Placed:
    """Where a vehicle stands: on a road along ``axis`` (0 = x, 1 = y), centred at ``across`` and
    ``along``, its front towards ``+along`` (``sign`` +1) or ``-along`` (-1)."""

    axis: int
    across: float
    along: float
    sign: float

    @property
    def facing(self) -> int:
        return int(np.sign(self.sign)) * (1 if self.axis == 0 else 2)

    def box(self, a0: float, a1: float, c0: float, c1: float, z0: float, z1: float
            ) -> tuple[tuple[float, float, float], tuple[float, float, float]]:
        """World corners of a part given in the vehicle's frame (along, across, up)."""
        if self.sign < 0:
            a0, a1, c0, c1 = -a1, -a0, -c1, -c0
        if self.axis == 1:
            return ((self.across + c0, self.along + a0, z0), (self.across + c1, self.along + a1, z1))
        return ((self.along + a0, self.across + c0, z0), (self.along + a1, self.across + c1, z1))


def draw_size(rng: np.random.Generator, vt: VehicleType) -> tuple[float, float, float]:
    """Length, width and height of one vehicle of type ``vt``."""
    length, width, height = (float(rng.uniform(*r)) for r in (vt.length, vt.width, vt.height))
    return length, width, height


def vehicle_parts(rng: np.random.Generator, vt: VehicleType, at: Placed, size: tuple[float, float, float],
                  track: int, color: np.ndarray | None = None) -> Boxes:
    """The boxes of one vehicle of type ``vt`` and ``size`` (length, width, height) standing at
    ``at``; all its parts share ``track``."""
    length, width, height = size
    col = paint(rng, vt) if color is None else np.asarray(color, np.float32)
    parts: list[tuple] = []   # (a0, a1, c0, c1, z0, z1, cls, kind, colour)
    L2, W2 = length / 2, width / 2
    r = vt.wheel

    def axles(*at_along: float) -> None:
        for a in at_along:
            parts.append((a - r, a + r, -W2, W2, 0.0, 2 * r, vt.cls, KIND_WHEEL, DARK))
    if vt.two_wheeler:
        frame_col = col if vt.cls == sm.MOTORCYCLE else np.array((0.12, 0.12, 0.12), np.float32)
        parts.append((-L2, L2, -W2 * 0.35, W2 * 0.35, 0.0, height * 0.85, vt.cls, KIND_VEHICLE, frame_col))
        top = height * 0.85
        cloth = CLOTHES[rng.integers(len(CLOTHES))]
        parts.append((-0.35, 0.15, -0.24, 0.24, top, top + 0.62, sm.RIDER, KIND_RIDER, cloth))
        head = HELMET[rng.integers(len(HELMET))] if vt.cls == sm.MOTORCYCLE else np.array((0.5, 0.62, 0.78), np.float32)
        parts.append((-0.2, 0.05, -0.12, 0.12, top + 0.62, top + 0.88, sm.RIDER, KIND_HEAD, head))
    elif vt.name == "truck":
        cab = 2.2
        parts.append((-L2, L2 - cab - 0.15, -W2, W2, vt.clearance + 0.4, height, vt.cls, KIND_VEHICLE, col))
        cab_col = paint(rng, vt)
        parts.append((L2 - cab, L2, -W2 + 0.03, W2 - 0.03, vt.clearance, 1.9, vt.cls, KIND_VEHICLE, cab_col))
        parts.append((L2 - cab, L2 - 0.1, -W2 + 0.08, W2 - 0.08, 1.9, min(2.9, height), vt.cls, KIND_CABIN,
                      cab_col))
        parts.append((-L2 + 0.5, L2 - cab, -W2 + 0.3, W2 - 0.3, vt.clearance, vt.clearance + 0.4, vt.cls,
                      KIND_WHEEL, DARK))
        axles(L2 - 1.3, -L2 + 2.2, -L2 + 1.2)
    elif vt.name == "bus":
        parts.append((-L2, L2, -W2 + 0.03, W2 - 0.03, vt.clearance, height, vt.cls, KIND_VEHICLE, col))
        axles(L2 - 2.6, -L2 + 3.2)
    else:
        belt = height * vt.belt
        parts.append((-L2, L2, -W2 + 0.03, W2 - 0.03, vt.clearance, belt, vt.cls, KIND_VEHICLE, col))
        a0, a1 = -L2 + vt.tail * length, L2 - vt.hood * length
        parts.append((a0, a1, -W2 + 0.1, W2 - 0.1, belt, height, vt.cls, KIND_CABIN, col))
        overhang = min(0.95, 0.2 * length)
        axles(L2 - overhang, -L2 + overhang * 0.9)
    los, his = zip(*(at.box(*p[:6]) for p in parts), strict=True)
    return Boxes.make(np.array(los), np.array(his), np.array([p[6] for p in parts], np.uint8),
                      np.array([p[7] for p in parts], np.uint8), np.stack([p[8] for p in parts]),
                      track=np.full(len(parts), track, np.int32), facing=at.facing)
