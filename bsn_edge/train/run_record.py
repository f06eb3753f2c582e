"""How a run was trained, as its card records it (:class:`~bsn_edge.card.TrainingRecord`): counted from its
checkpoint, its history and its config, and from the run it started from."""

from __future__ import annotations

from collections.abc import Iterable
from pathlib import Path
from typing import TYPE_CHECKING, Any

from bsn_edge.card import UNRECORDED, TrainingRecord
from bsn_edge.networks import Carried, carried_over
from bsn_edge.train.config import TeacherConfig

if TYPE_CHECKING:
    from bsn_edge.train.run import Run


def last_parts(path: str) -> str:
    """A folder's last two parts ("models/campaign"): no one's directory layout in what is handed out."""
    return "/".join(Path(path).parts[-2:]) if path else ""


def trained_precision(records: Iterable[dict[str, Any]]) -> set[str]:
    """The arithmetic a run's history records name, step 0 left out (the start's own score, not a
    piece of the run's training); ``UNRECORDED`` for records written before the trainer named it."""
    return {r.get("precision", UNRECORDED) for r in records if r.get("step")}


def training_record(run: Run, info: dict[str, Any]) -> TrainingRecord | None:
    """How the run was trained: samples and seconds summed over every piece, as the trainer
    recorded them with the checkpoint (runs from before that: the history's last training record,
    scaled to the run's last step); the clips from the checkpoint; the start and the teacher from
    the config; the arithmetic of every piece as the trainer recorded it (runs from before that:
    as the history's training records name it). Counted from scratch: a run that started from
    another run's weights (``train.init``) adds that run's record, and ``init`` names it with its
    own count. None for a run with neither."""
    steps = int(info.get("step") or 0)
    trained = info.get("trained")
    # step 0 is the start's own score, not a piece of this run's training
    recs = [r for r in run.history() if r.get("phase") == "train" and r.get("step")]
    kinds = set((trained or {}).get("precision", [])) or trained_precision(recs)
    if trained is None:
        if not recs or not steps:
            return None
        scale = steps / recs[-1]["step"]
        trained = {"samples": recs[-1]["samples"] * scale, "seconds": recs[-1].get("seconds", 0.0) * scale}
    cfg = run.config()
    teacher = last_parts(cfg.get("teacher", {}).get("checkpoint", ""))
    if not teacher and run.teacher_path.is_file():
        teacher = f"trained in the run, {cfg.get('teacher', {}).get('steps', '?')} steps"
        if t_init := cfg.get("teacher", {}).get("init", ""):
            teacher += f" on from {last_parts(t_init)}"
    built = run.teacher_config()
    if teacher and built.encoder != TeacherConfig().encoder:
        teacher += f" ({built.encoder}{' from ImageNet' if built.pretrained else ''})"
    samples, hours = float(trained["samples"]), trained["seconds"] / 3600
    init = str(cfg.get("train", {}).get("init", ""))
    start = last_parts(init)
    # the start as it was when this run began (runs from before that record: as it is now)
    frozen = info.get(run.INIT_RECORD) or run.init_record(init)
    if frozen is not None:
        before = TrainingRecord.from_dict(frozen["training"])
        steps, samples, hours = steps + before.steps, samples + before.samples, hours + before.hours
        kinds |= set(before.precision) or {UNRECORDED}
        d_only = carried_over(cfg.get("model", {}).get("name", frozen["variant"]), frozen["variant"]) is Carried.D
        start += f" ({'its D, ' if d_only else ''}after {before.steps} steps)"
    counted = [r for r in recs if "alive_share" in r]
    alive = "" if not counted else (f"{100 * counted[-1]['alive_share']:.1f} % of "
                                    f"{counted[-1]['channels']:,} convolution channels alive at step "
                                    f"{counted[-1]['step']}")
    return TrainingRecord(steps=steps, samples=round(samples), hours=round(hours, 2),
                          train_clips=len(info.get("train_clips", [])), val_clips=len(info.get("val_clips", [])),
                          init=start, teacher=teacher,
                          precision=() if kinds <= {UNRECORDED} else tuple(sorted(kinds)), alive=alive)
