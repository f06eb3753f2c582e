"""Validation: the figures the history records, and the decision threshold chosen on the validation
clips."""

from __future__ import annotations

import torch
from torch.utils.data import DataLoader

from bsn_edge import semantics as sm
from bsn_edge.data.cache import SampleCache
from bsn_edge.metrics import ThresholdSweep
from bsn_edge.networks import MAX_DEPTH_M, MIN_DEPTH_M, BlindSpotNet
from bsn_edge.train.config import Config
from bsn_edge.train.device import autocast, layout


def given_depth(model: torch.nn.Module, b: dict[str, torch.Tensor]) -> torch.Tensor | None:
    """The ground-truth depth of batch ``b`` for a model whose B reads it (``oracle_depth``, a research
    arm), else None. ``model`` may be wrapped (DistributedDataParallel)."""
    inner = getattr(model, "module", model)
    return b["depth"] if getattr(inner, "oracle_depth", False) else None


def outputs(model: torch.nn.Module, x: torch.Tensor, b: dict[str, torch.Tensor]) -> tuple[torch.Tensor, ...]:
    """``model(x)``, and for an ``oracle_depth`` model ``model(x, depth)`` with batch ``b``'s depth."""
    depth = given_depth(model, b)
    return model(x) if depth is None else model(x, depth.to(x.device))


@torch.no_grad()
def sweep_thresholds(model: torch.nn.Module, ds, batch: int = 8) -> ThresholdSweep:
    """The counts inside V on ``ds`` at every candidate threshold."""
    model.eval()
    sweep = ThresholdSweep()
    dev = next(model.parameters()).device
    for b in DataLoader(ds, batch_size=batch):
        prob = torch.sigmoid(outputs(model, b["image"].to(dev), b)[0]).cpu().numpy()
        sweep.add(prob, b["blindspot"].numpy() > 0.5, b["visibility"].numpy() > 0.5)
    return sweep


def choose_threshold(model: torch.nn.Module, ds, batch: int = 8) -> tuple[float, dict[str, float]]:
    """The threshold with the best IoU inside V on ``ds`` (the validation split)."""
    return sweep_thresholds(model, ds, batch).best()


ROAD_RANGE_M = (5.0, 40.0)   # as the real-camera benchmark reads road depth


@torch.no_grad()
def validate(model: torch.nn.Module, cache: SampleCache, frames: int, dtype: torch.dtype | None = None,
             channels_last: bool = False) -> dict[str, float]:
    """Validation figures on up to ``frames`` evenly spaced samples of ``cache``: IoU inside V at the
    best threshold of the sweep, D's depth AbsRel (pixels with depth, sky left out) and, apart, on
    the road ``ROAD_RANGE_M`` away (the road the product reads its geometry from, which the
    all-pixel figure can hide)."""
    was = model.training
    model.eval()
    dev = next(model.parameters()).device
    sweep = ThresholdSweep()
    err, n, road_err, road_n = 0.0, 0, 0.0, 0
    for b in cache.evenly(frames):
        with autocast(dev, dtype):
            logits, depth, _ = outputs(model, layout(b["image"].to(dev), channels_last), b)
        sweep.add(torch.sigmoid(logits.float()).cpu().numpy(), b["blindspot"].numpy() > 0.5,
                  b["visibility"].numpy() > 0.5)
        gt = b["depth"]
        rel = (depth.float().cpu() - gt).abs() / gt.clamp_min(MIN_DEPTH_M)
        ok = (gt >= MIN_DEPTH_M) & (gt <= MAX_DEPTH_M) & ~b["sky"]
        road = ok & (b["semantic"][:, None] == sm.ROAD) & (gt >= ROAD_RANGE_M[0]) & (gt <= ROAD_RANGE_M[1])
        err, n = err + float(rel[ok].sum()), n + int(ok.sum())
        road_err, road_n = road_err + float(rel[road].sum()), road_n + int(road.sum())
    model.train(was)
    threshold, metrics = sweep.best()
    return {"iou": metrics["iou"], "threshold": threshold, "abs_rel": err / max(n, 1),
            "road_abs_rel": road_err / road_n if road_n else float("nan")}


def validation_figures(model: BlindSpotNet, cfg: Config, dtype: torch.dtype | None,
                val_caches: dict[str, SampleCache]) -> dict[str, float]:
    """The history's validation figures: :func:`validate` on each cache, keys prefixed as named."""
    return {f"{prefix}{k}": v for prefix, c in val_caches.items()
            for k, v in validate(model, c, cfg.train.eval_frames, dtype, cfg.train.channels_last).items()}
