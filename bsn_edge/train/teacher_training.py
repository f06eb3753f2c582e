"""The segmentation teacher: taken from a trained one, or trained (resumably) on the clips' semantics;
its held-out IoU by class group."""

from __future__ import annotations

import dataclasses
import time
from pathlib import Path
from typing import Any, cast

import numpy as np
import torch
import torch.nn.functional as F

from bsn_edge import semantics as sm
from bsn_edge.data.cache import SampleCache
from bsn_edge.networks import create_teacher
from bsn_edge.networks.alive import alive_channels
from bsn_edge.progress import progress_bar
from bsn_edge.train.batches import datasets, sample_cache, skipped_and_torn, training_batches
from bsn_edge.train.checkpoints import open_run
from bsn_edge.train.config import Config
from bsn_edge.train.device import (
    autocast,
    autocast_dtype,
    distributed,
    layout,
    module_layout,
    precision_name,
    scaled,
    train_device,
)
from bsn_edge.train.optim import Optimizer, param_groups
from bsn_edge.train.run import Run

TEACHER_CLASSES = {"road": (sm.ROAD,), "sidewalk": (sm.SIDEWALK,), "vehicle": sm.VEHICLES,
                   "person": sm.VULNERABLE}


@torch.no_grad()
def teacher_miou(teacher: torch.nn.Module, cache: SampleCache, scale: float, frames: int,
                 dtype: torch.dtype | None = None) -> dict[str, float]:
    """IoU of the teacher's road, sidewalk, vehicle and person (classes grouped) on up to ``frames``
    evenly spaced samples of ``cache``, and their mean ``miou``."""
    was = teacher.training
    teacher.eval()
    dev = next(teacher.parameters()).device
    inter = dict.fromkeys(TEACHER_CLASSES, 0)
    union = dict.fromkeys(TEACHER_CLASSES, 0)
    for b in cache.evenly(frames):
        with autocast(dev, dtype):
            logits, _ = teacher(scaled(b["image"].to(dev), scale))
        pred = F.interpolate(logits.float(), size=b["semantic"].shape[1:], mode="bilinear",
                             align_corners=False).argmax(1).cpu()
        sem = b["semantic"]
        known = sem != sm.IGNORE
        for name, ids in TEACHER_CLASSES.items():
            t = torch.isin(sem, torch.tensor(ids)) & known
            q = torch.isin(pred, torch.tensor(ids)) & known
            inter[name] += int((t & q).sum())
            union[name] += int((t | q).sum())
    teacher.train(was)
    out = {name: inter[name] / union[name] if union[name] else float("nan") for name in TEACHER_CLASSES}
    out["miou"] = float(np.nanmean(list(out.values())))
    return out


def with_teachers_build(cfg: Config) -> Config:
    """``cfg`` with the build (encoder, its start, width, input scale) of the teacher that
    ``teacher.checkpoint`` or ``teacher.init`` names, as that teacher was trained, so the run's config
    says what its teacher is and the teacher sees frames as it learnt to."""
    t = cfg.teacher
    if not (t.checkpoint or t.init):
        return cfg
    held = Run.of_teacher(t.checkpoint or t.init).teacher_config()
    return dataclasses.replace(cfg, teacher=dataclasses.replace(t, encoder=held.encoder, pretrained=held.pretrained,
                                                                width=held.width, scale=held.scale))


def _teacher_to_start(cfg: Config, run: Run) -> tuple[torch.nn.Module, bool]:
    """The teacher to start from, and whether it is finished: ``teacher.checkpoint``'s, or the run's own
    finished one; else a new one (from ``teacher.init``'s weights when given) to train."""
    t = cfg.teacher
    if t.checkpoint:
        teacher = Run.of_teacher(t.checkpoint).load_teacher()
        if teacher is None:
            raise FileNotFoundError(f"teacher.checkpoint {t.checkpoint}: no teacher/teacher.pt there")
        return teacher, True
    state = run.load_teacher_state()
    if state is not None:
        teacher = create_teacher(t.encoder, t.width)
        teacher.load_state_dict(state)
        return teacher, True
    teacher = create_teacher(t.encoder, t.width, pretrained=t.pretrained and not t.init)
    if t.init:
        state = Run.of_teacher(t.init).load_teacher_state()
        if state is None:
            raise FileNotFoundError(f"teacher.init {t.init}: no teacher/teacher.pt there")
        teacher.load_state_dict(state)
    return teacher, False


def _teacher_record(teacher: torch.nn.Module, cfg: Config, val_cache, dtype: torch.dtype | None, step: int,
                    samples: int, seconds: float) -> dict[str, Any]:
    """The teacher's history line at ``step``: its held-out IoU by class group."""
    miou = teacher_miou(teacher, val_cache, cfg.teacher.scale, cfg.train.eval_frames, dtype)
    return {"phase": "teacher", "step": step, "samples": samples, "seconds": round(seconds, 1),
            "precision": precision_name(dtype), **{f"val_{k}": v for k, v in miou.items()},
            **alive_channels(teacher).to_dict()}


