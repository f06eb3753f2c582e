"""Training BlindSpotNet: teacher first (if distilling), then D and B together.

Loss (paper, Section 4): BCE over pixels in V, plus lambda x the pairwise-similarity
distillation loss between the teacher's decoder output and B's, plus D's depth loss (D is
trained on the dataset's metric depth so the fused model can report distances). Adam
(0.9, 0.999, 1e-8, weight decay 5e-4), lr 1e-3 with a polynomial schedule. Runs under
``torchrun`` with DistributedDataParallel (gloo on CPU, nccl on GPUs).
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import numpy as np
import torch
import torch.distributed as dist

from bsn_edge import semantics as sm
from bsn_edge.card import UNRECORDED
from bsn_edge.data.cache import SampleCache
from bsn_edge.data.camera_mix import CameraMix
from bsn_edge.data.guessed_camera import GuessedDepth
from bsn_edge.networks import BlindSpotNet, create_model, get_spec, start_from
from bsn_edge.networks.alive import alive_channels
from bsn_edge.networks.revive import revive
from bsn_edge.progress import progress_bar
from bsn_edge.train.batches import datasets, sample_cache, skipped_and_torn, training_batches
from bsn_edge.train.checkpoints import carried, checkpoint, finish, open_run
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
from bsn_edge.train.encoder_norm import EncoderNorm, freeze_norm_stats
from bsn_edge.train.losses import depth_loss, distillation_loss, masked_bce, visible_out_to
from bsn_edge.train.optim import Optimizer, param_groups
from bsn_edge.train.run import Run
from bsn_edge.train.teacher_training import train_teacher, with_teachers_build
from bsn_edge.train.validation import outputs, validation_figures


def depth_weights(b: dict[str, torch.Tensor], cfg: Config) -> tuple[torch.Tensor | None, torch.Tensor | None]:
    """D's loss terms for batch ``b``: per-pixel weights ``[N, 1, H, W]`` (None: a plain mean) and
    which samples are taught their depth only up to a scale (None: none), by what the config says
    a guessed-camera sample teaches (``data.guessed_depth``)."""
    weight = _depth_weights(b["semantic"], cfg.train.depth_object_weight)
    guessed, teach = b.get("guessed"), GuessedDepth(cfg.data.guessed_depth)
    if guessed is None or not bool(guessed.any()) or teach is GuessedDepth.METRIC:
        return weight, None
    if teach is GuessedDepth.SCALE_FREE:
        return weight, guessed
    keep = (~guessed).to(b["semantic"].device, torch.float32).view(-1, 1, 1, 1)
    return (keep if weight is None else weight * keep), None


def _depth_weights(semantic: torch.Tensor, object_weight: float) -> torch.Tensor | None:
    """Per-pixel depth-loss weights ``[N, 1, H, W]``: ``object_weight`` on vehicles and people, 1
    elsewhere; None when the weight is 1 (plain mean)."""
    if object_weight == 1.0:
        return None
    ids = torch.tensor(sm.ROAD_USERS, device=semantic.device)
    obj = torch.isin(semantic, ids)[:, None]
    return 1.0 + (object_weight - 1.0) * obj.to(torch.float32)


def bce_weights(b: dict[str, torch.Tensor], people_weight: float) -> torch.Tensor | None:
    """Per-pixel BCE weights ``[N, 1, H, W]``: ``people_weight`` on the blind-spot pixels of people and
    what they ride, 1 elsewhere (their negatives too: the rendered clips already teach a person mostly
    as not hiding road); None when the weight is 1."""
    if people_weight == 1.0:
        return None
    ids = torch.tensor(sm.PEOPLE_AND_CYCLES, device=b["semantic"].device)
    people = torch.isin(b["semantic"], ids)[:, None] & (b["blindspot"] > 0.5)
    return 1.0 + (people_weight - 1.0) * people.to(torch.float32)


def losses(net: torch.nn.Module, b: dict[str, torch.Tensor], teacher: torch.nn.Module | None, cfg: Config,
           dtype: torch.dtype | None) -> tuple[torch.Tensor, ...]:
    """``(loss, bce, distillation, depth)`` of one batch: BCE inside V (out to ``train.bce_range_m``
    when set), D's depth loss, and lambda x the
    pairwise-similarity distillation against the batch's cached ``teacher_grid`` or, without one,
    a pass of ``teacher``. The networks run under ``dtype`` autocast; the losses are fp32."""
    cl = cfg.train.channels_last
    dev = b["image"].device
    with autocast(dev, dtype):
        logits, depth, feats = outputs(net, layout(b["image"], cl), b)
    logits, depth, feats = logits.float(), depth.float(), feats.float()
    valid = b["visibility"]
    if cfg.train.bce_range_m > 0:
        valid = visible_out_to(valid, b["depth"], b["semantic"], cfg.train.bce_range_m)
    l_bce = masked_bce(logits, b["blindspot"], valid, bce_weights(b, cfg.train.people_weight))
    weight, free_scale = depth_weights(b, cfg)
    l_depth = depth_loss(depth, b["depth"], b["sky"], weight, cfg.train.depth_grad_scales, free_scale)
    loss = l_bce + cfg.train.depth_weight * l_depth
    l_kd = torch.zeros((), device=dev)
    if teacher is not None:
        if "teacher_grid" in b:
            t_feats = b["teacher_grid"]
        else:
            with torch.no_grad(), autocast(dev, dtype):
                _, t_feats = teacher(layout(scaled(b["image"], cfg.teacher.scale), cl))
        l_kd = distillation_loss(feats, t_feats.float(), cfg.train.distill_grid)
        loss = loss + cfg.distill_weight * l_kd
    return loss, l_bce, l_kd, l_depth


def train(cfg: Config, data_dir: str | Path, out: str | Path, resume: bool = False,
          progress: bool = True, force: bool = False, stop_after: float | None = None) -> dict[str, Any]:
    """Train per ``cfg`` on the labelled clips under ``data_dir``; write the run to ``out``.

    An existing run is refused unless ``resume`` (continue it: verified state, same data stream)
    or ``force`` (start again). ``stop_after`` (seconds) ends this piece of a longer training at
    the first step past it (counted from this call, the teacher and the caches included), with a
    checkpoint to resume from; the learning-rate schedule spans ``train.steps``, whatever the pieces."""
    piece_start = time.perf_counter()
    rank, world = distributed()
    cfg = with_teachers_build(cfg)
    run, torn, state = open_run(cfg, out, resume, force, rank, world)
    data = datasets(cfg, data_dir)
    if rank == 0:
        run.write_config(cfg.to_dict())
    dev = train_device(cfg)
    dtype, cl = autocast_dtype(cfg, dev), cfg.train.channels_last
    cache, val_caches, teacher = _caches_and_teacher(cfg, data, run, rank, world, progress, resume, dtype)

    model, optim = _model_and_optimizer(cfg, state, dev)
    start = int(state["step"]) if state is not None else 0
    seconds_before = float(state.get("seconds", 0.0)) if state is not None else 0.0
    # the arithmetic of every piece so far, this one's included (a state from before it was kept: unrecorded)
    kinds = sorted({precision_name(dtype)} | (set(state.get("precision", [UNRECORDED])) if state else set()))
    module_layout(model, cl)
    net = torch.nn.parallel.DistributedDataParallel(model) if world > 1 else model
    batches = _batches(cfg, data, cache, state, start, rank, world, dev)
    if rank == 0:
        _start_history(run, model, cfg, start, dtype, val_caches)
    bar = progress_bar(range(start, cfg.train.steps), initial=start, total=cfg.train.steps,
                       desc=f"train {cfg.model.name}", unit="step", enabled=progress and not rank)
    last: list[float] | None = None                      # this piece's latest step
    since, first = carried(state)
    t0, done = time.perf_counter(), start
    net.train()
    for step in bar:
        last = _step(net, optim, next(batches), teacher, cfg, dtype)
        bar.set_postfix(loss=f"{last[0]:.3f}", bce=f"{last[1]:.3f}", kd=f"{last[2]:.4f}", depth=f"{last[3]:.3f}")
        since.append(last)
        first, done = first or last, step + 1
        seconds = seconds_before + time.perf_counter() - t0
        out_of_time = stop_after is not None and time.perf_counter() - piece_start >= stop_after \
            and done < cfg.train.steps
        if rank == 0 and cfg.train.eval_every and (done % cfg.train.eval_every == 0 or done == cfg.train.steps):
            run.append_history(_record(model, cfg, since, done, world, seconds, dtype, val_caches))
            since = []
        if rank == 0 and (done % cfg.train.checkpoint_every == 0 or done == cfg.train.steps or out_of_time):
            checkpoint(run, model, optim, cfg, data, done, world, seconds, kinds, since, first)
        if out_of_time:
            break
    summary: dict[str, Any] = {"steps": cfg.train.steps, "resumed_from": start, "steps_run": done - start,
                               "seconds": round(time.perf_counter() - t0, 1), "final_loss": last,
                               **skipped_and_torn(data, torn)}
    if done < cfg.train.steps:
        summary["stopped_at"] = done
    elif rank == 0:
        summary.update(finish(run, model, cfg, data, [first, last] if last else None))
    if world > 1:
        dist.barrier()
    return summary


def _caches_and_teacher(cfg: Config, data, run: Run, rank: int, world: int, progress: bool, resume: bool,
                        dtype: torch.dtype | None):
    """The training batches' cache (a :class:`CameraMix` when guessed cameras are asked for), the
    validation caches by the prefix of their history keys (``val_``, ``val_guessed_``), and the teacher
    (trained or taken as the config says, its features attached to the training caches); None where
    there is none."""
    show = progress and rank == 0
    cache = sample_cache(cfg, data.train_ds, show, "caching training samples")
    val_caches: dict[str, SampleCache] = {}
    for prefix, ds, desc in (("val_", data.val_ds, "caching validation samples"),
                             ("val_guessed_", data.val_guessed_ds, "caching validation samples, guessed cameras")):
        got = sample_cache(cfg, ds, show, desc) if ds is not None else None
        if got is not None:
            val_caches[prefix] = got
    guessed = sample_cache(cfg, data.train_guessed_ds, show, "caching samples, guessed cameras") \
        if data.train_guessed_ds is not None else None
    teacher = (train_teacher(cfg, data.train_ds, run, rank, world, progress, cache, val_caches.get("val_"),
                             resume=resume) if cfg.distill_weight > 0 else None)
    cl = cfg.train.channels_last
    for c in (cache, guessed):
        if teacher is not None and c is not None:
            c.attach_teacher(teacher, cfg.teacher.scale, cfg.train.distill_grid, progress=show,
                             resize=lambda x, sc: layout(scaled(x, sc), cl), dtype=dtype)
    if guessed is not None and cache is not None:
        return CameraMix(cache, guessed, cfg.data.guessed_camera), val_caches, teacher
    return cache, val_caches, teacher


def _start_history(run: Run, model: BlindSpotNet, cfg: Config, start: int, dtype: torch.dtype | None,
                   val_caches: dict[str, SampleCache]) -> None:
    """The history from ``start`` on; a run started from another records where it begins (its gain is
    then measured, not assumed)."""
    run.trim_history("train", start)
    if start == 0 and cfg.train.init and cfg.train.eval_every and val_caches:
        run.append_history({"phase": "train", "step": 0, "samples": 0, "seconds": 0.0,
                            "precision": precision_name(dtype), **validation_figures(model, cfg, dtype, val_caches)})


def _step(net, optim: Optimizer, batch, teacher, cfg: Config, dtype: torch.dtype | None) -> list[float]:
    """One optimizer step on ``batch``; its losses (total, BCE, distillation, depth)."""
    loss, l_bce, l_kd, l_depth = losses(net, batch, teacher, cfg, dtype)
    optim.step(loss)
    return [loss.item(), l_bce.item(), l_kd.item(), l_depth.item()]


def _batches(cfg: Config, data, cache, state: dict[str, Any] | None, start: int, rank: int, world: int,
             dev: torch.device):
    """The training batches from step ``start`` on, and the random draws where the saved state left them."""
    batches = training_batches(data.train_ds, cache, cfg.train.batch_size, world, rank, cfg.train.seed,
                               cfg.data.workers, start, device=dev, real_share=cfg.data.real_share)
    if state is not None and "torch_rng" in state:
        # dropout draws go on where they stopped (after the loader, which takes a draw of its own)
        torch.set_rng_state(state["torch_rng"])
    return batches


def _model_and_optimizer(cfg: Config, state: dict[str, Any] | None,
                         dev: torch.device) -> tuple[BlindSpotNet, Optimizer]:
    """The model on ``dev`` and its optimizer: from the saved state, else from ``train.init``, else fresh
    (from the encoder's ImageNet weights where the variant says so)."""
    spec = get_spec(cfg.model.name)
    model = create_model(cfg.model.name, pretrained=bool(spec.pretrained) and not cfg.train.init and state is None)
    if cfg.train.init:
        init, init_card = Run(cfg.train.init).load_model()
        try:
            start_from(model, cfg.model.name, init, init_card.variant)
        except ValueError as e:
            raise ValueError(f"train.init {cfg.train.init}: {e}") from None
        if cfg.train.revive and state is None:
            revive(model, seed=cfg.train.seed)
    if EncoderNorm(cfg.train.encoder_bn) is EncoderNorm.FROZEN:
        _freeze_encoder_stats(model, cfg, spec.pretrained)
    model.to(dev)
    optim = Optimizer(param_groups(model, getattr(model, "frame_encoder", None), cfg.train.lr,
                                   cfg.train.encoder_lr if spec.pretrained else 1.0),
                      cfg.train.lr, cfg.train.steps, cfg.train)
    if state is not None:
        model.load_state_dict(state["weights"])
        optim.load_state_dict(state)
    return model, optim


def _freeze_encoder_stats(model: BlindSpotNet, cfg: Config, pretrained: str) -> None:
    """Keep the frame encoder's batch-norm statistics as they came (``train.encoder_bn = "frozen"``)."""
    encoder = getattr(model, "frame_encoder", None)
    if encoder is None:
        raise ValueError(f'train.encoder_bn = "frozen": {cfg.model.name} has no one frame encoder to freeze the '
                         "statistics of (a shared-encoder variant has)")
    if not pretrained and not cfg.train.init:
        raise ValueError(f'train.encoder_bn = "frozen" keeps the statistics an encoder came with, and '
                         f"{cfg.model.name}'s starts from none (no ImageNet weights; set train.init to a run)")
    freeze_norm_stats(encoder)


def _record(model: BlindSpotNet, cfg: Config, since: list[list[float]], done: int, world: int, seconds: float,
            dtype: torch.dtype | None, val_caches: dict[str, SampleCache]) -> dict[str, Any]:
    """The history line at step ``done``: the losses averaged since the last one, and validation."""
    mean = np.mean(since, axis=0)
    rec = {"phase": "train", "step": done, "samples": done * cfg.train.batch_size * world,
           "seconds": round(seconds, 1), "loss": float(mean[0]), "bce": float(mean[1]),
           "kd": float(mean[2]), "depth": float(mean[3]), "precision": precision_name(dtype)}
    rec.update(validation_figures(model, cfg, dtype, val_caches))
    rec.update(alive_channels(model).to_dict())     # training health: a channel once dead stays dead
    return rec
