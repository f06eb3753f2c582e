"""Training batches that show a share of samples with a guessed camera: :class:`CameraMix`."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import torch

from bsn_edge.data.cache import SampleCache

GUESS_DRAW = 7919   # the stream of the own-or-guessed draw, apart from the augmentation's


class CameraMix:
    """Two sample caches of the same items, one warped with each clip's own camera and one with the
    camera a user without a camera file gets (:mod:`~bsn_edge.data.guessed_camera`); a batch takes
    each sample from the guessed one with probability ``share``. The choice is drawn from the
    sample's own draw, so a resumed run makes the same choices, and the augmentation of a sample is
    the same whichever cache it comes from."""

    def __init__(self, own: SampleCache, guessed: SampleCache, share: float) -> None:
        if own.items != guessed.items:
            raise ValueError("the own-camera and guessed-camera caches must hold the same samples in the same order")
        if not 0.0 <= share <= 1.0:
            raise ValueError(f"share is a share of samples in [0, 1], got {share}")
        self.own, self.guessed, self.share = own, guessed, share

    def __len__(self) -> int:
        return len(self.own)

    def guessed_picks(self, picks: Sequence[tuple[int, int]], seed: int) -> np.ndarray:
        """Which of ``picks`` come from the guessed cache."""
        return np.array([np.random.default_rng([seed, draw, GUESS_DRAW]).random() < self.share for _, draw in picks],
                        bool)

    def batch(self, picks: Sequence[tuple[int, int]], augment: bool, seed: int, object_repaint: float = 0.0,
              object_see_through: float = 0.0, camera_look: float = 0.0) -> dict[str, torch.Tensor]:
        """As :meth:`SampleCache.batch`, each sample from the cache its draw chose (the own camera's
        without ``augment``), and ``guessed`` ([N] bool) saying which came from the guessed one."""
        use = self.guessed_picks(picks, seed) if augment else np.zeros(len(picks), bool)
        args = (augment, seed, object_repaint, object_see_through, camera_look)
        if not use.any():
            out = self.own.batch(picks, *args)
        elif use.all():
            out = self.guessed.batch(picks, *args)
        else:
            a = self.own.batch([p for p, u in zip(picks, use, strict=True) if not u], *args)
            b = self.guessed.batch([p for p, u in zip(picks, use, strict=True) if u], *args)
            back = torch.from_numpy(np.argsort(np.concatenate([np.flatnonzero(~use), np.flatnonzero(use)]),
                                               kind="stable"))
            out = {k: torch.cat([a[k], b[k]])[back] for k in a}
        out["guessed"] = torch.from_numpy(use)
        return out