def train_teacher(cfg: Config, ds, run: Run, rank: int, world: int, progress: bool,
                  cache: SampleCache | None = None, val_cache: SampleCache | None = None,
                  resume: bool = False) -> torch.nn.Module:
    """The segmentation teacher, trained on the dataset's semantics (or loaded). With ``val_cache``
    and ``teacher.eval_every``, its held-out mIoU is recorded in the run's history. Its state is saved
    every ``teacher.checkpoint_every`` steps; ``resume`` goes on from the last one, on the same stream
    of batches (the schedule spans ``teacher.steps``)."""
    t = cfg.teacher
    dev = train_device(cfg)
    teacher, finished = _teacher_to_start(cfg, run)
    if finished:
        return teacher.to(dev).eval()
    saved = run.load_teacher_progress() if resume else None
    if saved is not None:
        teacher.load_state_dict(saved["weights"])
    cl = cfg.train.channels_last
    module_layout(teacher.to(dev), cl)
    dtype = autocast_dtype(cfg, dev)
    model = torch.nn.parallel.DistributedDataParallel(teacher) if world > 1 else teacher
    encoder = cast(torch.nn.Module, teacher.encoder)
    optim = Optimizer(param_groups(teacher, encoder, t.lr, t.encoder_lr if t.pretrained else 1.0), t.lr,
                      t.steps, cfg.train)
    start, seconds_before = 0, 0.0
    if saved is not None:
        optim.load_state_dict(saved)
        start, seconds_before = int(saved["step"]), float(saved.get("seconds", 0.0))
    batches = training_batches(ds, cache, t.batch_size, world, rank, cfg.train.seed + 1, cfg.data.workers, start,
                               device=dev, real_share=cfg.data.real_share)
    if saved is not None and "torch_rng" in saved:
        torch.set_rng_state(saved["torch_rng"])
    bar = progress_bar(range(start, t.steps), initial=start, total=t.steps, desc="teacher", unit="step",
                       enabled=progress and not rank)
    if rank == 0:
        run.trim_history("teacher", start)
        if start == 0 and t.init and val_cache is not None and t.eval_every:
            # where a teacher trained on from another begins
            run.append_history(_teacher_record(teacher, cfg, val_cache, dtype, 0, 0, 0.0))
    model.train()
    losses, t0 = [], time.perf_counter()
    for step in bar:
        b = next(batches)
        with autocast(dev, dtype):
            logits, _ = model(layout(scaled(b["image"], t.scale), cl))
        target = scaled(b["semantic"][:, None].float(), t.scale, "nearest")[:, 0].long()
        loss = F.cross_entropy(logits.float(), target, ignore_index=sm.IGNORE)
        optim.step(loss)
        losses.append(loss.item())
        bar.set_postfix(ce=f"{losses[-1]:.3f}")
        done = step + 1
        seconds = seconds_before + time.perf_counter() - t0
        if rank == 0 and val_cache is not None and t.eval_every and (done % t.eval_every == 0 or done == t.steps):
            run.append_history({**_teacher_record(teacher, cfg, val_cache, dtype, done, done * t.batch_size * world,
                                                  seconds), "ce": float(np.mean(losses))})
            losses = []
        if rank == 0 and done < t.steps and done % t.checkpoint_every == 0:
            run.save_teacher_progress(teacher.state_dict(), {**optim.state_dict(), "step": done,
                                                             "torch_rng": torch.get_rng_state(), "seconds": seconds})
    if rank == 0:
        run.save_teacher({k: v.contiguous() for k, v in teacher.state_dict().items()})
    return teacher.eval()


def train_teacher_alone(cfg: Config, data_dir: str | Path, out: str | Path, resume: bool = False,
                        progress: bool = True, force: bool = False) -> dict[str, Any]:
    """Train the segmentation teacher alone into ``out`` (``teacher/teacher.pt``, ``config.json`` and
    the history), for later runs to distil from with ``teacher.checkpoint``: no student, no teacher
    features cached. ``resume`` goes on from the teacher's last state; a teacher trained already is
    left as it is."""
    if cfg.teacher.checkpoint:
        raise ValueError("training a teacher alone: teacher.checkpoint names one trained already")
    rank, world = distributed()
    run, torn, _ = open_run(cfg, out, resume, force, rank, world)
    data = datasets(cfg, data_dir)
    if rank == 0:
        run.write_config(cfg.to_dict())
    show = progress and rank == 0
    cache = sample_cache(cfg, data.train_ds, show, "caching training samples")
    val = sample_cache(cfg, data.val_ds, show, "caching validation samples") \
        if data.val_ds is not None and cfg.data.cache != "off" else None
    train_teacher(cfg, data.train_ds, run, rank, world, progress, cache, val, resume=resume)
    return {"teacher_steps": cfg.teacher.steps, "teacher": str(run.teacher_path), **skipped_and_torn(data, torn)}
