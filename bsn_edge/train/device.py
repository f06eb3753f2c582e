"""Where and in what arithmetic training runs: the process group, the device, bf16 autocast and the
memory layout, and resizing a batch for a network that reads it at another scale."""

from __future__ import annotations

import os

import torch
import torch.distributed as dist
import torch.nn.functional as F

from bsn_edge.card import PRECISION_BF16, PRECISION_FP32
from bsn_edge.train.config import Config


def distributed() -> tuple[int, int]:
    """(rank, world size); starts the process group when launched by torchrun."""
    world = int(os.environ.get("WORLD_SIZE", "1"))
    if world > 1 and not dist.is_initialized():
        dist.init_process_group("nccl" if torch.cuda.is_available() else "gloo")
    return (dist.get_rank(), world) if world > 1 else (0, 1)


def cpu_has_native_bf16() -> bool:
    """Whether this CPU multiplies bf16 natively (AMX tiles or AVX-512 BF16)."""
    return any(getattr(torch.cpu, name, lambda: False)() for name in ("_is_amx_tile_supported",
                                                                       "_is_avx512_bf16_supported"))


def autocast_dtype(cfg: Config, device: torch.device) -> torch.dtype | None:
    """The autocast dtype of ``train.precision`` on ``device`` (None: fp32)."""
    want = cfg.train.precision
    if want == "auto":
        want = PRECISION_BF16 if device.type == "cpu" and cpu_has_native_bf16() else PRECISION_FP32
    return torch.bfloat16 if want == PRECISION_BF16 else None


def precision_name(dtype: torch.dtype | None) -> str:
    """How a history record's training arithmetic is named: ``PRECISION_BF16`` (autocast) or ``PRECISION_FP32``. Every
    record carries it: ``train.precision=auto`` trains differently on different CPUs, and a run
    resumed on another machine may change it from one piece to the next."""
    return PRECISION_BF16 if dtype == torch.bfloat16 else PRECISION_FP32


def autocast(device: torch.device, dtype: torch.dtype | None):
    return torch.autocast(device.type, dtype=dtype or torch.float32, enabled=dtype is not None)


def layout(x: torch.Tensor, channels_last: bool) -> torch.Tensor:
    return x.contiguous(memory_format=torch.channels_last) if channels_last else x


def module_layout(m: torch.nn.Module, channels_last: bool) -> torch.nn.Module:
    """``m``'s weights in channels-last memory (or back to contiguous), in place."""
    # torch's stubs lack Module.to's memory_format, which the function takes
    return m.to(memory_format=torch.channels_last if channels_last else torch.contiguous_format)  # type: ignore[call-overload]


def train_device(cfg: Config) -> torch.device:
    """Where training runs: ``train.device``, with "auto" meaning CUDA when torch sees a GPU."""
    want = cfg.train.device
    if want == "auto":
        want = "cuda" if torch.cuda.is_available() else "cpu"
    if want == "cuda" and not torch.cuda.is_available():
        raise ValueError("train.device is cuda but torch sees no GPU (a CPU build of torch, or no driver)")
    if want == "cuda":
        torch.backends.cuda.matmul.allow_tf32 = True
        torch.backends.cudnn.allow_tf32 = True
        return torch.device("cuda", int(os.environ.get("LOCAL_RANK", 0)))
    return torch.device("cpu")


def scaled(x: torch.Tensor, scale: float, mode: str = "bilinear") -> torch.Tensor:
    """``x`` resized by ``scale`` (unchanged at 1)."""
    if scale == 1.0:
        return x
    kw = {"align_corners": False} if mode == "bilinear" else {}
    return F.interpolate(x, scale_factor=scale, mode=mode, **kw)
