"""A training run folder, owned by one object: :class:`Run`.

::

    RUN/config.json        the resolved training config
    RUN/model.pt           weights only (a state dict of tensors, loaded with ``weights_only=True``)
    RUN/checkpoint.json    {"card": the model card, "step", clips, validation metrics, ...}
    RUN/state.pt           what resuming needs, in one file: weights, optimizer, schedule, step
    RUN/teacher/teacher.pt the segmentation teacher
    RUN/teacher/state.pt   while the teacher trains: what resuming it needs, as ``state.pt``
    RUN/history.jsonl      one JSON record per line: losses and validation figures along the way

Nothing is unpickled beyond tensors and numbers. A save writes ``state.pt`` first (one atomic
file holding the weights with their sha256 and the optimizer state of the same step), then
``model.pt``, then ``checkpoint.json``: a kill between any two leaves a run that resumes from
``state.pt``; a ``model.pt`` whose sha256 matches neither ``checkpoint.json`` nor ``state.pt`` is
damaged and refused.
"""

from __future__ import annotations

import dataclasses
import hashlib
import io
import json
import pickle
from pathlib import Path
from typing import Any

import torch

from bsn_edge.card import ModelCard
from bsn_edge.fields import read_json_object
from bsn_edge.networks import BlindSpotNet, ModelSpec, build, create_teacher, weights_bytes
from bsn_edge.sequence.images import atomic_write, atomic_write_bytes, torn_writes
from bsn_edge.train.config import TeacherConfig
from bsn_edge.train.run_record import training_record


class RunError(ValueError):
    """A run folder that cannot be used as asked (damaged, unfinished, or in the way)."""


def to_bytes(obj: Any) -> bytes:
    """``obj`` as a torch file's bytes (weights only: tensors and numbers)."""
    buf = io.BytesIO()
    torch.save(obj, buf)
    return buf.getvalue()


def _from_bytes(data: bytes, what: Path) -> Any:
    try:
        return torch.load(io.BytesIO(data), map_location="cpu", weights_only=True)
    except (pickle.UnpicklingError, RuntimeError, EOFError, ValueError) as e:
        first = str(e).strip().splitlines()[0] if str(e).strip() else type(e).__name__
        raise RunError(f"{what}: not a weights-only torch file, or damaged ({first[:160]})") from None


def _write_state(path: Path, data: bytes, sha: str, resume_state: dict[str, Any]) -> None:
    """A training state in one file, written atomically: what resuming needs, the weights' bytes
    and their sha256.

    The bytes go in as a uint8 tensor, a record of the file's own: as a pickled byte string
    (torch pickles with protocol 2) they would be re-encoded, larger and several times slower to
    write and to read. The state streams to the file, never held whole in memory."""
    weights = torch.frombuffer(bytearray(data), dtype=torch.uint8)
    atomic_write(path, lambda f: torch.save({**resume_state, "weights": weights, "weights_sha256": sha}, f))


def _read_state(path: Path, what: str) -> dict[str, Any]:
    """A training state written by :func:`_write_state`, verified; its ``weights`` still as bytes
    (states written before the weights were a tensor hold a byte string: read the same)."""
    state = _from_bytes(path.read_bytes(), path)
    if not isinstance(state, dict) or not {"weights", "weights_sha256", "optimizer", "step"} <= set(state):
        raise RunError(f"{path}: not a {what} of this version")
    weights = state["weights"]
    if isinstance(weights, torch.Tensor) and weights.dtype == torch.uint8 and weights.dim() == 1:
        state["weights"] = weights.numpy().tobytes()
    elif not isinstance(weights, bytes):
        raise RunError(f"{path}: not a {what} of this version (its weights are neither bytes nor a byte tensor)")
    if hashlib.sha256(state["weights"]).hexdigest() != state["weights_sha256"]:
        raise RunError(f"{path}: damaged (its weights' sha256 differs); --force starts the run again")
    return state


