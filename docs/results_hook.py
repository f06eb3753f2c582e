"""mkdocs hook: the benchmark reports (``benchmarks/results``) served as the site's ``results/`` pages.

The reports are written where the benchmarks write them; the docs link to them as ``results/NAME.md``. This
hook adds them to the build from where they are, so no copy or link of them lives under ``docs/``.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from mkdocs.structure.files import File, Files

BENCHMARKS = Path(__file__).resolve().parents[1] / "benchmarks"


def on_files(files: Files, config: Any) -> Files:
    """Every file of ``benchmarks/results`` as ``results/...`` of the site."""
    for path in sorted((BENCHMARKS / "results").rglob("*")):
        if path.is_file():
            files.append(File(path.relative_to(BENCHMARKS).as_posix(), str(BENCHMARKS), config["site_dir"],
                              config["use_directory_urls"]))
    return files
