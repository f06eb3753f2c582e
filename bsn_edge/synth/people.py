"""Pedestrians built from boxes: two legs, a torso with arms, a head; some push a stroller."""

from __future__ import annotations

import numpy as np

from bsn_edge import semantics as sm
from bsn_edge.synth.boxes import KIND_HEAD, KIND_LEGS, KIND_PERSON, Boxes
from bsn_edge.synth.vehicles import CLOTHES, Placed

TROUSERS = np.array([(0.35, 0.22, 0.12), (0.08, 0.08, 0.08), (0.35, 0.35, 0.36), (0.45, 0.55, 0.62),
                     (0.20, 0.25, 0.30)], np.float32)
SKIN = np.array([(0.55, 0.66, 0.85), (0.42, 0.55, 0.74), (0.28, 0.38, 0.55), (0.18, 0.25, 0.38)], np.float32)
STROLLER = np.array([(0.12, 0.12, 0.12), (0.45, 0.25, 0.15), (0.30, 0.30, 0.55)], np.float32)
P_CHILD = 0.1
P_STROLLER = 0.06


def person_parts(rng: np.random.Generator, at: Placed, track: int) -> Boxes:
    """The boxes of one pedestrian walking along ``at`` (the front is the walking direction)."""
    h = float(rng.uniform(1.1, 1.4) if rng.random() < P_CHILD else rng.uniform(1.55, 1.95))
    s = h / 1.75
    legs, torso = 0.47 * h, 0.84 * h
    trousers = TROUSERS[rng.integers(len(TROUSERS))]
    top = np.clip(CLOTHES[rng.integers(len(CLOTHES))] + rng.normal(0, 0.05, 3), 0.02, 1).astype(np.float32)
    skin = SKIN[rng.integers(len(SKIN))]
    stride = float(rng.uniform(-0.12, 0.12)) * s   # legs caught mid-step
    parts = [
        (-0.08 * s + stride, 0.08 * s + stride, -0.16 * s, -0.03 * s, 0.0, legs, KIND_LEGS, trousers),
        (-0.08 * s - stride, 0.08 * s - stride, 0.03 * s, 0.16 * s, 0.0, legs, KIND_LEGS, trousers),
        (-0.12 * s, 0.12 * s, -0.23 * s, 0.23 * s, legs, torso, KIND_PERSON, top),
        (-0.1 * s, 0.11 * s, -0.095 * s, 0.095 * s, torso, h, KIND_HEAD, skin),
    ]
    if h > 1.5 and rng.random() < P_STROLLER:
        parts.append((0.35, 1.15, -0.28, 0.28, 0.12, 1.0, KIND_PERSON, STROLLER[rng.integers(len(STROLLER))]))
    los, his = zip(*(at.box(*p[:6]) for p in parts), strict=True)
    return Boxes.make(np.array(los), np.array(his), sm.PERSON, np.array([p[6] for p in parts], np.uint8),
                      np.stack([p[7] for p in parts]), track=np.full(len(parts), track, np.int32))
