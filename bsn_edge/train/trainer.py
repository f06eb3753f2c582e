"""Training BlindSpotNet: teacher first (if distilling), then D and B together.

Loss (paper, Section 4): BCE over pixels in V, plus lambda x the pairwise-similarity
distillation loss between the teacher's decoder output and B's, plus D's depth loss (D is
trained on the dataset's metric depth so the fused model can report distances). Adam
(0.9, 0.999, 1e-8, weight decay 5e-4), lr 1e-3 with a polynomial schedule. Runs under
``torchrun`` with DistributedDataParallel (gloo on CPU, nccl on GPUs).
"""

from __future__ import annotations

import io
import json
import os
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import torch
import torch.distributed as dist
import torch.nn.functional as F
from torch.utils.data import DataLoader, DistributedSampler
from tqdm import tqdm

from bsn_edge import semantics as sm
from bsn_edge.data import BlindSpotDataset, find_clips, split_clips
from bsn_edge.evaluate.metrics import ThresholdSweep
from bsn_edge.models import create_model, create_teacher, get_spec
from bsn_edge.sequence import SequenceMeta
from bsn_edge.sequence.images import atomic_write_bytes
from bsn_edge.train.checkpoint import CONFIG_FILE, load_model, load_state, save_model, save_state
from bsn_edge.train.config import Config
from bsn_edge.train.losses import depth_loss, distillation_loss, masked_bce

TEACHER_DIR = "teacher"


def _dist() -> tuple[int, int]:
    """(rank, world size); starts the process group when launched by torchrun."""
    world = int(os.environ.get("WORLD_SIZE", "1"))
    if world > 1 and not dist.is_initialized():
        dist.init_process_group("nccl" if torch.cuda.is_available() else "gloo")
    return (dist.get_rank(), world) if world > 1 else (0, 1)


def _loader(ds, batch: int, world: int, rank: int, seed: int, workers: int) -> Iterator[dict]:
    """An endless stream of shuffled batches (a new epoch whenever one runs out)."""
    sampler = DistributedSampler(ds, world, rank, shuffle=True, seed=seed) if world > 1 else None
    epoch = 0
    while True:
        if sampler is not None:
            sampler.set_epoch(epoch)
        g = torch.Generator().manual_seed(seed + epoch)
        dl = DataLoader(ds, batch_size=batch, shuffle=sampler is None, sampler=sampler,
                        drop_last=len(ds) >= batch, num_workers=workers, generator=g)
        yield from dl
        epoch += 1


def scaled(x: torch.Tensor, scale: float, mode: str = "bilinear") -> torch.Tensor:
    """``x`` resized by ``scale`` (unchanged at 1)."""
    if scale == 1.0:
        return x
    kw = {"align_corners": False} if mode == "bilinear" else {}
    return F.interpolate(x, scale_factor=scale, mode=mode, **kw)


def _poly(opt: torch.optim.Optimizer, steps: int, power: float) -> torch.optim.lr_scheduler.LambdaLR:
    return torch.optim.lr_scheduler.LambdaLR(opt, lambda s: max(1.0 - s / steps, 0.0) ** power)


def _adam(params, lr: float, cfg: Config) -> torch.optim.Optimizer:
    t = cfg.train
    return torch.optim.Adam(params, lr=lr, betas=t.betas, eps=t.eps, weight_decay=t.weight_decay)


def datasets(cfg: Config, data_dir: str | Path) -> dict[str, Any]:
    """Clips split by clip, the training styles applied, and the datasets over them."""
    clips = find_clips(data_dir, cfg.data.label)
    split = split_clips(clips, cfg.data.val_fraction, cfg.data.test_fraction, cfg.data.split_seed)
    train = split["train"]
    styles = cfg.data.train_styles
    if styles:
        train = [c for c in train if c.style in styles]
    if cfg.data.fraction < 1.0 and train:
        train = train[: max(1, round(cfg.data.fraction * len(train)))]
    if not train:
        raise ValueError(f"no training clips (styles {styles or 'any'}) in {data_dir}")
    val = [c for c in split["val"] if not styles or c.style in styles]
    return {"clips": split, "train": train, "val": val,
            "train_ds": BlindSpotDataset(train, cfg.data.size, augment=True, label_name=cfg.data.label,
                                         seed=cfg.train.seed),
            "val_ds": BlindSpotDataset(val, cfg.data.size, label_name=cfg.data.label) if val else None}


