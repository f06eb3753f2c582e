"""Fine-tuning B on a user's T-frame labels, and how well a model agrees with them."""

from __future__ import annotations

import numpy as np
import torch
from torch.utils.data import DataLoader

from bsn_edge.adapt.config import AdaptConfig
from bsn_edge.metrics import ThresholdSweep
from bsn_edge.networks import BlindSpotNet
from bsn_edge.progress import progress_bar
from bsn_edge.train.batches import batch_stream
from bsn_edge.train.config import TrainConfig
from bsn_edge.train.device import scaled
from bsn_edge.train.losses import distillation_loss, masked_bce
from bsn_edge.train.optim import Optimizer


@torch.no_grad()
def agreement(model: BlindSpotNet, ds, batch: int = 8) -> ThresholdSweep:
    """Pooled counts inside V of ``model``'s masks against ``ds``'s labels, at every candidate threshold."""
    model.eval()
    sweep = ThresholdSweep()
    for b in DataLoader(ds, batch_size=batch):
        prob = torch.sigmoid(model(b["image"])[0]).numpy()
        sweep.add(prob, b["blindspot"].numpy() > 0.5, b["visibility"].numpy() > 0.5)
    return sweep


def at_threshold(sweep: ThresholdSweep, threshold: float) -> dict[str, float]:
    """The sweep's metrics at the candidate threshold nearest ``threshold``."""
    k = int(np.argmin(np.abs(sweep.thresholds - threshold)))
    return {"threshold": float(sweep.thresholds[k]), **sweep.counts[k].metrics()}


def finetune_b(model: BlindSpotNet, ds, cfg: AdaptConfig, teacher: torch.nn.Module | None = None,
               teacher_scale: float = 1.0, distill_grid: tuple[int, int] = (8, 16),
               progress: bool = True) -> list[float]:
    """Train B (D frozen: B reads D's depth, so D must stay the one it was trained with) for
    ``cfg.steps`` on ``ds``: BCE inside V plus, with ``teacher``, the pairwise-similarity
    distillation. Returns the loss per step."""
    torch.manual_seed(cfg.seed)
    torch.set_num_threads(cfg.threads)
    model.depth_net.requires_grad_(False)
    optim = Optimizer(model.blindspot.parameters(), cfg.lr, cfg.steps, TrainConfig())   # training's step
    stream = batch_stream(ds, cfg.batch_size, 1, 0, cfg.seed, 0)
    model.train()
    model.depth_net.eval()
    losses = []
    for _ in progress_bar(range(cfg.steps), desc="fine-tune B", unit="step", enabled=progress):
        b = next(stream)
        logits, _, feats = model(b["image"])
        loss = masked_bce(logits, b["blindspot"], b["visibility"])
        if teacher is not None and cfg.distill_weight > 0:
            with torch.no_grad():
                _, t_feats = teacher(scaled(b["image"], teacher_scale))
            loss = loss + cfg.distill_weight * distillation_loss(feats, t_feats, distill_grid)
        optim.step(loss)
        losses.append(float(loss.item()))
    model.eval()
    model.depth_net.requires_grad_(True)
    return losses
