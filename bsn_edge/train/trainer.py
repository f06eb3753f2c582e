"""Training BlindSpotNet: teacher first (if distilling), then D and B together.

Loss (paper, Section 4): BCE over pixels in V, plus lambda x the pairwise-similarity
distillation loss between the teacher's decoder output and B's, plus D's depth loss (D is
trained on the dataset's metric depth so the fused model can report distances). Adam
(0.9, 0.999, 1e-8, weight decay 5e-4), lr 1e-3 with a polynomial schedule. Runs under
``torchrun`` with DistributedDataParallel (gloo on CPU, nccl on GPUs).
"""

from __future__ import annotations

import dataclasses
import os
import shutil
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch
import torch.distributed as dist
import torch.nn.functional as F
from torch.utils.data import DataLoader

from bsn_edge import semantics as sm
from bsn_edge.card import BF16, FP32, UNCHOSEN_THRESHOLD, UNRECORDED, ModelCard
from bsn_edge.data import BlindSpotDataset, Clip, find_clips, split_clips
from bsn_edge.data.cache import SampleCache, default_cache_root
from bsn_edge.data.camera_mix import CameraMix
from bsn_edge.data.guessed_camera import ClipCamera, GuessedDepth
from bsn_edge.labels.camvid import STYLE as CAMVID_STYLE
from bsn_edge.labels.generator import label_camera
from bsn_edge.metrics import ThresholdSweep
from bsn_edge.models import MAX_DEPTH_M, MIN_DEPTH_M, BlindSpotNet, create_model, create_teacher, get_spec, start_from
from bsn_edge.progress import progress_bar
from bsn_edge.sequence import SequenceMeta
from bsn_edge.sequence.folder import SequenceFolder
from bsn_edge.train.config import Config
from bsn_edge.train.encoder_norm import EncoderNorm, freeze_norm_stats
from bsn_edge.train.losses import depth_loss, distillation_loss, masked_bce, visible_out_to
from bsn_edge.train.optim import Optimizer
from bsn_edge.train.run import Run, RunError


def _dist() -> tuple[int, int]:
    """(rank, world size); starts the process group when launched by torchrun."""
    world = int(os.environ.get("WORLD_SIZE", "1"))
    if world > 1 and not dist.is_initialized():
        dist.init_process_group("nccl" if torch.cuda.is_available() else "gloo")
    return (dist.get_rank(), world) if world > 1 else (0, 1)


REAL_STYLES = (CAMVID_STYLE,)   # clips of real pictures (data.real_share draws from them)
GROUP_SEED_STRIDE = 7919   # a group's permutations are drawn from seeds of their own, far from the others'


