"""Aligning a relative depth map to metric scale against sparse landmarks (least squares).

Monocular depth networks give depth (or inverse depth, MiDaS-style) up to an unknown scale
and shift per image. Landmarks triangulated with the clip's poses give sparse depths in the
poses' scale; a least-squares fit of ``scale * pred + shift`` to them, in the network's own
space, brings the dense map into that scale. The Pearson correlation between the aligned
prediction and the landmarks says whether the fit can be trusted: the paper rejects clips
under 0.7.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

KINDS = ("depth", "inverse_depth", "metric_depth")
MIN_POINTS = 12
METRIC_NEAR_M = 20.0   # a metric prediction's scale is fitted on the landmarks it puts nearer than this


@dataclass(frozen=True)
class Alignment:
    """``metric = scale * pred + shift`` in the prediction's space (depth or inverse depth; for
    ``metric_depth``, a network already in metres, the shift is 0 and only the scale is fitted)."""

    scale: float
    shift: float
    kind: str
    corr: float
    n: int

    def apply(self, pred: np.ndarray) -> np.ndarray:
        """Metric depth from a prediction; non-positive results become 0 (unknown)."""
        v = self.scale * pred.astype(np.float32) + np.float32(self.shift)
        if self.kind == "inverse_depth":
            with np.errstate(divide="ignore"):
                v = np.where(v > 1e-6, 1.0 / np.maximum(v, 1e-6), 0.0)
        return np.where(v > 0, v, 0.0).astype(np.float32)


def fit(pred: np.ndarray, target_depth: np.ndarray, kind: str = "depth", trim: float = 3.0) -> Alignment:
    """Least-squares scale and shift of ``pred`` to ``target_depth`` (1-D arrays of matched samples),
    with one round of trimming residuals beyond ``trim`` robust standard deviations."""
    if kind not in KINDS:
        raise ValueError(f"unknown prediction kind {kind!r}; valid: {', '.join(KINDS)}")
    pred = np.asarray(pred, np.float64).ravel()
    target = np.asarray(target_depth, np.float64).ravel()
    ok = np.isfinite(pred) & np.isfinite(target) & (target > 0)
    pred, target = pred[ok], target[ok]
    if len(pred) < MIN_POINTS:
        raise ValueError(f"too few landmarks to align depth ({len(pred)} < {MIN_POINTS})")
    if kind == "metric_depth":
        return _fit_scale(pred, target, trim)
    y = 1.0 / target if kind == "inverse_depth" else target
    keep = np.ones(len(y), bool)
    for _ in range(2):
        A = np.stack([pred[keep], np.ones(keep.sum())], 1)
        (s, b), *_ = np.linalg.lstsq(A, y[keep], rcond=None)
        r = y - (s * pred + b)
        mad = np.median(np.abs(r[keep] - np.median(r[keep]))) * 1.4826 + 1e-12
        keep = np.abs(r) < trim * mad
        if keep.sum() < MIN_POINTS:
            keep = np.ones(len(y), bool)
            break
    # correlation over the points the fit kept: a few bad tracks must not reject a good clip,
    # while a prediction unrelated to depth keeps most points and stays uncorrelated
    fitted = s * pred[keep] + b
    yk = y[keep]
    corr = float(np.corrcoef(fitted, yk)[0, 1]) if np.std(fitted) > 0 and np.std(yk) > 0 else 0.0
    return Alignment(float(s), float(b), kind, corr, int(keep.sum()))


def _fit_scale(pred: np.ndarray, target: np.ndarray, trim: float) -> Alignment:
    """A metric prediction's one error that landmarks can fix, its scale (a camera it was not
    trained for, monocular odometry's units): the robust median of ``log(target / pred)``. An
    affine fit in depth space would let the far landmarks, where a network errs most, bend the
    near road, where it is right."""
    ok = pred > 0
    pred, target = pred[ok], target[ok]
    if len(pred) < MIN_POINTS:
        raise ValueError(f"too few landmarks to align depth ({len(pred)} < {MIN_POINTS})")
    near = pred < METRIC_NEAR_M      # where a metric network is most right (and labels are made)
    if near.sum() >= MIN_POINTS:
        pred, target = pred[near], target[near]
    lr = np.log(target) - np.log(pred)
    keep = np.ones(len(lr), bool)
    for _ in range(2):
        m = np.median(lr[keep])
        mad = np.median(np.abs(lr[keep] - m)) * 1.4826 + 1e-12
        keep = np.abs(lr - m) < trim * mad
        if keep.sum() < MIN_POINTS:
            keep = np.ones(len(lr), bool)
            break
    s = float(np.exp(np.median(lr[keep])))
    fitted, yk = s * pred[keep], target[keep]
    corr = float(np.corrcoef(fitted, yk)[0, 1]) if np.std(fitted) > 0 and np.std(yk) > 0 else 0.0
    return Alignment(s, 0.0, "metric_depth", corr, int(keep.sum()))


def pooled_correlation(preds: list[np.ndarray], targets: list[np.ndarray], aligns: list[Alignment]) -> float:
    """Correlation of aligned predictions with landmarks over a whole clip (in the fit's space)."""
    xs, ys = [], []
    for p, t, a in zip(preds, targets, aligns, strict=True):
        y = 1.0 / t if a.kind == "inverse_depth" else t
        xs.append(a.scale * p + a.shift)
        ys.append(y)
    x, y = np.concatenate(xs), np.concatenate(ys)
    ok = np.isfinite(x) & np.isfinite(y)       # pixels a prediction does not cover carry NaN
    x, y = x[ok], y[ok]
    if len(x) < MIN_POINTS or np.std(x) == 0 or np.std(y) == 0:
        return 0.0
    return float(np.corrcoef(x, y)[0, 1])
