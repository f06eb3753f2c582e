"""The optimizer, its schedule and one step: shared by training (D, B, the teacher) and
``bsn-adapt``'s fine-tuning, so that fine-tuning is the training's own step."""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any

import torch

from bsn_edge.train.config import ADAMW, TrainConfig


class Optimizer:
    """The training's optimizer (``train.optimizer``) with its betas, eps and weight decay, its learning
    rate decayed as ``(1 - step / steps) ** poly_power`` over ``steps`` (the whole training, whatever its
    pieces).

    ``adamw`` (the default): decoupled weight decay (each step shrinks a weight by ``lr x weight_decay``
    of itself), on the convolutions' and linear layers' weights only; normalisation scales and biases are
    not decayed. ``adam``: the recipe before it, L2 decay added to every gradient, normalisation scales
    and biases included. Adam normalises that decay like any gradient, so a channel with little gradient
    of its own walks to exactly zero at the learning rate's pace: it killed 81 % of the default's
    channels (``bsn_edge.networks.alive``). Kept to reproduce the runs trained with it."""

    def __init__(self, params: Iterable[torch.nn.Parameter] | Iterable[dict], lr: float, steps: int,
                 t: TrainConfig, fused: bool = False) -> None:
        """``params``: parameters, or parameter groups as :func:`param_groups` makes them; ``fused``:
        torch's one-kernel Adam (the same update; the state is interchangeable with the per-tensor one's)."""
        groups: list[Any] = decay_groups(params, t.weight_decay) if t.optimizer == ADAMW else list(params)
        if t.optimizer == ADAMW:
            self.opt: torch.optim.Optimizer = torch.optim.AdamW(groups, lr=lr, betas=t.betas, eps=t.eps,
                                                                fused=fused or None)
        else:
            self.opt = torch.optim.Adam(groups, lr=lr, betas=t.betas, eps=t.eps, weight_decay=t.weight_decay,
                                        fused=fused or None)
        power = t.poly_power
        self.sched = torch.optim.lr_scheduler.LambdaLR(self.opt, lambda s: max(1.0 - s / steps, 0.0) ** power)

    def step(self, loss: torch.Tensor) -> None:
        """Gradients of ``loss``, one update, the schedule moved on."""
        self.opt.zero_grad(set_to_none=True)
        loss.backward()
        self.opt.step()
        self.sched.step()

    def state_dict(self) -> dict:
        return {"optimizer": self.opt.state_dict(), "scheduler": self.sched.state_dict()}

    def load_state_dict(self, state: dict) -> None:
        """Resume from a state as :meth:`state_dict` writes it (the scheduler's part is optional)."""
        try:
            self.opt.load_state_dict(state["optimizer"])
        except ValueError as e:        # groups that do not match: another optimizer's state
            raise ValueError(f"the saved optimizer state is not this optimizer's ({e}): a run trained with "
                             "train.optimizer = \"adam\" (the recipe before adamw, with train.weight_decay = "
                             "5e-4) resumes only with those settings; or start anew from its weights "
                             "(train.init)") from None
        if "scheduler" in state:
            self.sched.load_state_dict(state["scheduler"])


def decays(p: torch.nn.Parameter) -> bool:
    """Whether decoupled weight decay applies: a convolution's or linear layer's weight (two axes or
    more), not a normalisation scale or a bias (one axis)."""
    return p.ndim >= 2


def decay_groups(params: Iterable[torch.nn.Parameter] | Iterable[dict], weight_decay: float) -> list[dict[str, Any]]:
    """Each parameter group split in two: its weights decayed by ``weight_decay``, its normalisation
    scales and biases not (``decays``); the group's other settings (its learning rate) kept by both."""
    given: list[Any] = list(params)
    groups: list[dict[str, Any]] = given if given and isinstance(given[0], dict) else [{"params": given}]
    out = []
    for g in groups:
        ps = list(g["params"])
        rest = {k: v for k, v in g.items() if k != "params"}
        out.append({**rest, "params": [p for p in ps if decays(p)], "weight_decay": weight_decay})
        out.append({**rest, "params": [p for p in ps if not decays(p)], "weight_decay": 0.0})
    return [g for g in out if g["params"]]


def param_groups(model: torch.nn.Module, encoder: torch.nn.Module | None, lr: float,
                 encoder_share: float) -> list[dict]:
    """Adam's parameter groups: ``model``'s ``encoder`` at ``encoder_share`` of ``lr`` (a pretrained
    encoder keeps more of what it learnt on real photographs), the rest at ``lr``."""
    if encoder is None or encoder_share == 1.0:
        return [{"params": list(model.parameters())}]
    own = {id(p) for p in encoder.parameters()}
    return [{"params": list(encoder.parameters()), "lr": lr * encoder_share},
            {"params": [p for p in model.parameters() if id(p) not in own]}]
