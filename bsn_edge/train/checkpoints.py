"""A training run's folder as training writes it: prepared (new, resumed or started again), checkpoints
with everything a resumed piece needs, and the final card with its chosen threshold."""

from __future__ import annotations

import shutil
from pathlib import Path
from typing import Any

import numpy as np
import torch
import torch.distributed as dist

from bsn_edge.card import UNCHOSEN_THRESHOLD, ModelCard
from bsn_edge.labels.generator import label_camera
from bsn_edge.networks import MAX_DEPTH_M, MIN_DEPTH_M, BlindSpotNet, get_spec
from bsn_edge.sequence import SequenceMeta
from bsn_edge.sequence.folder import SequenceFolder
from bsn_edge.train.batches import Datasets
from bsn_edge.train.config import Config
from bsn_edge.train.optim import Optimizer
from bsn_edge.train.run import Run, RunError
from bsn_edge.train.validation import choose_threshold


def prepare_run(out: str | Path, resume: bool = False, force: bool = False) -> Run:
    """The run folder to train into: a new one, the same one continued (``resume``), or an existing
    one started again (``force``, which removes the old checkpoint, state and teacher)."""
    run = Run(out)
    if resume and force:
        raise ValueError("--resume and --force contradict each other: continue the run, or start it again")
    if run.exists() and not (resume or force):
        raise RunError(f"{run.path} already holds a run; pass --resume to continue it or --force to start again")
    if force:
        for p in (run.model_path, run.checkpoint_path, run.state_path):
            p.unlink(missing_ok=True)
        shutil.rmtree(run.teacher_path.parent, ignore_errors=True)
    return run


def open_run(cfg: Config, out: str | Path, resume: bool, force: bool, rank: int,
              world: int) -> tuple[Run, list[Path], dict[str, Any] | None]:
    """The run folder (torn writes of a killed piece removed), the seeds set, and its saved state when
    resuming: ``(run, torn, state)``."""
    run = prepare_run(out, resume, force) if rank == 0 else Run(out)
    torn = run.remove_torn_writes() if rank == 0 and (resume or force) else []
    if world > 1:
        dist.barrier()
    torch.manual_seed(cfg.train.seed + rank)
    np.random.seed(cfg.train.seed + rank)
    torch.set_num_threads(cfg.train.threads)
    state = run.load_state() if resume else None
    if resume:
        check_resumable(run, cfg, state)
    return run, torn, state


def carried(state: dict[str, Any] | None) -> tuple[list[list[float]], list[float] | None]:
    """What the loss records carry across pieces: the losses since the last record (a record after a
    stop between records averages the same steps as the uninterrupted run's) and the run's first step's."""
    if state is None:
        return [], None
    return [list(x) for x in state.get("since", [])], state.get("first_loss")


def checkpoint(run: Run, model: BlindSpotNet, optim: Optimizer, cfg: Config, data, done: int, world: int,
                seconds: float, kinds: list[str], since: list[list[float]], first: list[float] | None) -> None:
    """Save the weights and everything a resumed piece needs to go on as if never stopped."""
    trained = {"samples": done * cfg.train.batch_size * world, "seconds": round(seconds, 1), "precision": kinds}
    save_checkpoint(run, model, cfg, data, done, threshold=None, trained=trained,
          resume_state={**optim.state_dict(), "step": done, "torch_rng": torch.get_rng_state(),
                        "seconds": seconds, "precision": kinds, "since": since, "first_loss": first})


def check_resumable(run: Run, cfg: Config, state: dict[str, Any] | None) -> None:
    """``RunError`` when ``run`` cannot go on under ``cfg``: no state to resume from, or another model."""
    if state is None and run.exists() and not run.teacher_state_path.is_file():
        raise RunError(f"{run.path}: no {Run.STATE} to resume from (made by an older version, or a run that "
                       "never checkpointed); --force starts it again")
    if run.config_path.is_file() and run.config().get("model", {}).get("name") not in (None, cfg.model.name):
        raise RunError(f"{run.path} trains {run.config()['model']['name']!r}, the config asks for {cfg.model.name!r}")


def save_checkpoint(run: Run, model, cfg: Config, data: Datasets, step: int, threshold: float | None,
          val: dict | None = None, loss_first_last: list | None = None,
          resume_state: dict[str, Any] | None = None, trained: dict[str, Any] | None = None) -> ModelCard:
    """A checkpoint of ``model`` with its card; ``threshold`` None keeps the previous one (if any).
    ``trained``: samples seen and seconds spent up to ``step`` (None keeps the previous record)."""
    first = data.train[0].path
    # the labels' camera (bsn-label --calib's calibration when one was given), else the clip's
    camera = label_camera(SequenceFolder(first).labels(cfg.data.label)) or SequenceMeta.read(first).intrinsics
    model_camera, model_mounting = cfg.data.model_camera()
    h, w = cfg.data.size
    prev: dict[str, Any] = {}
    if run.checkpoint_path.is_file():
        prev = run.info()
        prev["threshold"] = prev["card"].threshold
    card_fields = {
        "variant": cfg.model.name, "spec": get_spec(cfg.model.name).to_dict(), "input_size": (h, w),
        "threshold": threshold if threshold is not None else prev.get("threshold"),
        "camera": model_camera, "mounting": model_mounting, "depth_range": (MIN_DEPTH_M, MAX_DEPTH_M),
        "config_digest": cfg.digest(), "train_camera": camera,
    }
    info = {
        "step": step, "label": cfg.data.label, "distill_weight": cfg.distill_weight,
        "train_clips": [c.path.name for c in data.train], "val_clips": [c.path.name for c in data.val],
        "test_clips": [c.path.name for c in data.clips["test"]],
        "val": val if val is not None else prev.get("val", {}),
    }
    if (trained := trained or prev.get("trained")) is not None:
        info["trained"] = trained
    if (start := prev.get(Run.INIT_RECORD) or run.init_record(cfg.train.init)) is not None:
        info[Run.INIT_RECORD] = start
    if loss_first_last:
        info["loss_first_last"] = loss_first_last
    return run.save(model, card_fields, info, resume_state)


def finish(run: Run, model: BlindSpotNet, cfg: Config, data, loss_first_last) -> dict[str, Any]:
    """The threshold chosen on the validation clips and the final card written; what the summary adds."""
    out: dict[str, Any] = {}
    threshold = UNCHOSEN_THRESHOLD
    val: dict[str, Any] = {}
    if data.val_ds is not None:
        threshold, val = choose_threshold(model, data.val_ds)
    else:
        out["threshold_note"] = f"no validation clips: threshold left at {UNCHOSEN_THRESHOLD}"
    card = save_checkpoint(run, model, cfg, data, cfg.train.steps, threshold=threshold, val=val,
                           loss_first_last=loss_first_last)
    return {**out, "threshold": threshold, "val": val, "weights_sha256": card.weights_sha256}
