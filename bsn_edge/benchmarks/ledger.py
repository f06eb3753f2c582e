"""The finished runs of a seeded benchmark, kept with its results: :class:`Ledger`.

A table trained with several seeds takes more CPU-hours than one sitting has. Each trained run's
figures are written to ``<results>/<name>_ledger.json`` the moment it is evaluated, so the next
sitting, on this machine or another (the ledger is committed with the results; the run folders
are not), trains only what is missing. The ledger names the experiment it belongs to (budget,
data, sizes): a run of the benchmark with another experiment refuses to mix into it.

On disk::

    {"experiment": {...}, "runs": {"BSN/town/seed0": {...}, ...}}
"""

from __future__ import annotations

import json
import statistics
from collections.abc import Iterable
from pathlib import Path
from typing import Any

from bsn_edge.sequence import atomic_write_bytes


class Ledger:
    """Runs of one experiment by key; :meth:`put` writes the file at once (atomically)."""

    def __init__(self, path: str | Path, experiment: dict[str, Any], fresh: bool = False) -> None:
        self.path = Path(path)
        self.experiment = json.loads(json.dumps(experiment))        # as it reads back from disk
        self.runs: dict[str, dict[str, Any]] = {}
        if self.path.is_file() and not fresh:
            stored, runs = self._load(self.path)
            if stored != self.experiment:
                diff = sorted(k for k in set(stored) | set(self.experiment) if stored.get(k) != self.experiment.get(k))
                raise ValueError(f"{self.path} holds another experiment (differs in {', '.join(diff)}): "
                                 "run with the same settings to continue it, or start over with --fresh")
            self.runs = dict(runs)

    @classmethod
    def read(cls, path: str | Path) -> Ledger:
        """The ledger at ``path`` as it is, whatever its experiment (for reading; :meth:`put` works too)."""
        path = Path(path)
        if not path.is_file():
            raise FileNotFoundError(f"no ledger at {path}")
        experiment, runs = cls._load(path)
        ledger = cls(path, experiment, fresh=True)
        ledger.runs = dict(runs)
        return ledger

    @staticmethod
    def _load(path: Path) -> tuple[dict[str, Any], dict[str, Any]]:
        try:
            data = json.loads(path.read_text())
            return data["experiment"], data["runs"]
        except (ValueError, KeyError, TypeError) as e:
            raise ValueError(f"{path}: not a ledger ({e}); move it away or start over with --fresh") from e

    def __contains__(self, key: str) -> bool:
        return key in self.runs

    def get(self, key: str) -> dict[str, Any] | None:
        """The record of run ``key``, None if it has not been run."""
        return self.runs.get(key)

    def put(self, key: str, record: dict[str, Any]) -> None:
        """Record run ``key`` and write the ledger."""
        self.runs[key] = record
        self.path.parent.mkdir(parents=True, exist_ok=True)
        text = json.dumps({"experiment": self.experiment, "runs": self.runs}, indent=1) + "\n"
        atomic_write_bytes(self.path, text.encode())


def mean_std(values: Iterable[float]) -> tuple[float, float, int]:
    """Mean, sample standard deviation (0 for one value) and count of ``values``."""
    v = list(values)
    if not v:
        raise ValueError("mean_std of no values")
    return statistics.fmean(v), (statistics.stdev(v) if len(v) > 1 else 0.0), len(v)


def exceeds_spread(a: Iterable[float], b: Iterable[float]) -> bool | None:
    """Whether the means of ``a`` and ``b`` differ by more than the two standard deviations added:
    a difference the seeds' own spread does not explain. None with fewer than two values on a side."""
    a, b = list(a), list(b)
    if len(a) < 2 or len(b) < 2:
        return None
    (ma, sa, _), (mb, sb, _) = mean_std(a), mean_std(b)
    return abs(ma - mb) > sa + sb


def fmt(values: Iterable[float]) -> str:
    """``mean +- std`` to three places (``mean (1 seed)`` for one value); ``-`` for none."""
    v = list(values)
    if not v:
        return "-"
    m, s, n = mean_std(v)
    return f"{m:.3f} +- {s:.3f}" if n > 1 else f"{m:.3f} (1 seed)"
