"""Dead channels given a new start: a run trained with Adam and L2 decay (``train.optimizer = "adam"``)
carries most of its channels at exactly zero (:mod:`bsn_edge.networks.alive`). Training on from it keeps them
there: a zero-weight channel behind a zero batch-norm scale gets no gradient. Re-initialising them lets a
new training use them, while the channels that are alive keep what they learnt.

A dead channel is re-drawn the way :func:`bsn_edge.networks.alive.alive_channels` pairs layers: its
convolution row at random (normal, with the spread of the layer's living rows; Kaiming's where none
live), and the batch norm that follows it at its living scales' median (:data:`REVIVED_SCALE`), its
shift kept (the constant the next layers have learnt to read from it) and its statistics reset (mean 0,
variance 1; a training pass relearns them). A convolution with no batch norm after it is re-drawn at
:data:`UNNORMED_SCALE` of that spread (its bias kept), so the network's outputs move little at the start.
"""

from __future__ import annotations

import math

import torch

from bsn_edge.networks.alive import SCALE_EPS, dead_rows, following_norm

# a revived channel's norm starts at this share of its layer's living scale. At a tenth (0.001-0.01 in the
# default's encoder) Adam's steps of a learning rate's size swamped it: after 1,000 steps at 5e-4 half of them
# sat under the 1e-3 that counts a channel dead again. Their outgoing weights were decayed to exactly zero
# with them, so at the full living scale the revived channels still change little at the start (the
# default's logits by 4 % of their mean size) and their readout learns from there
REVIVED_SCALE = 1.0
# a convolution with no norm after it writes its row straight into what follows: re-drawn at a tenth
UNNORMED_SCALE = 0.1


@torch.no_grad()
def revive(model: torch.nn.Module, seed: int = 0, scale_eps: float = SCALE_EPS) -> int:
    """Re-initialise every dead output channel of ``model``'s convolutions in place (see the module's
    text); returns how many were revived. Alive channels are not touched; the draw is ``seed``'s."""
    gen = torch.Generator().manual_seed(seed)
    modules = list(model.named_modules())
    revived = 0
    for i, (_, m) in enumerate(modules):
        if not isinstance(m, torch.nn.Conv2d):
            continue
        bn = following_norm(modules, i)
        dead = dead_rows(m, bn, scale_eps)
        n = int(dead.sum())
        if n == 0:
            continue
        w = m.weight
        rows = w.reshape(w.shape[0], -1)
        living = rows[~dead]
        fan_in = rows.shape[1]
        std = float(living.std()) if living.numel() > 1 else math.sqrt(2.0 / fan_in)
        if bn is None:
            std *= UNNORMED_SCALE
        fresh = torch.randn((n, *w.shape[1:]), generator=gen) * std
        w[dead] = fresh.to(w.device, w.dtype)
        if bn is not None:
            scales = bn.weight.detach().abs()[~dead]
            scale = REVIVED_SCALE * (float(scales.median()) if scales.numel() else 1.0)
            bn.weight[dead] = scale
            if bn.running_mean is not None and bn.running_var is not None:
                bn.running_mean[dead] = 0.0
                bn.running_var[dead] = 1.0
        revived += n
    return revived
