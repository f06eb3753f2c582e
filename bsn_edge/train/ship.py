"""A run handed out: its weights and teacher in half precision, its card re-digested, no optimizer state."""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

import torch

from bsn_edge.sequence.images import atomic_write_bytes
from bsn_edge.train.run import Run, RunError, to_bytes
from bsn_edge.train.run_record import last_parts


def ship_run(run: Run, dest: str | Path, dtype: torch.dtype = torch.float16, force: bool = False) -> Run:
    """A copy of ``run`` to hand out: the weights and the teacher in ``dtype`` (half the size in
    fp16), the card re-digested for them and the teacher's sha256 recorded, the config and the
    history; no optimizer state. Fine-tuning (``train.init``), ``bsn-adapt``, ``bsn-eval`` and
    ``bsn-export`` take it as they take the run."""
    out = Run(dest)
    if out.path.resolve() == run.path.resolve():
        raise RunError(f"{dest}: shipping a run onto itself")
    if out.exists() and not force:
        raise RunError(f"{out.path} already holds a run; pass force to replace it")
    # everything read before anything is written: the destination may be where this run started
    # from or where its teacher is (the next leg of a campaign shipped over the last)
    info = run.info()
    model, card = run.load_model()
    teacher = run.load_teacher_state()

    def cast(state: dict[str, torch.Tensor]) -> dict[str, torch.Tensor]:
        return {k: (v.detach().to(dtype) if v.is_floating_point() else v.detach()).contiguous()
                for k, v in state.items()}

    out.path.mkdir(parents=True, exist_ok=True)
    if force:
        out.teacher_path.unlink(missing_ok=True)
    weights = to_bytes(cast(model.state_dict()))
    record = {k: v for k, v in info.items() if k != "card"}
    record.update(card=card.replace(weights_sha256=hashlib.sha256(weights).hexdigest()).to_dict(),
                  weights_dtype=str(dtype).removeprefix("torch."), shipped_from=run.path.name)
    if teacher is not None:
        tdata = to_bytes(cast(teacher))
        out.teacher_path.parent.mkdir(parents=True, exist_ok=True)
        atomic_write_bytes(out.teacher_path, tdata)
        record["teacher_sha256"] = hashlib.sha256(tdata).hexdigest()
    atomic_write_bytes(out.model_path, weights)
    if run.history_path.is_file():
        atomic_write_bytes(out.history_path, run.history_path.read_bytes())
    if run.config_path.is_file():
        # no path of this machine in a run handed out: the teacher travels with it, the start is named
        cfg = run.config()
        if teacher is not None and "teacher" in cfg:
            cfg["teacher"]["checkpoint"] = ""
        if cfg.get("train", {}).get("init"):
            cfg["train"]["init"] = last_parts(cfg["train"]["init"])
        out.write_config(cfg)
    out.state_path.unlink(missing_ok=True)
    atomic_write_bytes(out.checkpoint_path, (json.dumps(record, indent=2) + "\n").encode())
    return out
