"""The optimizer, its schedule and one step: shared by training (D, B, the teacher) and
``bsn-adapt``'s fine-tuning, so that fine-tuning is the training's own step."""

from __future__ import annotations

from collections.abc import Iterable

import torch

from bsn_edge.train.config import TrainConfig


class Optimizer:
    """Adam with the training's betas, eps and weight decay, its learning rate decayed as
    ``(1 - step / steps) ** poly_power`` over ``steps`` (the whole training, whatever its pieces)."""

    def __init__(self, params: Iterable[torch.nn.Parameter], lr: float, steps: int, t: TrainConfig,
                 fused: bool = False) -> None:
        """``fused``: torch's one-kernel Adam (the same update; the state is interchangeable with the
        per-tensor one's)."""
        self.opt = torch.optim.Adam(params, lr=lr, betas=t.betas, eps=t.eps, weight_decay=t.weight_decay,
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
        self.opt.load_state_dict(state["optimizer"])
        if "scheduler" in state:
            self.sched.load_state_dict(state["scheduler"])


def param_groups(model: torch.nn.Module, encoder: torch.nn.Module | None, lr: float,
                 encoder_share: float) -> list[dict]:
    """Adam's parameter groups: ``model``'s ``encoder`` at ``encoder_share`` of ``lr`` (a pretrained
    encoder keeps more of what it learnt on real photographs), the rest at ``lr``."""
    if encoder is None or encoder_share == 1.0:
        return [{"params": list(model.parameters())}]
    own = {id(p) for p in encoder.parameters()}
    return [{"params": list(encoder.parameters()), "lr": lr * encoder_share},
            {"params": [p for p in model.parameters() if id(p) not in own]}]
