"""Training configuration: TOML file + ``key=value`` overrides -> validated frozen dataclasses."""

from __future__ import annotations

import dataclasses
import hashlib
import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from bsn_edge.camera import Intrinsics
from bsn_edge.config_toml import build, merge_overrides, read_toml
from bsn_edge.data.guessed_camera import GuessedDepth
from bsn_edge.model_frame import MODEL_HFOV_DEG, MODEL_PITCH_DEG, model_camera
from bsn_edge.mounting import REFERENCE_HEIGHT_M, Mounting
from bsn_edge.networks import get_spec, teacher_encoder
from bsn_edge.train.encoder_norm import EncoderNorm


@dataclass(frozen=True)
class ModelConfig:
    name: str = "small-light"

    def __post_init__(self) -> None:
        get_spec(self.name)


@dataclass(frozen=True)
class DataConfig:
    size: tuple[int, int] = (128, 256)       # training size (H, W)
    label: str = "T5s"
    val_fraction: float = 0.2
    test_fraction: float = 0.0
    split_seed: int = 0
    train_styles: tuple[str, ...] = ()       # empty: all styles
    fraction: float = 1.0                    # share of the training clips used (fine-tuning: 0.2)
    workers: int = 0                         # loader processes when the cache is off
    # decoded, warped samples kept once for the whole run (bsn_edge.data.cache): "auto" (the user's
    # cache folder, or $BSN_EDGE_CACHE), "memory", "off" (decode every sample every step) or a folder
    cache: str = "auto"
    # the model camera every clip is warped into (written on the model card): horizontal field of
    # view at ``size``, reference height above the road and pitch (down positive)
    camera_hfov_deg: float = MODEL_HFOV_DEG
    camera_height_m: float = REFERENCE_HEIGHT_M
    camera_pitch_deg: float = MODEL_PITCH_DEG
    # share of training samples whose vehicles and people are repainted (bsn_edge.data.repaint)
    object_repaint: float = 0.0
    # share of training samples that show the scene through their vehicles and people (glass)
    object_see_through: float = 0.0
    # share of training samples shown through a camera of their own: white balance, contrast,
    # saturation, tone curve, blur and noise (bsn_edge.data.camera_look)
    camera_look: float = 0.0
    # share of training samples warped with the camera a user without a camera file gets instead of
    # the clip's own (bsn_edge.data.guessed_camera: half as bsn-run starts, half midway through
    # online calibration); they come from a second sample cache, so the cache cannot be "off"
    guessed_camera: float = 0.0
    # what the guessed-camera samples teach D (bsn_edge.data.guessed_camera.GuessedDepth): "metric",
    # "scale-free" (up to a factor of their own) or "none"
    guessed_depth: str = GuessedDepth.METRIC.value
    # share of each training batch drawn from real pictures (clips of style "camvid": bsn_edge.labels.camvid),
    # however few they are beside the synthetic clips; 0: every sample alike
    real_share: float = 0.0

    def __post_init__(self) -> None:
        if self.guessed_depth not in {g.value for g in GuessedDepth}:
            raise ValueError(f"data.guessed_depth must be one of {', '.join(g.value for g in GuessedDepth)}, "
                             f"got {self.guessed_depth!r}")
        if not 0.0 <= self.real_share < 1.0:
            raise ValueError(f"data.real_share is a share of each batch in [0, 1), got {self.real_share}")
        for name in ("object_repaint", "object_see_through", "camera_look", "guessed_camera"):
            if not 0.0 <= getattr(self, name) <= 1.0:
                raise ValueError(f"data.{name} is a share of samples in [0, 1], got {getattr(self, name)}")
        if len(self.size) != 2 or min(self.size) < 32 or any(s % 32 for s in self.size):
            raise ValueError(f"data.size must be two multiples of 32 (H, W), got {self.size}")
        if not 0 < self.fraction <= 1:
            raise ValueError(f"data.fraction must be in (0, 1], got {self.fraction}")
        if not self.cache.strip():
            raise ValueError('data.cache must be "auto", "memory", "off" or a folder, got an empty string')
        if self.guessed_camera > 0 and self.cache == "off":
            raise ValueError('data.guessed_camera draws from a second sample cache: it needs data.cache other '
                             'than "off"')
        self.model_camera()   # validates the camera

    def model_camera(self) -> tuple[Intrinsics, Mounting]:
        """The model camera: intrinsics at ``size`` and its mounting."""
        return model_camera(self.size, self.camera_hfov_deg, self.camera_height_m, self.camera_pitch_deg)


