"""How a pretrained encoder's batch norm behaves in training.

At batch 8 a batch's own statistics are noisy, and a synthetic batch's are not those of the real
photographs the encoder's ImageNet statistics came from. :attr:`EncoderNorm.FROZEN` keeps the
statistics the encoder came with (ImageNet's, or those of the run it starts from) and lets batch
norm's scale and shift learn; :attr:`EncoderNorm.BATCH` is batch norm as it is usually trained.
Exported and evaluated models normalise with their running statistics either way.
"""

from __future__ import annotations

from enum import Enum

from torch import nn


class EncoderNorm(Enum):
    """What the frame encoder's batch norm normalises with while it trains."""

    BATCH = "batch"     # each batch's statistics; the running ones follow them
    FROZEN = "frozen"   # the running statistics it came with, never updated


class FrozenStatsBatchNorm2d(nn.BatchNorm2d):
    """Batch norm that normalises with its running statistics and never updates them, in training
    too; its scale and shift still learn. Its state dict is a :class:`~torch.nn.BatchNorm2d`'s."""

    def __init__(self, *args, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        self.training = False

    def train(self, mode: bool = True) -> FrozenStatsBatchNorm2d:
        return super().train(False)


def freeze_norm_stats(module: nn.Module) -> int:
    """Replace every :class:`~torch.nn.BatchNorm2d` inside ``module`` by a
    :class:`FrozenStatsBatchNorm2d` holding the same parameters and statistics; returns how many.
    Call it before an optimizer is given the parameters (they are new objects)."""
    swapped = 0
    for parent in list(module.modules()):
        for name, child in list(parent.named_children()):
            if type(child) is nn.BatchNorm2d:
                frozen = FrozenStatsBatchNorm2d(child.num_features, child.eps, child.momentum, child.affine,
                                                child.track_running_stats)
                frozen.load_state_dict(child.state_dict())
                setattr(parent, name, frozen.to(child.weight.device if child.affine else "cpu"))
                swapped += 1
    return swapped
