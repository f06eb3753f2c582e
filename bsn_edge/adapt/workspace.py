"""The adaptation's own files inside the new run folder, owned by one object.

::

    OUT/                       the adapted run (``Run``: model.pt, checkpoint.json, config.json, teacher/)
    OUT/adapt/config.json      the resolved AdaptConfig, the inputs and the run adapted from
    OUT/adapt/report.json      what each stage did
    OUT/adapt/labeller/        the source run's depth model and teacher as ONNX (label sources)
    OUT/adapt/clips/<name>/    the user's clips as sequence folders (frames, meta, camera file, labels)
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from bsn_edge.sequence.images import atomic_write_bytes


class AdaptFolder:
    """Where each file of an adaptation lives (under ``RUN2/adapt``)."""

    DIR, CONFIG, REPORT, LABELLER, CLIPS = "adapt", "config.json", "report.json", "labeller", "clips"
    DEPTH_MODEL, TEACHER_MODEL = "model.onnx", "teacher.onnx"

    def __init__(self, run_dir: str | Path) -> None:
        self.run_dir = Path(run_dir)
        self.root = self.run_dir / self.DIR

    @property
    def config_path(self) -> Path:
        return self.root / self.CONFIG

    @property
    def report_path(self) -> Path:
        return self.root / self.REPORT

    @property
    def depth_model(self) -> Path:
        return self.root / self.LABELLER / self.DEPTH_MODEL

    @property
    def teacher_model(self) -> Path:
        return self.root / self.LABELLER / self.TEACHER_MODEL

    @property
    def clips_dir(self) -> Path:
        return self.root / self.CLIPS

    def clip(self, name: str) -> Path:
        return self.clips_dir / name

    def exists(self) -> bool:
        return self.config_path.is_file()

    def read_config(self) -> dict[str, Any]:
        return json.loads(self.config_path.read_text())

    def write_json(self, path: Path, record: dict[str, Any]) -> None:
        path.parent.mkdir(parents=True, exist_ok=True)
        atomic_write_bytes(path, (json.dumps(record, indent=1, default=str) + "\n").encode())
