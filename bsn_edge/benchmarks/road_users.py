"""Boxes of the road users in a labelled synthetic frame, as ``realboxes`` draws them by hand on real ones.

The real benchmark's development frames hold no people or cyclists, and only 25 near occluders. A
synthetic frame knows every object exactly, so the same question (is at least
``bench_realboxes.MARKED_SHARE`` of the occluder's box blind spot?) can be asked of thousands of
road users, people and cyclists among them, and of the T-frame labels as well as of a model: the
labels' share says how many of them the paper's definition marks at all, the most a model trained
on it learns to mark.

An occluder is a connected patch of one kind of road user that touches road or sidewalk (it hides
road only then); depth edges cut patches on their far side, so a car in front of another is two.
Near: its median depth is under :data:`NEAR_M`. Cars parked bumper to bumper stay one box, which a
hand would draw as several. Riders and their bicycles are one cyclist.
"""

from __future__ import annotations

from typing import Any

import cv2
import numpy as np

from bsn_edge import semantics as sm

NEAR_M = 20.0                 # the real boxes' "near": within about 20 m
MIN_PIXELS = 24               # smaller patches are not drawn (a person at 20 m is about 50 px at 512x256)
DEPTH_EDGE = 0.1              # a jump in log depth between neighbours that cuts a patch in two
CONTACT = 0.05                # share of a patch's rim on road or sidewalk: it stands there
KINDS: dict[str, tuple[int, ...]] = {
    "car": (sm.CAR,),
    "truck": (sm.TRUCK, sm.TRAIN),
    "bus": (sm.BUS,),
    "person": (sm.PERSON,),
    "cyclist": (sm.RIDER, sm.BICYCLE, sm.MOTORCYCLE),
}


def _behind_an_edge(depth: np.ndarray) -> np.ndarray:
    """Pixels more than :data:`DEPTH_EDGE` farther (in log depth) than one of their four neighbours:
    the far side of an occluding contour, so the nearer object keeps all its pixels."""
    logd = np.log(np.maximum(depth, 1e-3))
    cut = np.zeros(depth.shape, bool)
    dx = np.diff(logd, axis=1)              # right minus left
    dy = np.diff(logd, axis=0)              # lower minus upper
    cut[:, 1:] |= dx > DEPTH_EDGE
    cut[:, :-1] |= -dx > DEPTH_EDGE
    cut[1:, :] |= dy > DEPTH_EDGE
    cut[:-1, :] |= -dy > DEPTH_EDGE
    return cut


def road_users(semantic: np.ndarray, depth: np.ndarray, seen: np.ndarray | None = None) -> list[dict[str, Any]]:
    """Occluder boxes (``{"class", "box": [x0, y0, x1, y1], "near"}``, the format of
    ``bsn_edge/benchmarks/realboxes/boxes.json``) of the road users in a trainId ``semantic`` image with metric
    ``depth``; only pixels where ``seen`` (default: everywhere) count."""
    if semantic.shape != depth.shape:
        raise ValueError(f"semantic {semantic.shape} and depth {depth.shape} differ in size")
    seen = np.ones(semantic.shape, bool) if seen is None else seen
    trav = sm.is_traversable(semantic)
    cut = _behind_an_edge(depth)
    kernel = np.ones((5, 5), np.uint8)   # reaches past a one-pixel cut
    out = []
    for kind, ids in KINDS.items():
        mask = np.isin(semantic, ids) & seen & (depth > 0)
        if not mask.any():
            continue
        n, lab, stats, _ = cv2.connectedComponentsWithStats((mask & ~cut).astype(np.uint8), connectivity=4)
        for i in range(1, n):
            if stats[i, cv2.CC_STAT_AREA] < MIN_PIXELS:
                continue
            patch = lab == i
            rim = cv2.dilate(patch.astype(np.uint8), kernel).astype(bool) & ~mask
            if not rim.any() or trav[rim].mean() < CONTACT:
                continue
            x, y, w, h = (int(v) for v in stats[i, :4])
            out.append({"class": kind, "box": [x, y, x + w, y + h],
                        "near": bool(np.median(depth[patch]) < NEAR_M)})
    return out
