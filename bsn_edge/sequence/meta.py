"""``meta.json`` of a sequence folder."""

from __future__ import annotations

import json
import os
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from bsn_edge.camera import Intrinsics
from bsn_edge.fields import read_json_object
from bsn_edge.sequence.images import atomic_write_bytes

META_NAME = "meta.json"
RENDERED = "synth"           # the source of clips bsn-synth rendered: their depth and classes are exact


@dataclass(frozen=True)
class SequenceMeta:
    """What a stage needs to know about a clip: rate, size, intrinsics, where it came from."""

    fps: float
    intrinsics: Intrinsics
    source: str
    frames: int
    seed: int | None = None
    extra: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if not self.fps > 0:
            raise ValueError(f"fps must be positive, got {self.fps}")
        if self.frames < 0:
            raise ValueError(f"frames must be >= 0, got {self.frames}")

    @property
    def rendered(self) -> bool:
        """Whether ``bsn-synth`` rendered the clip (exact depth, classes and poses)."""
        return self.source == RENDERED

    @property
    def width(self) -> int:
        return self.intrinsics.width

    @property
    def height(self) -> int:
        return self.intrinsics.height

    def to_json(self) -> str:
        """The file's text: the intrinsics written flat beside the rest, as the format has always been."""
        d = asdict(self)
        d.update(d.pop("intrinsics"))
        d.update(d.pop("extra"))
        return json.dumps(d, indent=2, sort_keys=True)

    def write(self, seq_dir: str | os.PathLike) -> None:
        atomic_write_bytes(Path(seq_dir) / META_NAME, (self.to_json() + "\n").encode())

    @classmethod
    def read(cls, seq_dir: str | os.PathLike) -> SequenceMeta:
        path = Path(seq_dir) / META_NAME
        if not path.is_file():
            raise FileNotFoundError(f"{seq_dir}: not a sequence folder (no {META_NAME}); bsn-synth makes one, and "
                                    "bsn-adapt imports your own videos as sequence folders")
        d = read_json_object(path)
        known = {"fps", "width", "height", "fx", "fy", "cx", "cy", "source", "frames", "seed"}
        missing = sorted(known - {"seed", "frames", "source"} - d.keys())
        if missing:
            raise ValueError(f"{path}: missing keys {missing}")
        if "frames" not in d:   # a user's own clip: count what the folder holds
            from bsn_edge.sequence.folder import SequenceFolder

            d["frames"] = SequenceFolder(seq_dir).count_frames()
        extra = {k: v for k, v in d.items() if k not in known}
        return cls(fps=float(d["fps"]), intrinsics=Intrinsics.from_dict(d, where=str(path)),
                   source=str(d.get("source", "user")), frames=int(d["frames"]), seed=d.get("seed"), extra=extra)
