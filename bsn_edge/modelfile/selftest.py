"""The power-on self-test: a known frame in, the answer the export stored out.

``test_frame`` draws the same street-like picture (sky, road, lane lines, a dark and a light
car, pixel noise from an integer hash) on every machine, for any input size, without a random
generator whose stream could change between library versions. The export runs the finished
model on it and stores the outputs, pooled to a coarse grid, in the model card; the runtime
runs it again before it reports OK. A digest proves the file is intact; the self-test proves
that this machine's onnxruntime computes what the export computed.
"""

from __future__ import annotations

from collections.abc import Callable

import cv2
import numpy as np

from bsn_edge.card import SelfTest, is_float_scheme

GRID = (8, 16)
# how far a healthy run may stray from the stored answer, per quantization (prob abs, depth rel);
# int8 kernels differ between CPUs (VNNI or not), fp32 only by summation order
TOLERANCE = {"fp32": (2e-3, 2e-3), "int8": (0.05, 0.05)}

Infer = Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]]


class SelfTestError(ValueError):
    """The model's answer on the test frame is not the stored one."""


def _hash_noise(h: int, w: int) -> np.ndarray:
    y, x = np.mgrid[0:h, 0:w].astype(np.uint32)
    n = (x * np.uint32(73856093)) ^ (y * np.uint32(19349663))
    n ^= n >> np.uint32(13)
    n *= np.uint32(0x5BD1E995)
    n ^= n >> np.uint32(15)
    return (n & np.uint32(31)).astype(np.int16) - 16


def test_frame(height: int, width: int) -> np.ndarray:
    """``[H, W, 3]`` uint8 BGR: the self-test's picture at this size."""
    h, w = height, width
    img = np.empty((h, w, 3), np.int16)
    horizon = int(0.45 * h)
    rows = np.arange(h)[:, None]
    sky = np.array([215, 185, 150]) - (rows[:horizon] * 60 // max(horizon, 1))[..., None]
    img[:horizon] = sky
    img[horizon:] = (95, 97, 100)
    cx = w // 2
    for k in (-1, 1):   # lane lines converging on the horizon
        x0 = cx + k * int(0.42 * w)
        pts = np.array([[cx + k * int(0.02 * w), horizon], [x0, h - 1], [x0 + k * int(0.03 * w), h - 1]])
        cv2.fillConvexPoly(img, pts.astype(np.int32), (235, 235, 235))
    for (a, b, color) in ((0.10, 0.34, (35, 30, 30)), (0.64, 0.88, (240, 240, 238))):   # dark car, white car
        top, bottom = horizon - int(0.06 * h), horizon + int(0.22 * h)
        cv2.rectangle(img, (int(a * w), top), (int(b * w), bottom), color, -1)
        cv2.rectangle(img, (int(a * w), bottom - int(0.03 * h)), (int(b * w), bottom), (20, 20, 20), -1)
    img += _hash_noise(h, w)[..., None]
    return np.clip(img, 0, 255).astype(np.uint8)


def pooled(prob: np.ndarray, depth: np.ndarray, grid: tuple[int, int] = GRID) -> tuple[np.ndarray, np.ndarray]:
    """Area-averaged ``[gh, gw]`` probabilities and depths."""
    gh, gw = grid
    return (cv2.resize(prob.astype(np.float32), (gw, gh), interpolation=cv2.INTER_AREA),
            cv2.resize(depth.astype(np.float32), (gw, gh), interpolation=cv2.INTER_AREA))


def record(infer: Infer, size: tuple[int, int], quantization: str) -> SelfTest:
    """Run the model on the test frame and keep its pooled answer (the export calls this)."""
    prob, depth = infer(test_frame(*size))
    p, d = pooled(prob, depth)
    if not (np.isfinite(p).all() and np.isfinite(d).all() and (d > 0).all()):
        raise SelfTestError("the model gives non-finite or non-positive outputs on the self-test frame")
    atol, rtol = TOLERANCE["fp32" if is_float_scheme(quantization) else "int8"]
    return SelfTest(GRID, tuple(round(float(v), 6) for v in p.ravel()),
                    tuple(round(float(v), 5) for v in d.ravel()), atol, rtol)


def deviation(infer: Infer, size: tuple[int, int], expected: SelfTest) -> dict[str, float]:
    """Run the self-test frame; the worst differences from the stored answer (inf for non-finite outputs)."""
    prob, depth = infer(test_frame(*size))
    p, d = pooled(prob, depth, expected.grid)
    want_p = np.array(expected.prob, np.float32).reshape(expected.grid)
    want_d = np.array(expected.depth, np.float32).reshape(expected.grid)
    worst_p = float(np.nanmax(np.abs(p - want_p))) if np.isfinite(p).all() else float("inf")
    worst_d = float(np.nanmax(np.abs(d - want_d) / want_d)) if np.isfinite(d).all() else float("inf")
    return {"max_abs_prob": worst_p, "max_rel_depth": worst_d}


def check(infer: Infer, size: tuple[int, int], expected: SelfTest) -> dict[str, float]:
    """Run the self-test; returns the worst differences, raises ``SelfTestError`` beyond tolerance."""
    dev = deviation(infer, size, expected)
    worst_p, worst_d = dev["max_abs_prob"], dev["max_rel_depth"]
    if not (worst_p <= expected.prob_atol and worst_d <= expected.depth_rtol):
        raise SelfTestError(f"self-test failed: probabilities differ by up to {worst_p:.3g} (allowed "
                            f"{expected.prob_atol:g}), depth by up to {100 * worst_d:.3g} % (allowed "
                            f"{100 * expected.depth_rtol:g} %) from the answer stored at export")
    return dev
