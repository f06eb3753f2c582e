"""The source run's own depth head and teacher as label sources: no outside model.

The fused model (exported as ``bsn-export`` would, fp32) gives depth through ``bsn:MODEL`` (the
frame warped into its camera with the clip's calibration, then aligned to the visual odometry's
landmarks); the segmentation teacher the run distilled from gives road, sky and objects through
``onnx:MODEL`` (Cityscapes trainIds, ImageNet-normalised RGB in).
"""

from __future__ import annotations

import io
import warnings
from pathlib import Path

import numpy as np
import torch
from torch import Tensor, nn

from bsn_edge import semantics as sm
from bsn_edge.export.pipeline import export_run
from bsn_edge.labels.sources.base import SegSource
from bsn_edge.sequence.images import atomic_write_bytes
from bsn_edge.train.run import Run

OPSET = 17


class _Scores(nn.Module):
    """The teacher's class scores alone (its decoder features are for distillation)."""

    def __init__(self, teacher: nn.Module) -> None:
        super().__init__()
        self.teacher = teacher

    def forward(self, x: Tensor) -> Tensor:
        return self.teacher(x)[0]


def load_teacher(run: Run, model_run: Run | None = None) -> tuple[nn.Module, tuple[int, int], float]:
    """The run's segmentation teacher (eval mode), the input size it is fed at (its scale of
    ``model_run``'s input, by default the run's own) and that scale. ``FileNotFoundError`` when the
    run has none."""
    teacher = run.load_teacher()
    if teacher is None:
        raise FileNotFoundError(f"{run.path}: no teacher ({run.TEACHER}/teacher.pt); bsn-adapt labels with a "
                                "run's teacher (train with bsn-train, which keeps it)")
    h, w = (model_run or run).card().input_size
    scale = run.teacher_config().scale
    size = (max(32, round(h * scale / 32) * 32), max(32, round(w * scale / 32) * 32))
    return teacher, size, scale


def export_teacher(run: Run, out: Path, model_run: Run | None = None) -> Path:
    """The run's teacher as ONNX: float RGB ``[1, 3, H, W]`` (ImageNet-normalised) in, 19 class
    scores out, at the size it is fed at (:func:`load_teacher`)."""
    teacher, (h, w), _ = load_teacher(run, model_run)
    buf = io.BytesIO()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        # the stubs name only paths, but the exporter writes to any binary file object
        torch.onnx.export(_Scores(teacher).eval(), (torch.zeros(1, 3, h, w),), buf,  # type: ignore[arg-type]
                          input_names=["image"],
                          output_names=["scores"], opset_version=OPSET, dynamo=False, do_constant_folding=True)
    out.parent.mkdir(parents=True, exist_ok=True)
    atomic_write_bytes(out, buf.getvalue())
    return out


def prepare_labeller(run: Run, depth_out: Path, teacher_out: Path, teacher: Run | None = None) -> dict[str, str]:
    """Both label models, made once (kept when already there): ``run``'s depth head and ``teacher``'s
    segmentation (by default ``run``'s own teacher)."""
    if not depth_out.is_file():
        export_run(run.path, depth_out, log=io.StringIO())
    if not teacher_out.is_file():
        export_teacher(teacher or run, teacher_out, run)
    return {"depth": f"bsn:{depth_out}", "seg": f"onnx:{teacher_out}"}


def road_share(seg: SegSource, frames: int, samples: int = 5) -> float:
    """Share of the lower half of ``samples`` frames (evenly over ``frames``) that ``seg`` calls
    road or sidewalk."""
    shares = []
    for i in np.linspace(0, frames - 1, min(samples, frames)).round().astype(int):
        cls = seg(int(i))
        shares.append(float(sm.is_traversable(cls[cls.shape[0] // 2:]).mean()))
    return float(np.mean(shares)) if shares else 0.0
