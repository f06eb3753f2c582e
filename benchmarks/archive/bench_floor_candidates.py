"""Speed only: what the int8 floor multiple of the light model becomes with layers int8 may run better.

    python -m benchmarks.archive.bench_floor_candidates

Each candidate is the light model with one change, untrained (weights at their initialisation,
calibrated on random frames: latency does not depend on what was learnt), exported and quantized
as ``bsn-export --int8`` does, and timed in alternation with the dense 3x3 stack of
``bench_floor`` (2 intra-op threads). Prints GMACs, median latency and the multiple of the int8
floor. Accuracy needs each candidate trained; this says only which changes are worth training.
"""

from __future__ import annotations

import dataclasses
import tempfile
from pathlib import Path

import numpy as np
import torch
from torch import nn

from bsn_edge.camera import Intrinsics
from bsn_edge.export import QuantConfig, quantize, to_onnx
from bsn_edge.models import registry
from bsn_edge.models.resnet import ResNetEncoder

from ..bench_arch import count_gmacs
from ..bench_floor import alternation, stack_rate

SIZE = (256, 512)
PROBE = "_floor_probe"      # a registry name for the candidate while it is exported


def three_by_three_stem(model: nn.Module) -> nn.Module:
    """Every ResNet 7x7 stem replaced by three 3x3 convolutions with the same stride (ResNet-C)."""
    for m in model.modules():
        if isinstance(m, ResNetEncoder):
            cin = m.stem[0].in_channels
            m.stem = nn.Sequential(
                nn.Conv2d(cin, 32, 3, 2, 1, bias=False), nn.BatchNorm2d(32), nn.ReLU(),
                nn.Conv2d(32, 32, 3, 1, 1, bias=False), nn.BatchNorm2d(32), nn.ReLU(),
                nn.Conv2d(32, 64, 3, 1, 1, bias=False), nn.BatchNorm2d(64), nn.ReLU(), nn.MaxPool2d(3, 2, 1))
    return model


def main() -> int:
    light = registry.get_spec("small-light")
    dense = dataclasses.replace(light, separable=False)
    candidates = {
        "small-light (shipped)": (light, None, True),
        "heads in int8": (light, None, False),
        "3x3 stem": (light, three_by_three_stem, True),
        "dense 3x3 decoder": (dense, None, True),
        "3x3 stem + dense decoder + heads in int8": (dense, three_by_three_stem, False),
        "one encoder for D and B (shared-light)": (registry.get_spec("shared-light"), None, True),
    }
    h, w = SIZE
    camera = Intrinsics.from_fov(w, h, 80.0)
    calib = np.random.default_rng(0).integers(0, 256, (8, h, w, 3), dtype=np.uint8)
    print("| candidate | GMACs | median ms | multiple of the int8 floor |\n|---|---|---|---|")
    with tempfile.TemporaryDirectory() as tmp:
        tmp_dir = Path(tmp)
        stack = stack_rate(256, (h // 16, w // 16), QuantConfig(), 30, tmp_dir)
        for i, (label, (spec, change, heads_float)) in enumerate(candidates.items()):
            registry.MODELS[PROBE] = spec
            try:
                torch.manual_seed(0)
                model = registry.build(spec).eval()
                if change is not None:
                    model = change(model)
                gmacs = count_gmacs(model, SIZE)
                fp32, int8 = tmp_dir / f"c{i}.onnx", tmp_dir / f"c{i}_int8.onnx"
                to_onnx(model, fp32, registry.describe(PROBE, model, camera))
                quantize(fp32, int8, calib, QuantConfig(keep_heads_float=heads_float))
            finally:
                del registry.MODELS[PROBE]
            t_model, t_stack = alternation([(int8, calib[:1]), (stack["path"], stack["input"])], 120)
            peak = stack["gmacs"] * 1e9 / t_stack
            multiple = t_model * peak / (gmacs * 1e9)
            print(f"| {label} | {gmacs:.2f} | {1e3 * t_model:.2f} | {multiple:.2f}x |", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