def train_teacher(cfg: Config, ds, out: Path, rank: int, world: int, progress: bool) -> torch.nn.Module:
    """The segmentation teacher, trained on the dataset's semantics (or loaded)."""
    t = cfg.teacher
    teacher = create_teacher(t.encoder, t.width)
    if t.checkpoint:
        state = torch.load(Path(t.checkpoint) / "teacher.pt", map_location="cpu", weights_only=True)
        teacher.load_state_dict(state)
        return teacher.eval()
    path = out / TEACHER_DIR / "teacher.pt"
    if path.is_file():
        teacher.load_state_dict(torch.load(path, map_location="cpu", weights_only=True))
        return teacher.eval()
    model = torch.nn.parallel.DistributedDataParallel(teacher) if world > 1 else teacher
    opt = _adam(model.parameters(), t.lr, cfg)
    sched = _poly(opt, t.steps, cfg.train.poly_power)
    batches = _loader(ds, t.batch_size, world, rank, cfg.train.seed + 1, cfg.data.workers)
    bar = tqdm(range(t.steps), desc="teacher", disable=True if (not progress or rank) else None, unit="step")
    model.train()
    for _ in bar:
        b = next(batches)
        logits, _ = model(scaled(b["image"], t.scale))
        target = scaled(b["semantic"][:, None].float(), t.scale, "nearest")[:, 0].long()
        loss = F.cross_entropy(logits, target, ignore_index=sm.IGNORE)
        opt.zero_grad(set_to_none=True)
        loss.backward()
        opt.step()
        sched.step()
        bar.set_postfix(ce=f"{loss.item():.3f}")
    if rank == 0:
        path.parent.mkdir(parents=True, exist_ok=True)
        buf = io.BytesIO()
        torch.save(teacher.state_dict(), buf)
        atomic_write_bytes(path, buf.getvalue())
    return teacher.eval()


@torch.no_grad()
def choose_threshold(model: torch.nn.Module, ds, batch: int = 8) -> tuple[float, dict[str, float]]:
    """The threshold with the best IoU inside V on ``ds`` (the validation split)."""
    model.eval()
    sweep = ThresholdSweep()
    for b in DataLoader(ds, batch_size=batch):
        prob = torch.sigmoid(model(b["image"])[0]).numpy()
        sweep.add(prob, b["blindspot"].numpy() > 0.5, b["visibility"].numpy() > 0.5)
    return sweep.best()


