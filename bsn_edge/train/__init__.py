"""Training: config, losses, checkpoints, the trainer."""

from bsn_edge.train.checkpoint import load_model, read_meta
from bsn_edge.train.config import Config, load_config
from bsn_edge.train.losses import depth_loss, distillation_loss, masked_bce, pairwise_similarity

__all__ = ["Config", "depth_loss", "distillation_loss", "load_config", "load_model", "masked_bce",
           "pairwise_similarity", "read_meta"]