ADAMW, ADAM = "adamw", "adam"
OPTIMIZERS = (ADAMW, ADAM)
# past this, a few people's pixels would outweigh the rest of a batch's blind spots
MAX_PEOPLE_WEIGHT = 20.0


@dataclass(frozen=True)
class TrainConfig:
    steps: int = 400
    batch_size: int = 8
    lr: float = 1e-3
    betas: tuple[float, float] = (0.9, 0.999)
    eps: float = 1e-8
    # "adamw": decoupled decay on weights only; "adam": L2 on everything, the recipe that zeroed most
    # channels of the runs trained with it (bsn_edge.train.optim.Optimizer), kept to reproduce them
    optimizer: str = ADAMW
    weight_decay: float = 1e-2
    poly_power: float = 0.9
    distill_weight: float = 1.0              # lambda
    depth_weight: float = 1.0
    depth_object_weight: float = 1.0         # depth loss weight of vehicle and person pixels (road: 1)
    depth_grad_scales: int = 0               # scales of the depth gradient-matching term (0: off)
    distill_grid: tuple[int, int] = (8, 16)
    seed: int = 0
    threads: int = 2
    device: str = "cpu"                      # cpu, cuda or auto (cuda when torch sees a GPU)
    checkpoint_every: int = 100
    init: str = ""                           # start from this run's weights (fine-tuning)
    # re-draw train.init's dead channels before training on (bsn_edge.networks.revive)
    revive: bool = False
    encoder_lr: float = 1.0                  # share of lr for an encoder that starts from ImageNet weights
    # what the frame encoder's batch norm normalises with in training (bsn_edge.train.encoder_norm.
    # EncoderNorm): "batch" (each batch's statistics) or "frozen" (the statistics it came with)
    encoder_bn: str = EncoderNorm.BATCH.value
    # arithmetic of the forward and backward passes: fp32, bf16 (autocast; weights and losses stay
    # fp32) or auto (bf16 where the CPU has native bf16: AMX or AVX-512 BF16; CUDA: fp32)
    precision: str = "auto"
    channels_last: bool = True               # NHWC activations (oneDNN's native layout on CPUs)
    eval_every: int = 0                      # steps between validation records in the run's history (0: off)
    eval_frames: int = 256                   # validation frames per record (evenly spaced over the split)
    # BCE over the labels' V (the paper's L: surfaces nearer than 16 m, where depth from a model can
    # be trusted) widened to every pixel the clip sees nearer than this many metres: far occluders
    # are taught as well. Rendered clips only, whose depth is exact (0: V as labelled)
    bce_range_m: float = 0.0
    # BCE weight of the positive pixels on people and what they ride (semantics.PEOPLE_AND_CYCLES); every
    # other pixel weighs 1. Their positives are a few % of the labels' (bsn_edge/benchmarks/bench_label_classes.py)
    people_weight: float = 1.0

    def __post_init__(self) -> None:
        if self.steps < 1 or self.batch_size < 1:
            raise ValueError("train.steps and train.batch_size must be >= 1")
        if not self.lr > 0 or self.distill_weight < 0 or self.depth_weight < 0:
            raise ValueError("train.lr must be positive, the loss weights non-negative")
        if not 0 < self.encoder_lr <= 1:
            raise ValueError(f"train.encoder_lr must be in (0, 1], got {self.encoder_lr}")
        if self.depth_object_weight <= 0 or not 0 <= self.depth_grad_scales <= 6:
            raise ValueError("train.depth_object_weight must be positive, train.depth_grad_scales in 0..6")
        if self.encoder_bn not in {n.value for n in EncoderNorm}:
            raise ValueError(f"train.encoder_bn must be one of {', '.join(n.value for n in EncoderNorm)}, "
                             f"got {self.encoder_bn!r}")
        if self.device not in ("cpu", "cuda", "auto"):
            raise ValueError(f"train.device must be cpu, cuda or auto, got {self.device!r}")
        if self.precision not in ("fp32", "bf16", "auto"):
            raise ValueError(f"train.precision must be fp32, bf16 or auto, got {self.precision!r}")
        if self.eval_every < 0 or self.eval_frames < 1:
            raise ValueError("train.eval_every must be >= 0 and train.eval_frames >= 1")
        if self.bce_range_m < 0:
            raise ValueError(f"train.bce_range_m is metres (0: off), got {self.bce_range_m}")
        if self.revive and not self.init:
            raise ValueError("train.revive re-draws the dead channels of the weights train.init starts from; "
                             "set train.init to a run (a new network has none dead)")
        if not 1.0 <= self.people_weight <= MAX_PEOPLE_WEIGHT:
            raise ValueError(f"train.people_weight must be in [1, {MAX_PEOPLE_WEIGHT:g}], got {self.people_weight}")
        if self.optimizer not in OPTIMIZERS:
            raise ValueError(f"train.optimizer must be one of {', '.join(OPTIMIZERS)}, got {self.optimizer!r}")
        if not 0 <= self.weight_decay < 1:
            raise ValueError(f"train.weight_decay must be in [0, 1), got {self.weight_decay}")