class Run:
    """One run folder: where each file is, and the only code that reads or writes them."""

    MODEL, CHECKPOINT, STATE, CONFIG, TEACHER = "model.pt", "checkpoint.json", "state.pt", "config.json", "teacher"
    INIT_RECORD = "init_training"     # checkpoint key: the start's record as it was (``init_record``)
    HISTORY = "history.jsonl"

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)

    def __repr__(self) -> str:
        return f"Run({str(self.path)!r})"

    @property
    def model_path(self) -> Path:
        return self.path / self.MODEL

    @property
    def checkpoint_path(self) -> Path:
        return self.path / self.CHECKPOINT

    @property
    def state_path(self) -> Path:
        return self.path / self.STATE

    @property
    def config_path(self) -> Path:
        return self.path / self.CONFIG

    @property
    def teacher_path(self) -> Path:
        return self.path / self.TEACHER / "teacher.pt"

    @property
    def teacher_state_path(self) -> Path:
        """What resuming the teacher's training needs, while it is unfinished (gone once ``teacher.pt`` is)."""
        return self.path / self.TEACHER / self.STATE

    @property
    def history_path(self) -> Path:
        return self.path / self.HISTORY

    def exists(self) -> bool:
        """Whether anything of a run is already here."""
        return any(p.exists() for p in (self.model_path, self.checkpoint_path, self.state_path,
                                        self.teacher_state_path))

    def remove_torn_writes(self) -> list[Path]:
        """Remove the temporary files a killed save left beside the run's files (a ``state.pt``
        is hundreds of MB) and return them. For the run's one writer, before it writes."""
        files = (self.model_path, self.checkpoint_path, self.state_path, self.config_path, self.history_path,
                 self.teacher_path, self.teacher_state_path)
        torn = [t for f in files for t in torn_writes(f)]
        for t in torn:
            t.unlink(missing_ok=True)
        return torn

    def finished(self) -> bool:
        """Whether the run's training has ended: its last checkpoint carries the decision threshold,
        chosen once the last step is done; the checkpoints written on the way have none yet."""
        try:
            d = json.loads(self.checkpoint_path.read_text())
        except (OSError, json.JSONDecodeError):
            return False
        card = d.get("card", d) if isinstance(d, dict) else None
        return isinstance(card, dict) and card.get("threshold") is not None

    # -- reading ---------------------------------------------------------------------------------

    def info(self) -> dict[str, Any]:
        """``checkpoint.json`` with its card validated (``"card"`` is a :class:`ModelCard`)."""
        p = self.checkpoint_path
        if not p.is_file():
            raise FileNotFoundError(f"{self.path}: not a training run (no {self.CHECKPOINT})")
        d = read_json_object(p, error=RunError)
        if "card" in d:
            d["card"] = ModelCard.from_dict(d["card"], str(p))
        else:
            d = {"card": ModelCard.from_legacy(d, str(p)), **{k: v for k, v in d.items() if k != "card"}}
        if d["card"].training is None and (record := training_record(self, d)) is not None:
            d["card"] = d["card"].replace(training=record)
        return d

    @classmethod
    def init_record(cls, init: str | Path) -> dict[str, Any] | None:
        """What a run starting from ``init`` (``train.init``) starts from: its variant and training
        record, or None (no start, or a start with no record). A run keeps this with its checkpoint
        (``INIT_RECORD``) from its first save: the folder ``init`` names may later hold another run
        (``models/default`` does after every release)."""
        if not init or not (Path(init) / cls.CHECKPOINT).is_file():
            return None
        card = Run(init).card()
        if card.training is None:
            return None
        return {"variant": card.variant, "training": card.training.to_dict()}

    def card(self) -> ModelCard:
        return self.info()["card"]

    def config(self) -> dict[str, Any]:
        """The resolved config the run was trained with ({} if the run has none)."""
        if not self.config_path.is_file():
            return {}
        return read_json_object(self.config_path, error=RunError)

    def load_model(self) -> tuple[BlindSpotNet, ModelCard]:
        """The trained model (eval mode) and its card. Refuses weights whose sha256 is not the
        card's, or whose tensors do not fit the recorded architecture."""
        card = self.card()
        if not self.model_path.is_file():
            raise FileNotFoundError(f"{self.path}: no {self.MODEL}")
        data = self.model_path.read_bytes()
        if hashlib.sha256(data).hexdigest() != card.weights_sha256:
            raise RunError(f"{self.model_path}: weights do not match {self.CHECKPOINT} (sha256 differs): the file "
                           "is damaged or was replaced")
        return self._build(card, _from_bytes(data, self.model_path)).eval(), card

    def _build(self, card: ModelCard, state: dict[str, torch.Tensor]) -> BlindSpotNet:
        try:
            model = build(ModelSpec(**card.spec))
        except TypeError as e:
            raise RunError(f"{self.checkpoint_path}: the card's spec does not describe a model ({e})") from None
        try:
            model.load_state_dict(state)
        except RuntimeError as e:
            raise RunError(f"{self.path}: weights do not fit model {card.variant!r}: {str(e)[:300]}") from None
        return model

    def load_state(self) -> dict[str, Any] | None:
        """What resuming needs (``weights``, ``optimizer``, ``scheduler``, ``step``), verified; None if
        the run has no state. A ``model.pt`` that matches neither the checkpoint nor the state is refused."""
        if not self.state_path.is_file():
            return None
        state = _read_state(self.state_path, "training state")
        if self.model_path.is_file():
            have = hashlib.sha256(self.model_path.read_bytes()).hexdigest()
            known = {state["weights_sha256"]}
            if self.checkpoint_path.is_file():
                known.add(self.card().weights_sha256)
            if have not in known:
                raise RunError(f"{self.model_path}: weights match neither {self.CHECKPOINT} nor {self.STATE} "
                               "(sha256 differs): the file is damaged; --force starts the run again")
        state["weights"] = _from_bytes(state["weights"], self.state_path)
        return state

    def history(self) -> list[dict[str, Any]]:
        """The run's records in the order written (a torn last line, from a kill, is left out)."""
        if not self.history_path.is_file():
            return []
        out = []
        for line in self.history_path.read_text().splitlines():
            try:
                rec = json.loads(line)
            except json.JSONDecodeError:
                continue
            if isinstance(rec, dict):
                out.append(rec)
        return out

    @classmethod
    def of_teacher(cls, checkpoint: str | Path) -> Run:
        """The run a ``teacher.checkpoint`` setting names: a run folder or its ``teacher/`` folder."""
        src = Path(checkpoint)
        return cls(src.parent) if src.name == cls.TEACHER else cls(src)

    def teacher_holder(self) -> Run | None:
        """The run whose ``teacher/teacher.pt`` is this run's teacher: itself, else the run its
        config's ``teacher.checkpoint`` names (a run that trained with a teacher from elsewhere);
        None when neither holds one."""
        if self.teacher_path.is_file():
            return self
        named = self.config().get("teacher", {}).get("checkpoint", "")
        src = Run.of_teacher(named) if named else None
        if src is None or src.path.resolve() == self.path.resolve() or not src.teacher_path.is_file():
            return None
        return src

    def load_teacher_state(self) -> dict[str, torch.Tensor] | None:
        """The teacher's weights (from :meth:`teacher_holder`); None if it has none. Checked against
        the sha256 the holding run's ``checkpoint.json`` records for it, where it records one
        (shipped runs do)."""
        holder = self.teacher_holder()
        return None if holder is None else holder._own_teacher_state()

    def _own_teacher_state(self) -> dict[str, torch.Tensor]:
        """This run's own ``teacher/teacher.pt``, checked against its ``checkpoint.json``."""
        data = self.teacher_path.read_bytes()
        if self.checkpoint_path.is_file():
            want = self.info().get("teacher_sha256")
            if want and hashlib.sha256(data).hexdigest() != want:
                raise RunError(f"{self.teacher_path}: the teacher does not match {self.CHECKPOINT} (sha256 "
                               "differs): the file is damaged or was replaced")
        return _from_bytes(data, self.teacher_path)

    def teacher_config(self) -> TeacherConfig:
        """How the run's teacher is built and fed: its config's ``teacher`` section, with the
        defaults for what a run written before a setting existed does not record."""
        known = {f.name for f in dataclasses.fields(TeacherConfig)}
        return TeacherConfig(**{k: v for k, v in self.config().get("teacher", {}).items() if k in known})

    def load_teacher(self) -> torch.nn.Module | None:
        """The run's segmentation teacher in eval mode, built as the config of the run that holds it
        says (None without one)."""
        holder = self.teacher_holder()
        if holder is None:
            return None
        state = holder._own_teacher_state()
        t = holder.teacher_config()
        teacher = create_teacher(t.encoder, t.width)
        teacher.load_state_dict(state)
        return teacher.eval()

    # -- writing ---------------------------------------------------------------------------------

    def write_config(self, config: dict[str, Any]) -> None:
        self.path.mkdir(parents=True, exist_ok=True)
        atomic_write_bytes(self.config_path, (json.dumps(config, indent=2) + "\n").encode())

    def append_history(self, record: dict[str, Any]) -> None:
        """Add one record (flushed at once: a kill loses no record written before it)."""
        self.path.mkdir(parents=True, exist_ok=True)
        with open(self.history_path, "a") as f:
            f.write(json.dumps(record) + "\n")

    def trim_history(self, phase: str, step: int) -> None:
        """Drop ``phase`` records after ``step`` (written after the checkpoint a resume starts from)."""
        kept = [r for r in self.history() if not (r.get("phase") == phase and r.get("step", 0) > step)]
        atomic_write_bytes(self.history_path, "".join(json.dumps(r) + "\n" for r in kept).encode())

    def save_teacher(self, state: dict[str, torch.Tensor]) -> None:
        """The finished teacher's weights; its training state goes (nothing is left to resume)."""
        self.teacher_path.parent.mkdir(parents=True, exist_ok=True)
        atomic_write_bytes(self.teacher_path, to_bytes(state))
        self.teacher_state_path.unlink(missing_ok=True)

    def save_teacher_progress(self, weights: dict[str, torch.Tensor], resume_state: dict[str, Any]) -> None:
        """The unfinished teacher's weights and what resuming it needs (optimizer, scheduler, step...), in
        one atomic file with the weights' sha256."""
        self.teacher_state_path.parent.mkdir(parents=True, exist_ok=True)
        data = to_bytes({k: v.detach().cpu().contiguous() for k, v in weights.items()})
        _write_state(self.teacher_state_path, data, hashlib.sha256(data).hexdigest(), resume_state)

    def load_teacher_progress(self) -> dict[str, Any] | None:
        """The unfinished teacher's state (``weights``, ``optimizer``, ``step``...), verified; None if none."""
        p = self.teacher_state_path
        if not p.is_file():
            return None
        state = _read_state(p, "teacher training state")
        state["weights"] = _from_bytes(state["weights"], p)
        return state

    def save(self, model: torch.nn.Module, card_fields: dict[str, Any], info: dict[str, Any],
             resume_state: dict[str, Any] | None = None) -> ModelCard:
        """Write a checkpoint: ``state.pt`` (when ``resume_state`` is given: optimizer, scheduler,
        step...), ``model.pt`` and ``checkpoint.json``, in that order. The card is made here from
        ``card_fields`` and the weights' sha256; returns it."""
        self.path.mkdir(parents=True, exist_ok=True)
        data = weights_bytes(model)
        sha = hashlib.sha256(data).hexdigest()
        card = ModelCard(**card_fields, weights_sha256=sha)
        if resume_state is not None:
            _write_state(self.state_path, data, sha, resume_state)
        atomic_write_bytes(self.model_path, data)
        record = {"card": card.to_dict(), **{k: v for k, v in info.items() if k != "card"}}
        atomic_write_bytes(self.checkpoint_path, (json.dumps(record, indent=2) + "\n").encode())
        return card
