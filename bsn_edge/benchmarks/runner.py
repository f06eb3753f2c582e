"""The one way a benchmark runs: its options parsed, what it measured returned as a :class:`Report`, and the
report written beside the machine it ran on (``<name>.json`` and ``<name>.md`` in ``--out``)."""

from __future__ import annotations

import argparse
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from .common import write_result


@dataclass(frozen=True)
class Report:
    """What one benchmark measured: the figures (``result``, the JSON), the report's lines (Markdown),
    what the terminal is shown (default: the report's path) and, for a benchmark whose reports are named
    after what they measured, the report's name (default: ``--name``)."""

    result: dict[str, Any]
    markdown: list[str]
    printed: list[str] = field(default_factory=list)
    name: str = ""
    status: int = 0          # the exit status: 1 for a benchmark whose bar failing fails its run


class RefusedError(Exception):
    """A sitting the benchmark will not run as asked (its message says why and what to do); exit status 2."""


Measure = Callable[[argparse.Namespace, argparse.ArgumentParser], "Report | None"]


def run(measure: Measure, parser: argparse.ArgumentParser, argv: list[str] | None = None) -> int:
    """Parse ``argv`` with ``parser`` (which has ``--out`` and ``--name``), measure, write the report.
    ``measure`` returns None when there is nothing to measure here (its data is absent: it says so), and
    raises :class:`RefusedError` for a sitting it will not run (status 2)."""
    args = parser.parse_args(argv)
    try:
        report = measure(args, parser)
    except RefusedError as e:
        print(f"{parser.prog}: {e}")
        return 2
    if report is None:
        return 0
    path = write_result(args.out, report.name or args.name, report.result, "\n".join(report.markdown))
    print("\n".join(report.printed) if report.printed else f"wrote {path}")
    return report.status
