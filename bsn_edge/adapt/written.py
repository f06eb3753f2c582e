"""What ``bsn-adapt`` leaves: the adapted run written beside its source's config and teacher, and its int8 export
(the shipped model itself when adaptation kept the shipped default's weights)."""

from __future__ import annotations

import dataclasses
import json
import shutil
from pathlib import Path
from typing import Any

from bsn_edge.data.dataset import Clip
from bsn_edge.train.run import Run


def export_adapted(out: str | Path, path: Path, labelled: list[Clip], kept: str | None) -> dict[str, Any]:
    """The adapted run exported int8 to ``path``; when adaptation kept the source (``kept``: its weights'
    sha256) and the source is the shipped default's run, the shipped model itself, its threshold and card:
    never a model worse than the one the user started from."""
    from bsn_edge.default_model import DEFAULT_CARD, DEFAULT_MODEL

    shipped = json.loads(DEFAULT_CARD.read_text()).get("card", {}) if DEFAULT_CARD.is_file() else {}
    if kept is not None and kept == shipped.get("weights_sha256"):
        path.parent.mkdir(parents=True, exist_ok=True)
        shutil.copy2(DEFAULT_MODEL, path)
        shutil.copy2(DEFAULT_CARD, path.with_suffix(".json"))
        return {"path": str(path), "shipped": True,
                "note": f"the shipped model as it is (threshold {shipped.get('threshold')}, signed with the project's "
                        "key): adaptation kept the source"}
    from bsn_edge.export.pipeline import export_run

    summary = export_run(out, path, int8=True, calib=max(labelled, key=lambda c: len(c.frames)).path)
    return {"path": str(path), "shipped": False, "int8_vs_fp32": summary["int8_vs_fp32"]}


def write_adapted(src: Run, out: Path, model, card, threshold: float, best: dict[str, Any], label: str,
                   train: list[Clip], held: list[Clip]) -> str:
    """The adapted run written to ``out`` (its card, the source's config and teacher); its weights' sha256."""
    dst = Run(out)
    fields = {f.name: getattr(card, f.name) for f in dataclasses.fields(card) if f.name != "weights_sha256"}
    fields.update(threshold=threshold, graph_sha256="", self_test=None)
    if card.training is not None:      # the card names what it was adapted on, as every export of it will
        on = ", ".join(f"{c.path.name} ({len(c.frames)} label frames)" for c in train)
        fields["training"] = dataclasses.replace(card.training, adapted_on=f"bsn-adapt of {src.path.name} on {on}; "
                                                 f"threshold chosen on {', '.join(c.path.name for c in held)}")
    new_card = dst.save(model, fields, {"adapted_from": str(src.path), "label": label,
                                        "train_clips": sorted({c.path.name for c in train}),
                                        "val_clips": sorted({c.path.name for c in held}), "val": best})
    dst.write_config(src.config())
    dst.teacher_path.parent.mkdir(exist_ok=True)
    shutil.copy2(src.teacher_path, dst.teacher_path)     # a later adaptation of this run labels with it
    return new_card.weights_sha256
