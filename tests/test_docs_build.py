"""CI's docs build fails on a broken link: the build line of ``.ci/run``, run on a two-page site with the
project's own link validation (``mkdocs.yml``), once with a planted dead link and once without."""

import re
import shlex
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

ROOT = Path(__file__).resolve().parents[1]


def _ci_build_flags() -> list[str]:
    line = next(ln for ln in (ROOT / ".ci" / "run").read_text().splitlines() if re.match(r"\S*mkdocs build", ln))
    words = shlex.split(line, comments=True)
    flags = words[words.index("build") + 1:]
    i = flags.index("--site-dir")
    return flags[:i] + flags[i + 2:]


def _build(tmp_path: Path, link: str) -> subprocess.CompletedProcess:
    pytest.importorskip("mkdocs")
    project = yaml.safe_load((ROOT / "mkdocs.yml").read_text())
    cfg = {"site_name": "t", "docs_dir": "docs", "validation": project["validation"],
           "nav": [{"Home": "index.md"}, {"Other": "other.md"}]}
    (tmp_path / "docs").mkdir(parents=True)
    (tmp_path / "docs" / "index.md").write_text(f"# Home\n\nSee [the other page]({link}).\n")
    (tmp_path / "docs" / "other.md").write_text("# Other\n")
    (tmp_path / "mkdocs.yml").write_text(yaml.safe_dump(cfg))
    cmd = [sys.executable, "-m", "mkdocs", "build", *_ci_build_flags(), "--site-dir", str(tmp_path / "site")]
    return subprocess.run(cmd, cwd=tmp_path, capture_output=True, text=True, timeout=120)


def test_ci_builds_the_docs_strictly_and_without_hiding_warnings():
    flags = _ci_build_flags()
    assert "--strict" in flags and "--quiet" not in flags and "-q" not in flags


def test_a_broken_link_fails_the_docs_build_and_a_good_one_passes(tmp_path: Path):
    bad = _build(tmp_path / "bad", "missing.md")
    assert bad.returncode != 0, bad.stderr
    assert "missing.md" in bad.stderr
    good = _build(tmp_path / "good", "other.md")
    assert good.returncode == 0, good.stderr