@dataclass(frozen=True)
class TeacherConfig:
    steps: int = 300
    batch_size: int = 8
    lr: float = 1e-3
    # resnet18/34/50/101, or efficientnet-lite0 (TEACHER_ENCODERS); a whole number N is resnetN (runs
    # written before names), which the loader lets through for __post_init__ to name
    encoder: str = field(default="resnet18", metadata={"also": (int,)})
    pretrained: bool = False                 # a new teacher starts from the encoder's ImageNet weights
    encoder_lr: float = 1.0                  # share of lr for the encoder of a pretrained teacher
    width: int = 128
    scale: float = 0.5                       # the teacher sees the frame at this scale (its features
                                             # are pooled to a coarse grid for distillation anyway)
    checkpoint: str = ""                     # a trained teacher's folder; empty trains one first
    init: str = ""                           # train the run's teacher on from this trained teacher's weights
    eval_every: int = 0                      # steps between held-out mIoU records in the run's history (0: off)
    checkpoint_every: int = 500              # steps between saved training states (--resume goes on from the last)

    def __post_init__(self) -> None:
        try:
            object.__setattr__(self, "encoder", teacher_encoder(self.encoder, self.pretrained))
        except ValueError as e:
            raise ValueError(f"teacher.encoder: {e}") from None
        if self.checkpoint_every < 1:
            raise ValueError(f"teacher.checkpoint_every must be >= 1, got {self.checkpoint_every}")
        if not 0 < self.encoder_lr <= 1:
            raise ValueError(f"teacher.encoder_lr must be in (0, 1], got {self.encoder_lr}")
        if not 0.1 <= self.scale <= 1.0:
            raise ValueError(f"teacher.scale must be in [0.1, 1], got {self.scale}")
        if self.checkpoint and self.init:
            raise ValueError("teacher.checkpoint uses a trained teacher as it is, teacher.init trains one on from "
                             "it: set one of them")


@dataclass(frozen=True)
class Config:
    model: ModelConfig = field(default_factory=ModelConfig)
    data: DataConfig = field(default_factory=DataConfig)
    train: TrainConfig = field(default_factory=TrainConfig)
    teacher: TeacherConfig = field(default_factory=TeacherConfig)

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)

    def digest(self) -> str:
        """Short hash of the resolved config (written into checkpoints and exported models)."""
        return hashlib.sha256(json.dumps(self.to_dict(), sort_keys=True).encode()).hexdigest()[:16]

    @property
    def distill_weight(self) -> float:
        """lambda as used: 0 for a registry entry trained without distillation (``*-kd``)."""
        return self.train.distill_weight if get_spec(self.model.name).distill else 0.0


SECTIONS = {"model": ModelConfig, "data": DataConfig, "train": TrainConfig, "teacher": TeacherConfig}


def load_config(path: str | Path | None = None, overrides: list[str] | tuple[str, ...] = ()) -> Config:
    """Read a TOML config and apply overrides; unknown sections or keys are errors that list the
    valid ones (the mechanism of :mod:`bsn_edge.config_toml`)."""
    raw = read_toml(path)
    given = merge_overrides(raw, overrides, example="train.steps=100")
    parts = {}
    for section, values in raw.items():
        if section not in SECTIONS:
            raise ValueError(f"unknown config section [{section}]; valid: {', '.join(SECTIONS)}")
        parts[section] = build(SECTIONS[section], values, section, str(path), given)
    return Config(**parts)
