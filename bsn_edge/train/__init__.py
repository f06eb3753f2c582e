"""Training: config, losses, the run folder, the trainer."""

from bsn_edge.train.config import Config, load_config
from bsn_edge.train.losses import depth_loss, distillation_loss, masked_bce, pairwise_similarity
from bsn_edge.train.run import Run, RunError

__all__ = ["Config", "Run", "RunError", "depth_loss", "distillation_loss", "load_config", "masked_bce",
           "pairwise_similarity"]