class BatchStream:
    """An endless, resumable stream of batches: ``[(sample index, augmentation seed), ...]``.

    Epoch ``e`` visits the samples in a permutation drawn from ``seed + e``; a global batch of
    ``batch x world`` samples is split between the ranks. Batch ``k`` of the stream depends only on
    ``k``, so a run resumed at step ``s`` sees exactly what an uninterrupted run sees from ``s`` on,
    augmentation included (each sample's seed is its position in the stream).

    With ``real`` (sample indices) and ``real_per_batch`` > 0, every global batch holds that many samples of
    ``real`` and the rest of the others, each group visited in permutations of its own (drawn from the
    seed and the group's pass over it), so a small group of real pictures is seen at a set share however
    many synthetic samples there are; batch ``k`` still depends only on ``k``.
    """

    def __init__(self, n: int, batch: int, seed: int, start: int = 0, world: int = 1, rank: int = 0,
                 real: tuple[int, ...] = (), real_per_batch: int = 0) -> None:
        self.n, self.batch, self.seed, self.start, self.world, self.rank = n, batch, seed, start, world, rank
        glob = batch * world
        self.per_epoch = max(n // glob, 1)
        self.glob = min(glob, n)
        if real_per_batch and not 0 < real_per_batch < self.glob:
            raise ValueError(f"real samples per batch must be within 1..{self.glob - 1}, got {real_per_batch}")
        if real_per_batch and not real:
            raise ValueError("real samples per batch were asked for, but there is no real sample")
        real_set = set(real)
        self.groups = ((tuple(sorted(real_set)), real_per_batch),
                       (tuple(i for i in range(n) if i not in real_set), self.glob - real_per_batch)) \
            if real_per_batch else ()

    @staticmethod
    def _take(members: tuple[int, ...], seed: int, start: int, count: int) -> list[int]:
        """``count`` members from position ``start`` of an endless run of permutations of ``members``
        (pass ``p`` drawn from ``seed + p``)."""
        out: list[int] = []
        pos = start
        while len(out) < count:
            p, j = divmod(pos, len(members))
            order = torch.randperm(len(members), generator=torch.Generator().manual_seed(seed + p)).tolist()
            got = [members[i] for i in order[j:j + count - len(out)]]
            out += got
            pos += len(got)
        return out

    def __iter__(self) -> Iterator[list[tuple[int, int]]]:
        k = self.start
        if self.groups:
            while True:
                glob = [i for g, (members, m) in enumerate(self.groups)
                        for i in self._take(members, self.seed + GROUP_SEED_STRIDE * g, k * m, m)]
                picked = glob[self.rank::self.world]
                yield [(i, (k * self.glob + r) * self.world + self.rank) for r, i in enumerate(picked)]
                k += 1
        while True:
            epoch, j = divmod(k, self.per_epoch)
            order = torch.randperm(self.n, generator=torch.Generator().manual_seed(self.seed + epoch)).tolist()
            for jj in range(j, self.per_epoch):
                lo = jj * self.glob
                picked = order[lo:lo + self.glob][self.rank::self.world]
                yield [(i, (epoch * self.n + lo + r) * self.world + self.rank) for r, i in enumerate(picked)]
                k += 1


def real_samples(ds) -> tuple[int, ...]:
    """The indices of ``ds``'s samples from real pictures (clips of a style in :data:`REAL_STYLES`)."""
    return tuple(i for i, (clip, _) in enumerate(ds.items) if clip.style in REAL_STYLES)


def stream_for(ds, n: int, batch: int, seed: int, start: int, world: int, rank: int,
               real_share: float) -> BatchStream:
    """The :class:`BatchStream` of ``n`` samples of ``ds``, with ``real_share`` of each global batch from
    its real pictures when it has any (0: every sample alike)."""
    real = real_samples(ds) if real_share > 0 else ()
    per = min(max(round(real_share * min(batch * world, n)), 1), min(batch * world, n) - 1) if real else 0
    return BatchStream(n, batch, seed, start, world, rank, real, per)


def batch_stream(ds, batch: int, world: int, rank: int, seed: int, workers: int, start: int = 0,
                 device: torch.device | None = None, real_share: float = 0.0) -> Iterator[dict]:
    """Batches of ``ds`` from stream position ``start`` on (see :class:`BatchStream`), on ``device``."""
    dl = DataLoader(ds, batch_sampler=stream_for(ds, len(ds), batch, seed, start, world, rank, real_share),
                    num_workers=workers,
                    pin_memory=device is not None and device.type == "cuda",
                    persistent_workers=workers > 0)
    # the iterator is made now, not at the first batch: it takes a draw from torch's generator, and a
    # resumed run restores that generator right after this call
    it = iter(dl)
    return it if device is None else (_to(b, device) for b in it)


def _to(batch: dict, device: torch.device) -> dict:
    return {k: v.to(device, non_blocking=True) if torch.is_tensor(v) else v for k, v in batch.items()}


def sample_cache(cfg: Config, ds, progress: bool = False, desc: str = "caching samples") -> SampleCache | None:
    """The decoded, warped samples of ``ds`` as ``data.cache`` asks (None when it is "off")."""
    where = cfg.data.cache
    if where == "off":
        return None
    root = None if where == "memory" else default_cache_root() if where == "auto" else Path(where)
    return SampleCache.for_dataset(ds, root, progress, desc)


def training_batches(ds, cache: SampleCache | None, batch: int, world: int, rank: int, seed: int, workers: int,
                     start: int = 0, device: torch.device | None = None, real_share: float = 0.0) -> Iterator[dict]:
    """The stream of :class:`BatchStream` as batches: gathered from ``cache`` (augmented as a batch),
    or loaded sample by sample from ``ds`` when there is no cache. Both give the same samples.
    ``real_share``: of each batch, from real pictures (``data.real_share``)."""
    if cache is None:
        return batch_stream(ds, batch, world, rank, seed, workers, start, device, real_share)
    stream = stream_for(ds, len(cache), batch, seed, start, world, rank, real_share)
    dev = device or torch.device("cpu")
    return (_to(cache.batch(picks, ds.augment, ds.seed, ds.object_repaint, ds.object_see_through, ds.camera_look),
                dev)
            for picks in stream)


def cpu_has_native_bf16() -> bool:
    """Whether this CPU multiplies bf16 natively (AMX tiles or AVX-512 BF16)."""
    return any(getattr(torch.cpu, name, lambda: False)() for name in ("_is_amx_tile_supported",
                                                                       "_is_avx512_bf16_supported"))


def autocast_dtype(cfg: Config, device: torch.device) -> torch.dtype | None:
    """The autocast dtype of ``train.precision`` on ``device`` (None: fp32)."""
    want = cfg.train.precision
    if want == "auto":
        want = BF16 if device.type == "cpu" and cpu_has_native_bf16() else FP32
    return torch.bfloat16 if want == BF16 else None


def precision_name(dtype: torch.dtype | None) -> str:
    """How a history record's training arithmetic is named: ``BF16`` (autocast) or ``FP32``. Every
    record carries it: ``train.precision=auto`` trains differently on different CPUs, and a run
    resumed on another machine may change it from one piece to the next."""
    return BF16 if dtype == torch.bfloat16 else FP32


def _autocast(device: torch.device, dtype: torch.dtype | None):
    return torch.autocast(device.type, dtype=dtype or torch.float32, enabled=dtype is not None)


def _layout(x: torch.Tensor, channels_last: bool) -> torch.Tensor:
    return x.contiguous(memory_format=torch.channels_last) if channels_last else x


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


@dataclass(frozen=True)
class Datasets:
    """What a training run reads: its clips split by clip (``clips``: train / val / test), the training
    clips after the style and fraction settings, the validation clips, the datasets over them, and
    the sequence folders found without usable labels (``(folder, reason)``)."""

    clips: dict[str, list[Clip]]
    train: list[Clip]
    val: list[Clip]
    skipped: list[tuple[str, str]]
    train_ds: BlindSpotDataset
    val_ds: BlindSpotDataset | None
    # the same samples warped with guessed cameras (data.guessed_camera > 0), else None
    train_guessed_ds: BlindSpotDataset | None = None
    val_guessed_ds: BlindSpotDataset | None = None


def datasets(cfg: Config, data_dir: str | Path) -> Datasets:
    """Clips split by clip, the training styles applied, and the datasets over them."""
    skipped: list[tuple[str, str]] = []
    clips = find_clips(data_dir, cfg.data.label, skipped=skipped)
    split = split_clips(clips, cfg.data.val_fraction, cfg.data.test_fraction, cfg.data.split_seed)
    train = split["train"]
    styles = cfg.data.train_styles
    if styles:
        train = [c for c in train if c.style in styles]
    if cfg.data.fraction < 1.0 and train:
        train = train[: max(1, round(cfg.data.fraction * len(train)))]
    if not train:
        raise ValueError(f"no training clips (styles {styles or 'any'}) in {data_dir}")
    if cfg.train.bce_range_m > 0:
        for c in train:
            meta = SequenceMeta.read(c.path)
            if not meta.rendered:
                raise ValueError(f"train.bce_range_m teaches B beyond the labels' V from exact depth, which only "
                                 f"rendered clips have: {c.path} was not rendered (its meta.json source is "
                                 f"{meta.source!r}); leave it at 0 for this data")
    val = [c for c in split["val"] if not styles or c.style in styles]
    camera, mounting = cfg.data.model_camera()

    def train_ds(cameras: ClipCamera) -> BlindSpotDataset:
        return BlindSpotDataset(train, cfg.data.size, augment=True, label_name=cfg.data.label, camera=camera,
                                mounting=mounting, seed=cfg.train.seed, object_repaint=cfg.data.object_repaint,
                                object_see_through=cfg.data.object_see_through, clip_camera=cameras,
                                camera_look=cfg.data.camera_look)

    def val_ds(cameras: ClipCamera) -> BlindSpotDataset | None:
        return BlindSpotDataset(val, cfg.data.size, label_name=cfg.data.label, camera=camera, mounting=mounting,
                                clip_camera=cameras) if val else None

    guessed = cfg.data.guessed_camera > 0
    return Datasets(split, train, val, skipped, train_ds(ClipCamera.OWN), val_ds(ClipCamera.OWN),
                    train_ds(ClipCamera.GUESSED) if guessed else None, val_ds(ClipCamera.GUESSED) if guessed else None)


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
        with _autocast(dev, dtype):
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


def _teacher_val(teacher: torch.nn.Module, cfg: Config, val_cache, dtype: torch.dtype | None) -> dict[str, float]:
    return {f"val_{k}": v for k, v in teacher_miou(teacher, val_cache, cfg.teacher.scale, cfg.train.eval_frames,
                                                   dtype).items()}


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
    teacher.to(dev).to(memory_format=torch.channels_last if cl else torch.contiguous_format)
    dtype = autocast_dtype(cfg, dev)
    model = torch.nn.parallel.DistributedDataParallel(teacher) if world > 1 else teacher
    optim = Optimizer(param_groups(teacher, teacher.encoder, t.lr, t.encoder_lr if t.pretrained else 1.0), t.lr,
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
            run.append_history({"phase": "teacher", "step": 0, "samples": 0, "seconds": 0.0,
                                "precision": precision_name(dtype), **_teacher_val(teacher, cfg, val_cache, dtype)})
    model.train()
    losses, t0 = [], time.perf_counter()
    for step in bar:
        b = next(batches)
        with _autocast(dev, dtype):
            logits, _ = model(_layout(scaled(b["image"], t.scale), cl))
        target = scaled(b["semantic"][:, None].float(), t.scale, "nearest")[:, 0].long()
        loss = F.cross_entropy(logits.float(), target, ignore_index=sm.IGNORE)
        optim.step(loss)
        losses.append(loss.item())
        bar.set_postfix(ce=f"{losses[-1]:.3f}")
        done = step + 1
        seconds = seconds_before + time.perf_counter() - t0
        if rank == 0 and val_cache is not None and t.eval_every and (done % t.eval_every == 0 or done == t.steps):
            run.append_history({"phase": "teacher", "step": done, "samples": done * t.batch_size * world,
                                "seconds": round(seconds, 1), "ce": float(np.mean(losses)),
                                "precision": precision_name(dtype), **_teacher_val(teacher, cfg, val_cache, dtype)})
            losses = []
        if rank == 0 and done < t.steps and done % t.checkpoint_every == 0:
            run.save_teacher_progress(teacher.state_dict(), {**optim.state_dict(), "step": done,
                                                             "torch_rng": torch.get_rng_state(), "seconds": seconds})
    if rank == 0:
        run.save_teacher({k: v.contiguous() for k, v in teacher.state_dict().items()})
    return teacher.eval()


def given_depth(model: torch.nn.Module, b: dict[str, torch.Tensor]) -> torch.Tensor | None:
    """The ground-truth depth of batch ``b`` for a model whose B reads it (``oracle_depth``, a research
    arm), else None. ``model`` may be wrapped (DistributedDataParallel)."""
    inner = getattr(model, "module", model)
    return b["depth"] if getattr(inner, "oracle_depth", False) else None


def outputs(model: torch.nn.Module, x: torch.Tensor, b: dict[str, torch.Tensor]) -> tuple[torch.Tensor, ...]:
    """``model(x)``, and for an ``oracle_depth`` model ``model(x, depth)`` with batch ``b``'s depth."""
    depth = given_depth(model, b)
    return model(x) if depth is None else model(x, depth.to(x.device))


@torch.no_grad()
def choose_threshold(model: torch.nn.Module, ds, batch: int = 8) -> tuple[float, dict[str, float]]:
    """The threshold with the best IoU inside V on ``ds`` (the validation split)."""
    model.eval()
    sweep = ThresholdSweep()
    dev = next(model.parameters()).device
    for b in DataLoader(ds, batch_size=batch):
        prob = torch.sigmoid(outputs(model, b["image"].to(dev), b)[0]).cpu().numpy()
        sweep.add(prob, b["blindspot"].numpy() > 0.5, b["visibility"].numpy() > 0.5)
    return sweep.best()


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


def losses(net: torch.nn.Module, b: dict[str, torch.Tensor], teacher: torch.nn.Module | None, cfg: Config,
           dtype: torch.dtype | None) -> tuple[torch.Tensor, ...]:
    """``(loss, bce, distillation, depth)`` of one batch: BCE inside V (out to ``train.bce_range_m``
    when set), D's depth loss, and lambda x the
    pairwise-similarity distillation against the batch's cached ``teacher_grid`` or, without one,
    a pass of ``teacher``. The networks run under ``dtype`` autocast; the losses are fp32."""
    cl = cfg.train.channels_last
    dev = b["image"].device
    with _autocast(dev, dtype):
        logits, depth, feats = outputs(net, _layout(b["image"], cl), b)
    logits, depth, feats = logits.float(), depth.float(), feats.float()
    valid = b["visibility"]
    if cfg.train.bce_range_m > 0:
        valid = visible_out_to(valid, b["depth"], b["semantic"], cfg.train.bce_range_m)
    l_bce = masked_bce(logits, b["blindspot"], valid)
    weight, free_scale = depth_weights(b, cfg)
    l_depth = depth_loss(depth, b["depth"], b["sky"], weight, cfg.train.depth_grad_scales, free_scale)
    loss = l_bce + cfg.train.depth_weight * l_depth
    l_kd = torch.zeros((), device=dev)
    if teacher is not None:
        if "teacher_grid" in b:
            t_feats = b["teacher_grid"]
        else:
            with torch.no_grad(), _autocast(dev, dtype):
                _, t_feats = teacher(_layout(scaled(b["image"], cfg.teacher.scale), cl))
        l_kd = distillation_loss(feats, t_feats.float(), cfg.train.distill_grid)
        loss = loss + cfg.distill_weight * l_kd
    return loss, l_bce, l_kd, l_depth


ROAD_RANGE_M = (5.0, 40.0)   # as the real-camera benchmark reads road depth


@torch.no_grad()
def validate(model: torch.nn.Module, cache: SampleCache, frames: int, dtype: torch.dtype | None = None,
             channels_last: bool = False) -> dict[str, float]:
    """Validation figures on up to ``frames`` evenly spaced samples of ``cache``: IoU inside V at the
    best threshold of the sweep, D's depth AbsRel (pixels with depth, sky left out) and, apart, on
    the road ``ROAD_RANGE_M`` away (the road the product reads its geometry from, which the
    all-pixel figure can hide)."""
    was = model.training
    model.eval()
    dev = next(model.parameters()).device
    sweep = ThresholdSweep()
    err, n, road_err, road_n = 0.0, 0, 0.0, 0
    for b in cache.evenly(frames):
        with _autocast(dev, dtype):
            logits, depth, _ = outputs(model, _layout(b["image"].to(dev), channels_last), b)
        sweep.add(torch.sigmoid(logits.float()).cpu().numpy(), b["blindspot"].numpy() > 0.5,
                  b["visibility"].numpy() > 0.5)
        gt = b["depth"]
        rel = (depth.float().cpu() - gt).abs() / gt.clamp_min(MIN_DEPTH_M)
        ok = (gt >= MIN_DEPTH_M) & (gt <= MAX_DEPTH_M) & ~b["sky"]
        road = ok & (b["semantic"][:, None] == sm.ROAD) & (gt >= ROAD_RANGE_M[0]) & (gt <= ROAD_RANGE_M[1])
        err, n = err + float(rel[ok].sum()), n + int(ok.sum())
        road_err, road_n = road_err + float(rel[road].sum()), road_n + int(road.sum())
    model.train(was)
    threshold, metrics = sweep.best()
    return {"iou": metrics["iou"], "threshold": threshold, "abs_rel": err / max(n, 1),
            "road_abs_rel": road_err / road_n if road_n else float("nan")}


def param_groups(model: torch.nn.Module, encoder: torch.nn.Module | None, lr: float,
                 encoder_share: float) -> list[dict]:
    """Adam's parameter groups: ``model``'s ``encoder`` at ``encoder_share`` of ``lr`` (a pretrained
    encoder keeps more of what it learnt on real photographs), the rest at ``lr``."""
    if encoder is None or encoder_share == 1.0:
        return [{"params": list(model.parameters())}]
    own = {id(p) for p in encoder.parameters()}
    return [{"params": list(encoder.parameters()), "lr": lr * encoder_share},
            {"params": [p for p in model.parameters() if id(p) not in own]}]


def train(cfg: Config, data_dir: str | Path, out: str | Path, resume: bool = False,
          progress: bool = True, force: bool = False, stop_after: float | None = None) -> dict[str, Any]:
    """Train per ``cfg`` on the labelled clips under ``data_dir``; write the run to ``out``.

    An existing run is refused unless ``resume`` (continue it: verified state, same data stream)
    or ``force`` (start again). ``stop_after`` (seconds) ends this piece of a longer training at
    the first step past it (counted from this call, the teacher and the caches included), with a
    checkpoint to resume from; the learning-rate schedule spans ``train.steps``, whatever the pieces."""
    piece_start = time.perf_counter()
    rank, world = _dist()
    cfg = with_teachers_build(cfg)
    run, torn, state = _open_run(cfg, out, resume, force, rank, world)
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
    model.to(memory_format=torch.channels_last if cl else torch.contiguous_format)
    net = torch.nn.parallel.DistributedDataParallel(model) if world > 1 else model
    batches = _batches(cfg, data, cache, state, start, rank, world, dev)
    if rank == 0:
        _start_history(run, model, cfg, start, dtype, val_caches)
    bar = progress_bar(range(start, cfg.train.steps), initial=start, total=cfg.train.steps,
                       desc=f"train {cfg.model.name}", unit="step", enabled=progress and not rank)
    last: list[float] | None = None                      # this piece's latest step
    since, first = _carried(state)
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
            _checkpoint(run, model, optim, cfg, data, done, world, seconds, kinds, since, first)
        if out_of_time:
            break
    summary: dict[str, Any] = {"steps": cfg.train.steps, "resumed_from": start, "steps_run": done - start,
                               "seconds": round(time.perf_counter() - t0, 1), "final_loss": last,
                               "skipped_clips": [f"{name}: {why}" for name, why in data.skipped],
                               "removed_torn_writes": [str(t) for t in torn]}
    if done < cfg.train.steps:
        summary["stopped_at"] = done
    elif rank == 0:
        summary.update(_finish(run, model, cfg, data, [first, last] if last else None))
    if world > 1:
        dist.barrier()
    return summary


def train_teacher_alone(cfg: Config, data_dir: str | Path, out: str | Path, resume: bool = False,
                        progress: bool = True, force: bool = False) -> dict[str, Any]:
    """Train the segmentation teacher alone into ``out`` (``teacher/teacher.pt``, ``config.json`` and
    the history), for later runs to distil from with ``teacher.checkpoint``: no student, no teacher
    features cached. ``resume`` goes on from the teacher's last state; a teacher trained already is
    left as it is."""
    if cfg.teacher.checkpoint:
        raise ValueError("training a teacher alone: teacher.checkpoint names one trained already")
    rank, world = _dist()
    run, torn, _ = _open_run(cfg, out, resume, force, rank, world)
    data = datasets(cfg, data_dir)
    if rank == 0:
        run.write_config(cfg.to_dict())
    show = progress and rank == 0
    cache = sample_cache(cfg, data.train_ds, show, "caching training samples")
    val = sample_cache(cfg, data.val_ds, show, "caching validation samples") \
        if data.val_ds is not None and cfg.data.cache != "off" else None
    train_teacher(cfg, data.train_ds, run, rank, world, progress, cache, val, resume=resume)
    return {"teacher_steps": cfg.teacher.steps, "teacher": str(run.teacher_path),
            "skipped_clips": [f"{name}: {why}" for name, why in data.skipped],
            "removed_torn_writes": [str(t) for t in torn]}


def _caches_and_teacher(cfg: Config, data, run: Run, rank: int, world: int, progress: bool, resume: bool,
                        dtype: torch.dtype | None):
    """The training batches' cache (a :class:`CameraMix` when guessed cameras are asked for), the
    validation caches by the prefix of their history keys (``val_``, ``val_guessed_``), and the teacher
    (trained or taken as the config says, its features attached to the training caches); None where
    there is none."""
    show = progress and rank == 0
    cache = sample_cache(cfg, data.train_ds, show, "caching training samples")
    val_caches: dict[str, SampleCache] = {}
    if data.val_ds is not None and cfg.data.cache != "off":
        val_caches["val_"] = sample_cache(cfg, data.val_ds, show, "caching validation samples")
    guessed = sample_cache(cfg, data.train_guessed_ds, show, "caching samples, guessed cameras") \
        if data.train_guessed_ds is not None else None
    if data.val_guessed_ds is not None:
        val_caches["val_guessed_"] = sample_cache(cfg, data.val_guessed_ds, show,
                                                  "caching validation samples, guessed cameras")
    teacher = (train_teacher(cfg, data.train_ds, run, rank, world, progress, cache, val_caches.get("val_"),
                             resume=resume) if cfg.distill_weight > 0 else None)
    cl = cfg.train.channels_last
    for c in (cache, guessed):
        if teacher is not None and c is not None:
            c.attach_teacher(teacher, cfg.teacher.scale, cfg.train.distill_grid, progress=show,
                             resize=lambda x, sc: _layout(scaled(x, sc), cl), dtype=dtype)
    if guessed is not None:
        cache = CameraMix(cache, guessed, cfg.data.guessed_camera)
    return cache, val_caches, teacher


def _validation(model: BlindSpotNet, cfg: Config, dtype: torch.dtype | None,
                val_caches: dict[str, SampleCache]) -> dict[str, float]:
    """The history's validation figures: :func:`validate` on each cache, keys prefixed as named."""
    return {f"{prefix}{k}": v for prefix, c in val_caches.items()
            for k, v in validate(model, c, cfg.train.eval_frames, dtype, cfg.train.channels_last).items()}


def _start_history(run: Run, model: BlindSpotNet, cfg: Config, start: int, dtype: torch.dtype | None,
                   val_caches: dict[str, SampleCache]) -> None:
    """The history from ``start`` on; a run started from another records where it begins (its gain is
    then measured, not assumed)."""
    run.trim_history("train", start)
    if start == 0 and cfg.train.init and cfg.train.eval_every and val_caches:
        run.append_history({"phase": "train", "step": 0, "samples": 0, "seconds": 0.0,
                            "precision": precision_name(dtype), **_validation(model, cfg, dtype, val_caches)})


def _step(net, optim: Optimizer, batch, teacher, cfg: Config, dtype: torch.dtype | None) -> list[float]:
    """One optimizer step on ``batch``; its losses (total, BCE, distillation, depth)."""
    loss, l_bce, l_kd, l_depth = losses(net, batch, teacher, cfg, dtype)
    optim.step(loss)
    return [loss.item(), l_bce.item(), l_kd.item(), l_depth.item()]


def _carried(state: dict[str, Any] | None) -> tuple[list[list[float]], list[float] | None]:
    """What the loss records carry across pieces: the losses since the last record (a record after a
    stop between records averages the same steps as the uninterrupted run's) and the run's first step's."""
    if state is None:
        return [], None
    return [list(x) for x in state.get("since", [])], state.get("first_loss")


def _open_run(cfg: Config, out: str | Path, resume: bool, force: bool, rank: int,
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
        _check_resumable(run, cfg, state)
    return run, torn, state


def _batches(cfg: Config, data, cache, state: dict[str, Any] | None, start: int, rank: int, world: int,
             dev: torch.device):
    """The training batches from step ``start`` on, and the random draws where the saved state left them."""
    batches = training_batches(data.train_ds, cache, cfg.train.batch_size, world, rank, cfg.train.seed,
                               cfg.data.workers, start, device=dev, real_share=cfg.data.real_share)
    if state is not None and "torch_rng" in state:
        # dropout draws go on where they stopped (after the loader, which takes a draw of its own)
        torch.set_rng_state(state["torch_rng"])
    return batches


def _checkpoint(run: Run, model: BlindSpotNet, optim: Optimizer, cfg: Config, data, done: int, world: int,
                seconds: float, kinds: list[str], since: list[list[float]], first: list[float] | None) -> None:
    """Save the weights and everything a resumed piece needs to go on as if never stopped."""
    trained = {"samples": done * cfg.train.batch_size * world, "seconds": round(seconds, 1), "precision": kinds}
    _save(run, model, cfg, data, done, threshold=None, trained=trained,
          resume_state={**optim.state_dict(), "step": done, "torch_rng": torch.get_rng_state(),
                        "seconds": seconds, "precision": kinds, "since": since, "first_loss": first})


def _check_resumable(run: Run, cfg: Config, state: dict[str, Any] | None) -> None:
    """``RunError`` when ``run`` cannot go on under ``cfg``: no state to resume from, or another model."""
    if state is None and run.exists() and not run.teacher_state_path.is_file():
        raise RunError(f"{run.path}: no {Run.STATE} to resume from (made by an older version, or a run that "
                       "never checkpointed); --force starts it again")
    if run.config_path.is_file() and run.config().get("model", {}).get("name") not in (None, cfg.model.name):
        raise RunError(f"{run.path} trains {run.config()['model']['name']!r}, the config asks for {cfg.model.name!r}")


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
    rec.update(_validation(model, cfg, dtype, val_caches))
    return rec


def _finish(run: Run, model: BlindSpotNet, cfg: Config, data, loss_first_last) -> dict[str, Any]:
    """The threshold chosen on the validation clips and the final card written; what the summary adds."""
    out: dict[str, Any] = {}
    threshold, val = UNCHOSEN_THRESHOLD, {}
    if data.val_ds is not None:
        threshold, val = choose_threshold(model, data.val_ds)
    else:
        out["threshold_note"] = f"no validation clips: threshold left at {UNCHOSEN_THRESHOLD}"
    card = _save(run, model, cfg, data, cfg.train.steps, threshold=threshold, val=val, loss_first_last=loss_first_last)
    return {**out, "threshold": threshold, "val": val, "weights_sha256": card.weights_sha256}


def _save(run: Run, model, cfg: Config, data: Datasets, step: int, threshold: float | None,
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
