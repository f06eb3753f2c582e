"""Interfaces of the label generator's sources."""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from bsn_edge.sequence import SequenceMeta


class ClipRejectedError(Exception):
    """The clip cannot give trustworthy labels (e.g. depth does not fit the landmarks)."""


@dataclass(frozen=True)
class ClipData:
    """What every source may look at: the folder, its meta and its frame count."""

    seq: Path
    meta: SequenceMeta
    frames: int
    info: dict[str, Any] = field(default_factory=dict)


class DepthSource(ABC):
    """Metric depth of frame ``i`` (float32 metres, 0 = unknown)."""

    name: str = "depth"

    @abstractmethod
    def __call__(self, i: int) -> np.ndarray: ...

    def describe(self) -> dict[str, Any]:
        return {"kind": self.name}


class SegSource(ABC):
    """Cityscapes trainIds of frame ``i`` (uint8)."""

    name: str = "segmentation"

    @abstractmethod
    def __call__(self, i: int) -> np.ndarray: ...

    def describe(self) -> dict[str, Any]:
        return {"kind": self.name}
