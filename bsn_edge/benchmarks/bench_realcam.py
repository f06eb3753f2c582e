"""Depth on real cameras, before (frames resized into the model) and after (warped into the model camera).

    python -m bsn_edge.benchmarks.bench_realcam --out benchmarks/results [--model A.onnx --model B.onnx]

Real data from ``../shared/data/real/`` (skipped, with a note, when absent):

- DDAD (``ddad_dgp`` scenes, 3 frames each, and ``ddad_camviz_eval.npz``): LiDAR depth. The mounting
  comes from the calibration's camera-to-vehicle extrinsics and the road plane fitted to the LiDAR
  (height above it, pitch and roll against it, yaw against the vehicle's x axis). Road points lie
  within 0.15 m of the plane; object points 0.3-2.5 m above it, within 8 m of the car's axis (on the
  road: cars and people, the "car distance" figure). Object points are also read in two bands of
  height: 0.3-1 m (bumpers, doors, wheels: where a car meets the road) and 1-2.5 m (glass, roofs,
  roof racks, people's upper bodies: where a real car shows the scene through or in its glass).
- ``udacity_test_video.mp4``: intrinsics and distortion from ``camera_cal`` (the product's chessboard
  step), mounting from the product's own ``--mount`` step (lane width 3.7 m, a US highway lane);
  truth is the flat road's geometry in the ego lane (within 1.2 m of the car's axis) where no car is.

Per model: AbsRel, median ratio (prediction / truth) and delta < 1.25 in 5-10, 10-20, 20-40 and
5-40 m, for road points and for object points, with the old resize and with the model camera.
Overlay pictures (blind spots tinted, depth coloured) go beside the results.

A handful of frames holds a handful of cars, so every 5-40 m reading in the model camera also gets a
90 % interval from resampling the frames (a frame's points stay together: they share one car and one
exposure), and each model after the first its difference from the first over the same resamples. A
change whose interval holds 0 is not told apart from the frames' own spread. One that leaves 0 out
holds on these frames, which is necessary, not enough: the resampling cannot draw cars or scenes the
frames do not hold, nor a training's own drift from checkpoint to checkpoint.
"""

from __future__ import annotations

import argparse
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from bsn_edge.default_model import DEFAULT_MODEL
from bsn_edge.metrics import bin_name, depth_by_bin
from bsn_edge.runtime.engine import Engine
from bsn_edge.synth.sheet import tint

from .common import load_engine, named
from .real_samples import (
    BINS,
    CORRIDOR_M,
    INTERVAL_PCT,
    NEAREST_PCT,
    OBJECT_BANDS,
    OBJECT_CELL_M,
    OBJECT_MIN_POINTS,
    REAL,
    RESAMPLES,
    SPAN_M,
    Sample,
    ddad_samples,
    licence,
    udacity_samples,
)
from .runner import Report, run


