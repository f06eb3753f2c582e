"""The architectures' size and speed for the paper's Table 3 (``bench_arch``): parameters, GMACs and the fp32
ONNX model's time, or the times of an earlier report of it."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import torch
from torch.utils.flop_counter import FlopCounterMode

from bsn_edge.camera import Intrinsics
from bsn_edge.export import to_onnx
from bsn_edge.modelfile.read import session
from bsn_edge.networks import create_model, describe

from .common import summary, time_calls


def count_gmacs(model: torch.nn.Module, size: tuple[int, int]) -> float:
    """Multiply-accumulates of one forward pass at ``size`` (H, W), in billions."""
    with FlopCounterMode(display=False) as fc, torch.no_grad():
        model(torch.zeros(1, 3, *size))
    return fc.get_total_flops() / 2e9


def measure_arch(name: str, size: tuple[int, int], repeats: int, workdir: Path, timed: dict | None = None) -> dict:
    """Parameters and GMACs of ``name``, and its fp32 ONNX model's median time at ``size``; with ``timed``
    (a row of an earlier report) its time is taken from there instead of measured."""
    torch.manual_seed(0)
    m = create_model(name).eval()
    row = {"model": name, "params_m": round(sum(p.numel() for p in m.parameters()) / 1e6, 2),
           "gmacs": round(count_gmacs(m, size), 2)}
    if timed is not None:
        return {**row, **{k: timed[k] for k in ("median_ms", "fps", "repeats")}}
    path = workdir / f"{name}.onnx"
    # timing only: any camera of the right size will do
    to_onnx(m, path, describe(name, m, Intrinsics.from_fov(size[1], size[0], 80.0)))
    sess = session(path, threads=2)
    frame = np.random.default_rng(0).integers(0, 256, (1, *size, 3), dtype=np.uint8)
    med = summary(time_calls(lambda _: sess.run(None, {"frame": frame}), repeats, warmup=5))["median_ms"] / 1e3
    return {**row, "median_ms": round(1e3 * med, 2), "fps": round(1 / med, 2), "repeats": repeats}


def earlier_timing(path: Path, size: tuple[int, int]) -> tuple[dict[str, dict], dict]:
    """The rows of an earlier report of this benchmark by architecture, and where their times were
    measured (its own machine, or the report it took them from in turn)."""
    res = json.loads(path.read_text())
    if res.get("benchmark") is None or "rows" not in res:
        raise ValueError(f"{path} is not a report of this benchmark (no 'benchmark' and 'rows')")
    if res.get("size") != list(size) or res.get("threads") != 2:
        raise ValueError(f"{path} timed at {res.get('size')} with {res.get('threads')} threads, not "
                         f"{list(size)} with 2")
    source = res.get("timing_from") or {"report": res["benchmark"], "measured_at": res["measured_at"],
                                        "machine": res["machine"]}
    return {r["model"]: r for r in res["rows"] if {"median_ms", "fps", "repeats"} <= r.keys()}, source
