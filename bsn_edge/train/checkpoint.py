"""Checkpoints that never unpickle arbitrary objects.

A run folder holds ``model.pt`` (a state dict of tensors, loaded with ``weights_only=True``),
``checkpoint.json`` (model name and spec, step, decision threshold, training size, intrinsics,
config digest, weights sha256, validation metrics) and ``config.json`` (the resolved config).
Training state for resuming lives in ``state.pt`` (optimizer state and step, tensors and
numbers only).
"""

from __future__ import annotations

import hashlib
import io
import json
from pathlib import Path
from typing import Any

import torch

from bsn_edge.models import BlindSpotNet, build, get_spec
from bsn_edge.models.registry import ModelSpec
from bsn_edge.sequence.images import atomic_write_bytes

MODEL_FILE, META_FILE, STATE_FILE, CONFIG_FILE = "model.pt", "checkpoint.json", "state.pt", "config.json"


def _tensor_bytes(obj: Any) -> bytes:
    buf = io.BytesIO()
    torch.save(obj, buf)
    return buf.getvalue()


def save_model(run: Path, model: torch.nn.Module, meta: dict[str, Any]) -> dict[str, Any]:
    """Write the weights and their metadata atomically; returns the metadata written."""
    run.mkdir(parents=True, exist_ok=True)
    data = _tensor_bytes({k: v.detach().cpu() for k, v in model.state_dict().items()})
    atomic_write_bytes(run / MODEL_FILE, data)
    meta = {**meta, "weights_sha256": hashlib.sha256(data).hexdigest()}
    atomic_write_bytes(run / META_FILE, (json.dumps(meta, indent=2) + "\n").encode())
    return meta


def read_meta(run: str | Path) -> dict[str, Any]:
    p = Path(run) / META_FILE
    if not p.is_file():
        raise FileNotFoundError(f"{run}: not a training run (no {META_FILE})")
    return json.loads(p.read_text())


def load_model(run: str | Path) -> tuple[BlindSpotNet, dict[str, Any]]:
    """The trained model of a run (eval mode) and its metadata. Refuses weights whose sha256
    does not match the metadata, or whose tensors do not fit the recorded architecture."""
    run = Path(run)
    meta = read_meta(run)
    data = (run / MODEL_FILE).read_bytes()
    if hashlib.sha256(data).hexdigest() != meta.get("weights_sha256"):
        raise ValueError(f"{run / MODEL_FILE}: weights do not match {META_FILE} (sha256 differs)")
    spec = ModelSpec(**meta["spec"]) if "spec" in meta else get_spec(meta["model"])
    model = build(spec)
    state = torch.load(io.BytesIO(data), map_location="cpu", weights_only=True)
    try:
        model.load_state_dict(state)
    except RuntimeError as e:
        raise ValueError(f"{run}: weights do not fit model {meta.get('model')!r}: {str(e)[:300]}") from None
    return model.eval(), meta


def save_state(run: Path, optimizer: torch.optim.Optimizer, step: int, scheduler=None) -> None:
    state = {"optimizer": optimizer.state_dict(), "step": step}
    if scheduler is not None:
        state["scheduler"] = scheduler.state_dict()
    atomic_write_bytes(run / STATE_FILE, _tensor_bytes(state))


def load_state(run: Path) -> dict[str, Any] | None:
    p = run / STATE_FILE
    if not p.is_file():
        return None
    return torch.load(p, map_location="cpu", weights_only=True)