def predict(engine: Engine, sample: Sample, way: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Depth (raw camera z, metres) at the sample's truth pixels, the raw-grid depth and probability."""
    img = sample.image
    h, w = img.shape[:2]
    if way == "resize":
        # what bsn-run did before the model camera: resize, read depth as it comes
        mh, mw = engine.size
        prob, depth = engine.infer(cv2.resize(img, (mw, mh), interpolation=cv2.INTER_AREA)[None])
        raw_depth = cv2.resize(depth, (w, h), interpolation=cv2.INTER_NEAREST)
        raw_prob = cv2.resize(prob, (w, h), interpolation=cv2.INTER_LINEAR)
    else:
        mf = sample.camera.model_frame(w, h, engine.card.camera, engine.card.mounting)
        prob, depth = engine.infer(mf.to_model(img)[None])
        raw_depth, raw_prob = mf.depth_to_raw(depth), mf.to_raw(prob)
    u = np.clip(np.rint(sample.uv[:, 0]).astype(int), 0, w - 1)
    v = np.clip(np.rint(sample.uv[:, 1]).astype(int), 0, h - 1)
    return raw_depth[v, u], raw_depth, raw_prob


def metrics(pred: np.ndarray, truth: np.ndarray) -> dict[str, dict[str, float]]:
    return depth_by_bin(pred, truth, BINS, min_points=5)


def object_distances(pred: np.ndarray, sample: Sample) -> tuple[np.ndarray, np.ndarray]:
    """Per object in the model's view: its distance by the prediction and by LiDAR, each the nearest
    (``NEAREST_PCT`` percentile) depth over the object's truth pixels. The bus carries this reading:
    the nearest blind-spot depth of a sector, not the depth of every point of a car."""
    pd, td = [], []
    for o in np.unique(sample.obj[sample.obj >= 0]):
        m = (sample.obj == o) & (pred > 0)
        if m.sum() >= OBJECT_MIN_POINTS:
            pd.append(np.percentile(pred[m], NEAREST_PCT))
            td.append(np.percentile(sample.z[m], NEAREST_PCT))
    return np.array(pd), np.array(td)


@dataclass(frozen=True)
class FrameErrors:
    """One reading's errors in :data:`SPAN_M` split by frame: per frame, the summed ``|pred / truth - 1|``
    and the number of points (or objects) it sums."""

    sums: np.ndarray
    counts: np.ndarray

    @classmethod
    def of(cls, preds: list[np.ndarray], truths: list[np.ndarray]) -> FrameErrors:
        """From per-frame predictions and truths, scored as :func:`depth_by_bin` scores them."""
        stats = [depth_by_bin(pred, truth, (SPAN_M,)).get(bin_name(*SPAN_M), {"n": 0, "abs_rel": 0.0})
                 for pred, truth in zip(preds, truths, strict=True)]
        return cls(np.array([st["abs_rel"] * st["n"] for st in stats]), np.array([st["n"] for st in stats]))

    def abs_rel(self, frames: np.ndarray | None = None) -> np.ndarray | float:
        """AbsRel over all frames, or one value per row of ``frames`` (frame indices, with repeats); NaN
        where the chosen frames hold no point."""
        if frames is None:
            n = self.counts.sum()
            return float(self.sums.sum() / n) if n else math.nan
        with np.errstate(invalid="ignore", divide="ignore"):
            return self.sums[frames].sum(1) / self.counts[frames].sum(1)


def resampled_frames(n_frames: int, resamples: int = RESAMPLES, seed: int = 0) -> np.ndarray:
    """``resamples`` draws of ``n_frames`` frame indices with replacement; one set for every model,
    so their differences are paired."""
    return np.random.default_rng(seed).integers(0, n_frames, (resamples, n_frames))


def interval(values: np.ndarray) -> tuple[float, float]:
    """The :data:`INTERVAL_PCT` percentiles of resampled values, NaNs (draws with no point) left out."""
    lo, hi = np.nanpercentile(values, INTERVAL_PCT)
    return float(lo), float(hi)


def interval_table(errors: dict[str, dict[str, FrameErrors]], models: list[str]) -> tuple[list[str], dict]:
    """Report lines and JSON for :data:`SPAN_M` AbsRel with intervals: ``errors[row][model]`` per
    (data, reading) row, every model after the first also as its difference from the first."""
    base = models[0]
    head = "| data / reading | frames | " + " | ".join(
        [f"`{base}`", *(f"`{m}`, and minus `{base}`" for m in models[1:])]) + " |"
    lines = [head, "|---|---|" + "---|" * len(models)]
    out: dict[str, Any] = {}
    for row, per in errors.items():
        idx = resampled_frames(len(per[base].sums))
        ref = np.asarray(per[base].abs_rel(idx))
        cells: list[str] = []
        rec: dict[str, Any] = {}
        for m in models:
            e = per[m]
            resampled = np.asarray(e.abs_rel(idx))
            lo, hi = interval(resampled)
            rec[m] = {"abs_rel": e.abs_rel(), "interval": [lo, hi], "n": int(e.counts.sum())}
            cell = f"{e.abs_rel():.3f} [{lo:.3f}, {hi:.3f}]"
            if m != base:
                d_lo, d_hi = interval(resampled - ref)
                d = e.abs_rel() - per[base].abs_rel()
                apart = d_lo > 0 or d_hi < 0
                rec[m]["minus_first"] = {"diff": d, "interval": [d_lo, d_hi], "apart": apart}
                cell += f"; {d:+.3f} [{d_lo:+.3f}, {d_hi:+.3f}]" + (" *" if apart else "")
            cells.append(cell)
        out[row] = rec
        lines.append(f"| {row} | {len(per[base].sums)} | " + " | ".join(cells) + " |")
    return lines, out


def picture(sample: Sample, depth: np.ndarray, prob: np.ndarray, threshold: float) -> np.ndarray:
    scale = 480.0 / sample.image.shape[1]
    size = (480, round(sample.image.shape[0] * scale))
    img = cv2.resize(sample.image, size, interpolation=cv2.INTER_AREA)
    mask = cv2.resize((prob >= threshold).astype(np.uint8), size, interpolation=cv2.INTER_NEAREST) > 0
    d = cv2.resize(depth, size, interpolation=cv2.INTER_NEAREST)
    col = cv2.applyColorMap((255 * np.clip(10.0 / (d + 10.0), 0, 1)).astype(np.uint8), cv2.COLORMAP_MAGMA)
    col[d <= 0] = 0
    return np.hstack([tint(img, mask), col])


def parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--out", default="benchmarks/results")
    p.add_argument("--model", action="append", metavar="[NAME=]MODEL.onnx",
                   help="exported models to compare, named in the report by NAME (default: its file's stem); the "
                        "first is the one the others' differences are taken from (default: the shipped one)")
    p.add_argument("--name", default="realcam", help="the report's name in --out")
    return p


def _sets() -> tuple[list[tuple[str, str, list, tuple[str, ...]]], dict[str, Any]]:
    """(key, title, samples, readings) of each real set, and the Udacity camera as the product found it. The
    other DDAD cameras show the car's own body low in the picture, where the roof LiDAR sees road the camera
    cannot, so only objects are read there."""
    uda, uda_info = udacity_samples()
    bands = tuple(OBJECT_BANDS)
    return [("ddad", "DDAD front (LiDAR)", ddad_samples("front"), ("road", "object", *bands, "car distance")),
            ("ddad_other", "DDAD other cameras (LiDAR)", ddad_samples("other"), ("object", *bands, "car distance")),
            ("udacity", "Udacity (lane geometry)", uda, ("road",))], uda_info


def _readings(engine: Engine, samples: list, readings: tuple[str, ...], way: str, picture_to: Path | None):
    """Predicted and true depth of each reading over ``samples`` read ``way``; the first sample's picture
    written to ``picture_to`` when given."""
    got: dict[str, tuple[list[np.ndarray], list[np.ndarray]]] = {r: ([], []) for r in readings}
    for s in samples:
        pr, raw_depth, raw_prob = predict(engine, s, way)
        for r in readings:
            if r == "car distance":
                pd, td = object_distances(pr, s)
            else:
                m = s.points(r)
                pd, td = pr[m], s.z[m]
            got[r][0].append(pd)
            got[r][1].append(td)
        if picture_to is not None and s is samples[0]:
            cv2.imwrite(str(picture_to), picture(s, raw_depth, raw_prob, engine.threshold))
    return got


def _model_section(name: str, engine: Engine, sets: list, out: Path,
                   errors: dict[str, dict[str, FrameErrors]]) -> tuple[dict[str, Any], list[str]]:
    """One model's figures on every set, both ways, and its report section; its per-frame errors in the model
    camera added to ``errors`` ("data / reading" -> model)."""
    res: dict[str, Any] = {}
    lines = [f"## {name}", "", "| data | reading | way | " + " | ".join(f"{lo}-{hi} m AbsRel / median / d1"
                                                                      for lo, hi in BINS) + " |",
             "|---|---|---|" + "---|" * len(BINS)]
    for key, title, samples, readings in sets:
        for way in ("resize", "model camera"):
            shown = out / f"realcam_{name}_{key}.png" if way == "model camera" else None
            got = _readings(engine, samples, readings, way, shown)
            for r in readings:
                if not got[r][0]:
                    continue
                if way == "model camera":
                    errors.setdefault(f"{title} / {r}", {})[name] = FrameErrors.of(*got[r])
                m = metrics(np.concatenate(got[r][0]), np.concatenate(got[r][1]))
                res[f"{title} / {r} / {way}"] = m
                cells = [f"{m[b]['abs_rel']:.3f} / {m[b]['median_ratio']:.2f} / {m[b]['delta_1.25']:.2f}"
                         + (f" ({m[b]['n']})" if r == "car distance" else "")
                         if (b := f"{lo}-{hi}") in m else "-" for lo, hi in BINS]
                lines.append(f"| {title} | {r} | {way} | " + " | ".join(cells) + " |")
    lines += ["", "Car distance cells give the number of objects in brackets (an object seen in three "
              "frames counts three times).", "",
              " ".join(f"![{name} {title}](realcam_{name}_{key}.png)" for key, title, samples, _ in sets
                       if samples), "",
              "Frames: " + "; ".join(sorted({licence("ddad" if key.startswith("ddad") else key)
                                             for key, _, samples, _ in sets if samples})).rstrip(".") + ".", ""]
    return res, lines


def measure(args: argparse.Namespace, p: argparse.ArgumentParser) -> Report | None:
    try:
        models = named(args.model or [str(DEFAULT_MODEL)])
    except ValueError as e:
        p.error(str(e))
    names = list(models)
    if not REAL.is_dir():
        print(f"no real data at {REAL}: nothing to measure")
        return None
    sets, uda_info = _sets()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    results: dict[str, Any] = {"models": {}, "udacity_camera": uda_info,
                               "frames": {title: len(samples) for _, title, samples, _ in sets}}
    lines = ["# Real cameras: depth before and after the model camera", "",
             "Before: the frame resized into the model (what bsn-run did). After: warped into the model camera "
             "with the camera's calibration (`ModelFrame`), depth brought back by the height ratio. "
             f"Udacity camera from the product's own steps: {uda_info['mounting']}.", "",
             "Readings: `road` and `object` are per LiDAR point (objects: 0.3-2.5 m above the road plane, "
             f"within {CORRIDOR_M:g} m of the camera's heading: cars, people, poles, hedges; "
             + ", ".join(f"`{r}`: those {lo:g}-{hi:g} m above it" for r, (lo, hi) in OBJECT_BANDS.items())
             + "); `car distance` is "
             f"per object (points on touching {OBJECT_CELL_M:g} m ground cells, at least {OBJECT_MIN_POINTS} "
             f"in view), its nearest ({NEAREST_PCT}th percentile) depth, binned by the true distance: what "
             "the bus carries. Frames: " + ", ".join(f"{t} {len(s)}" for _, t, s, _ in sets) + ".", ""]
    errors: dict[str, dict[str, FrameErrors]] = {}       # "data / reading" -> model -> its frames' errors
    for name, mp in models.items():
        results["models"][name], section = _model_section(name, load_engine(mp), sets, out, errors)
        lines += section
    table, results["intervals"] = interval_table(errors, names)
    lo, hi = SPAN_M
    lines += [f"## Model camera, {lo}-{hi} m: AbsRel and its 90 % interval over the frames", "",
              f"The frames resampled with replacement {RESAMPLES:,} times (a frame's points together); "
              f"each model after the first also as its difference from `{names[0]}` over the same "
              "resamples (`*`: the interval leaves out 0). A difference without `*` is within what these "
              "frames' own spread gives; one with it holds on these frames, not necessarily on other cars "
              "and scenes (the resampling draws only the frames there are).", "", *table, ""]
    return Report(results, lines, lines)


def main(argv: list[str] | None = None) -> int:
    return run(measure, parser(), argv)


if __name__ == "__main__":
    raise SystemExit(main())
