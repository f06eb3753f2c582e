"""One policy for every file a command writes, checked before any work.

- an existing file is not replaced without ``--force`` (a pipe or a device is written to as asked);
- a suffix the writer does not know is refused, naming those it knows;
- a missing folder is created (for every output alike), and a folder that cannot be created or
  written is refused: all before the first frame, so a long run never ends with nothing written.
"""

from __future__ import annotations

import os
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path


@dataclass(frozen=True)
class OutputKind:
    """What an output flag writes: its name on the command line and the suffixes its writer knows
    (lower case; empty: any)."""

    flag: str
    suffixes: tuple[str, ...] = ()
    what: str = ""


class OutputsRefusedError(ValueError):
    """Outputs a command cannot write, every one named (``problems``), found before anything is written."""

    def __init__(self, problems: list[str]) -> None:
        self.problems = tuple(problems)
        exists = [m for m in problems if m.endswith(EXISTS)]
        rest = [m for m in problems if not m.endswith(EXISTS)]
        said = [f"{', '.join(m[: -len(EXISTS)] for m in exists)} "
                f"{'exists' if len(exists) == 1 else 'exist'}; pass --force to replace "
                f"{'it' if len(exists) == 1 else 'them'}"] if exists else []
        super().__init__("; ".join(rest + said))


EXISTS = " exists"


def judge_output(kind: OutputKind, path: str | os.PathLike, force: bool) -> str | None:
    """What is wrong with writing ``path`` as ``kind`` (None: nothing), judged without touching the disk."""
    p = Path(path)
    name = f"{kind.flag} {p}"
    if p.exists() and not p.is_file() and not p.is_dir():
        return None                       # a pipe or a device (/dev/null, /dev/full): written to as asked
    if kind.suffixes and p.suffix.lower() not in kind.suffixes:
        known = ", ".join(kind.suffixes)
        return f"{name}: {kind.what + ' ' if kind.what else ''}files end in {known}, not {p.suffix or 'nothing'}"
    if p.is_dir():
        return f"{name}: is a folder; give a file name"
    if p.is_file() and not force:
        return name + EXISTS
    return None


def prepare_output(kind: OutputKind, path: str | os.PathLike) -> Path:
    """``path``'s folder made and probed for writing (after :func:`judge_output` found nothing wrong);
    ``ValueError`` naming the flag."""
    p = Path(path)
    if p.exists() and not p.is_file() and not p.is_dir():
        return p
    name = f"{kind.flag} {p}"
    try:
        p.parent.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise ValueError(f"{name}: its folder cannot be made ({e.strerror or e})") from e
    probe = p.parent / f".{p.name}.{os.getpid()}.probe"      # what the disk says, read-only or full
    try:
        with probe.open("xb") as f:      # a byte, not only a name: a full disk still makes empty files
            f.write(b"\0")
        probe.unlink()
    except OSError as e:
        raise ValueError(f"{name}: cannot be written here ({e.strerror or e})") from e
    return p


def check_output(kind: OutputKind, path: str | os.PathLike, force: bool) -> Path:
    """``path`` checked and its folder made; :class:`OutputsRefusedError` (a ``ValueError``) naming the flag."""
    if (problem := judge_output(kind, path, force)) is not None:
        raise OutputsRefusedError([problem])
    return prepare_output(kind, path)


def check_outputs(outputs: Iterable[tuple[OutputKind, str | os.PathLike | None]], force: bool) -> None:
    """Every given output of a command checked (those not asked for are None), all of them before any
    folder is made: one :class:`OutputsRefusedError` names every output that cannot be written, so a refused
    command writes nothing and the next try is not refused for another. Two outputs naming one file
    (through a link too) are refused, as one would overwrite the other."""
    given = [(kind, path) for kind, path in outputs if path]
    check_distinct(given)
    problems = [m for kind, path in given if (m := judge_output(kind, path, force)) is not None]
    if problems:
        raise OutputsRefusedError(problems)
    for kind, path in given:
        prepare_output(kind, path)


def check_distinct(outputs: Iterable[tuple[OutputKind, str | os.PathLike | None]]) -> None:
    """``ValueError`` when two outputs name one file, through a link too (pipes and devices, which many
    may write into, excepted)."""
    seen: dict[str, OutputKind] = {}
    for kind, path in outputs:
        if not path:
            continue
        p = Path(path)
        if p.exists() and not p.is_file() and not p.is_dir():
            continue
        real = os.path.realpath(p)
        if real in seen:
            raise ValueError(f"{seen[real].flag} and {kind.flag} both name {path}: one would overwrite the other")
        seen[real] = kind


def _identity(path: Path) -> tuple[str, tuple[int, int] | None]:
    """A path's real location and, when it exists, its device and inode (a hard link has another name)."""
    try:
        st = path.stat()
        ino: tuple[int, int] | None = (st.st_dev, st.st_ino)
    except OSError:
        ino = None
    return os.path.realpath(path), ino


def check_not_inputs(outputs: Iterable[tuple[str, str | os.PathLike | None]],
                     inputs: Iterable[tuple[str, str | os.PathLike | None]]) -> None:
    """``ValueError`` when an output names one of the run's inputs (the same file by its real path or its
    inode), or a folder output lies in an input folder (maps saved among a folder's frames would be read as
    frames by the next run). ``--force`` changes nothing of it: an output never replaces what the run reads."""
    ins = [(flag, Path(p), *_identity(Path(p))) for flag, p in inputs if p and Path(p).exists()]
    for flag, out in outputs:
        if not out:
            continue
        o = Path(out)
        real, ino = _identity(o)
        for in_flag, src, in_real, in_ino in ins:
            if real == in_real or (ino is not None and ino == in_ino):
                raise ValueError(f"{flag} {out} is the run's {in_flag} ({src}): an output never replaces what "
                                 "the run reads, --force or not")
            if src.is_dir() and (real + os.sep).startswith(in_real + os.sep):
                raise ValueError(f"{flag} {out} lies in the run's {in_flag} folder ({src}): the next run would "
                                 "read what it writes as input; give it a folder of its own")
