"""Training health: the share of a network's channels that are alive.

A convolution's output channel is dead when its weights are all (about) zero, when the batch norm right
after it scales it by (about) nothing, or when that norm has seen it vary by (about) nothing: any way it
carries no information about the picture, though the graph still computes it. Adam with L2 weight decay
drives channels there (the decay's gradient is normalised like any other, so a channel with little
gradient of its own walks to zero at the learning rate's pace). Behind a batch norm the walk is the
convolution's weights, not the norm's scale: the norm divides their size out, so the channel works on
while its weights shrink by orders of magnitude and dies when its variation sinks under the norm's
epsilon; weights stored in fp16 then round to exactly zero. A healthy run keeps nearly all of them.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch

# a normalisation scale under this (in absolute value) silences its channel
SCALE_EPS = 1e-3
# a convolution row whose every weight is under this (in absolute value) computes nothing: fp32 weights
# walking to zero pass here long before they reach it, and fp16 storage rounds them to zero below 6e-8
WEIGHT_EPS = 1e-6
# a batch norm whose running variance of a channel is under this share of its epsilon passes on under a
# tenth of that channel's variation (sqrt(var / (var + eps)) < 0.1): what is left is its constant shift
VAR_SHARE = 1e-2
# a layer with fewer of its channels alive than this share is named in the one-line summary
WEAK_LAYER_SHARE = 0.5


@dataclass(frozen=True)
class LayerAlive:
    """One convolution: its output channels and how many of them are alive."""

    name: str
    channels: int
    alive: int

    @property
    def share(self) -> float:
        return self.alive / self.channels if self.channels else 1.0


@dataclass(frozen=True)
class Alive:
    """Every convolution of a network, in the order the network holds them."""

    layers: tuple[LayerAlive, ...]

    @property
    def channels(self) -> int:
        return sum(la.channels for la in self.layers)

    @property
    def alive(self) -> int:
        return sum(la.alive for la in self.layers)

    @property
    def share(self) -> float:
        return self.alive / self.channels if self.channels else 1.0

    @property
    def weak(self) -> tuple[LayerAlive, ...]:
        """The layers with fewer than :data:`WEAK_LAYER_SHARE` of their channels alive."""
        return tuple(la for la in self.layers if la.share < WEAK_LAYER_SHARE)

    def line(self) -> str:
        """One line for a card, a log or a report."""
        return (f"alive channels {100 * self.share:.1f} % ({self.alive:,} of {self.channels:,}; "
                f"{len(self.weak)} of {len(self.layers)} convolutions under {100 * WEAK_LAYER_SHARE:.0f} % alive)")

    def to_dict(self, per_layer: bool = False) -> dict[str, object]:
        """The record a run's history and report keep (``per_layer``: each convolution too)."""
        out: dict[str, object] = {"alive_share": round(self.share, 4), "alive_channels": self.alive,
                                  "channels": self.channels, "weak_layers": len(self.weak)}
        if per_layer:
            out["layers"] = [{"name": la.name, "channels": la.channels, "alive": la.alive} for la in self.layers]
        return out


def following_norm(modules: list[tuple[str, torch.nn.Module]],
                   i: int) -> torch.nn.modules.batchnorm._BatchNorm | None:
    """The batch norm that scales convolution ``modules[i]``'s channels: the next module in the network's
    order, when it is an affine batch norm of as many channels; else None."""
    conv, nxt = modules[i][1], (modules[i + 1][1] if i + 1 < len(modules) else None)
    if isinstance(conv, torch.nn.Conv2d) and isinstance(nxt, torch.nn.modules.batchnorm._BatchNorm) \
            and nxt.affine and nxt.num_features == conv.out_channels:
        return nxt
    return None


def dead_rows(conv: torch.nn.Conv2d, norm: torch.nn.modules.batchnorm._BatchNorm | None,
              scale_eps: float = SCALE_EPS) -> torch.Tensor:
    """Which output channels of ``conv`` are dead (a bool per channel): every weight under
    :data:`WEIGHT_EPS`; or, with the batch norm ``norm`` after it, its scale at most ``scale_eps`` or its
    running variance under :data:`VAR_SHARE` of its epsilon."""
    w = conv.weight.detach()
    dead = w.reshape(w.shape[0], -1).abs().lt(WEIGHT_EPS).all(dim=1)
    if norm is not None:
        dead |= norm.weight.detach().abs().le(scale_eps)
        if norm.running_var is not None:
            dead |= norm.running_var.detach().lt(VAR_SHARE * norm.eps)
    return dead


def alive_channels(model: torch.nn.Module, scale_eps: float = SCALE_EPS) -> Alive:
    """Which output channels of every convolution of ``model`` are alive: not :func:`dead_rows`, the batch
    norm that follows a convolution being the next module in ``model``'s order, when it normalises as many
    channels."""
    modules = list(model.named_modules())
    layers = []
    for i, (name, m) in enumerate(modules):
        if not isinstance(m, torch.nn.Conv2d):
            continue
        dead = dead_rows(m, following_norm(modules, i), scale_eps)
        layers.append(LayerAlive(name, int(dead.numel()), int((~dead).sum())))
    return Alive(tuple(layers))