def train(cfg: Config, data_dir: str | Path, out: str | Path, resume: bool = False,
          progress: bool = True) -> dict[str, Any]:
    """Train per ``cfg`` on the labelled clips under ``data_dir``; write the run to ``out``."""
    rank, world = _dist()
    out = Path(out)
    torch.manual_seed(cfg.train.seed + rank)
    np.random.seed(cfg.train.seed + rank)
    torch.set_num_threads(cfg.train.threads)
    data = datasets(cfg, data_dir)
    if rank == 0:
        out.mkdir(parents=True, exist_ok=True)
        atomic_write_bytes(out / CONFIG_FILE, (json.dumps(cfg.to_dict(), indent=2) + "\n").encode())
    lam = cfg.distill_weight
    teacher = train_teacher(cfg, data["train_ds"], out, rank, world, progress) if lam > 0 else None

    model = create_model(cfg.model.name)
    if cfg.train.init:
        init, init_meta = load_model(cfg.train.init)
        if init_meta["model"] != cfg.model.name:
            raise ValueError(f"train.init {cfg.train.init} holds a {init_meta['model']!r} model, "
                             f"not {cfg.model.name!r}")
        model.load_state_dict(init.state_dict())
    start = 0
    opt = _adam(model.parameters(), cfg.train.lr, cfg)
    sched = _poly(opt, cfg.train.steps, cfg.train.poly_power)
    if resume and (out / "model.pt").is_file():
        model.load_state_dict(torch.load(out / "model.pt", map_location="cpu", weights_only=True))
        state = load_state(out)
        if state:
            opt.load_state_dict(state["optimizer"])
            start = int(state["step"])
            if "scheduler" in state:
                sched.load_state_dict(state["scheduler"])
    net = torch.nn.parallel.DistributedDataParallel(model) if world > 1 else model
    batches = _loader(data["train_ds"], cfg.train.batch_size, world, rank, cfg.train.seed, cfg.data.workers)
    bar = tqdm(range(start, cfg.train.steps), desc=f"train {cfg.model.name}", unit="step",
               disable=True if (not progress or rank) else None)
    history = []
    t0 = time.perf_counter()
    net.train()
    for step in bar:
        b = next(batches)
        logits, depth, feats = net(b["image"])
        l_bce = masked_bce(logits, b["blindspot"], b["visibility"])
        l_depth = depth_loss(depth, b["depth"], b["sky"])
        loss = l_bce + cfg.train.depth_weight * l_depth
        l_kd = torch.zeros(())
        if teacher is not None:
            with torch.no_grad():
                _, t_feats = teacher(scaled(b["image"], cfg.teacher.scale))
            l_kd = distillation_loss(feats, t_feats, cfg.train.distill_grid)
            loss = loss + lam * l_kd
        opt.zero_grad(set_to_none=True)
        loss.backward()
        opt.step()
        sched.step()
        history.append([loss.item(), l_bce.item(), l_kd.item(), l_depth.item()])
        bar.set_postfix(loss=f"{loss.item():.3f}", bce=f"{l_bce.item():.3f}", kd=f"{l_kd.item():.4f}",
                        depth=f"{l_depth.item():.3f}")
        done = step + 1
        if rank == 0 and (done % cfg.train.checkpoint_every == 0 or done == cfg.train.steps):
            _save(out, model, cfg, data, done, threshold=None)
            save_state(out, opt, done, sched)
    elapsed = time.perf_counter() - t0
    summary: dict[str, Any] = {"steps": cfg.train.steps, "resumed_from": start, "seconds": round(elapsed, 1),
                               "final_loss": history[-1] if history else None}
    if rank == 0:
        threshold, val = (0.5, {})
        if data["val_ds"] is not None:
            threshold, val = choose_threshold(model, data["val_ds"])
        meta = _save(out, model, cfg, data, cfg.train.steps, threshold=threshold, val=val, history=history)
        summary.update(threshold=threshold, val=val, weights_sha256=meta["weights_sha256"])
    if world > 1:
        dist.barrier()
    return summary


def _save(out: Path, model, cfg: Config, data, step: int, threshold: float | None,
          val: dict | None = None, history: list | None = None) -> dict[str, Any]:
    first = data["train"][0]
    meta = SequenceMeta.read(first.path)
    h, w = cfg.data.size
    k = meta.intrinsics.scaled(w, h)
    prev = {}
    if (out / "checkpoint.json").is_file():
        prev = json.loads((out / "checkpoint.json").read_text())
    info = {
        "model": cfg.model.name, "spec": get_spec(cfg.model.name).to_dict(), "step": step,
        "threshold": threshold if threshold is not None else prev.get("threshold", 0.5),
        "input_size": [h, w], "intrinsics": k.to_dict(), "config_digest": cfg.digest(),
        "label": cfg.data.label, "distill_weight": cfg.distill_weight,
        "train_clips": [c.path.name for c in data["train"]], "val_clips": [c.path.name for c in data["val"]],
        "test_clips": [c.path.name for c in data["clips"]["test"]],
        "val": val if val is not None else prev.get("val", {}),
    }
    if history:
        info["loss_first_last"] = [history[0], history[-1]]
    return save_model(out, model, info)
