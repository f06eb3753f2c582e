"""``bsn-bench`` runs the benchmarks of a source tree against the installed package, wherever it is run from,
and every benchmark of the tree is reachable from it or named as one of the campaign's own."""

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

from bsn_edge.cli import bench

ROOT = Path(__file__).resolve().parents[2]


def _tree(root: Path) -> Path:
    """A source tree whose 'alive' benchmark writes where its package came from, and whose report writer
    writes REPORT.md."""
    b = root / "benchmarks"
    b.mkdir(parents=True)
    (b / "__init__.py").write_text("")
    (b / "bench_alive.py").write_text(
        "import argparse, pathlib, bsn_edge\n"
        "a = argparse.ArgumentParser(); a.add_argument('--out'); o = a.parse_args().out\n"
        "pathlib.Path(o).mkdir(parents=True, exist_ok=True)\n"
        "(pathlib.Path(o) / 'alive.md').write_text(bsn_edge.__file__)\n")
    for mark in ("configs/quick.toml", "models/README.md"):
        (root / mark).parent.mkdir(parents=True, exist_ok=True)
        (root / mark).write_text("")
    (b / "report.py").write_text(
        "import argparse, pathlib\n"
        "a = argparse.ArgumentParser(); a.add_argument('--results'); r = a.parse_args().results\n"
        "(pathlib.Path(r) / 'REPORT.md').write_text('report')\n")
    return root


def test_an_installed_bsn_bench_runs_the_benchmarks_of_the_tree_it_is_given(tmp_path):
    tree, elsewhere = _tree(tmp_path / "tree"), tmp_path / "elsewhere"
    elsewhere.mkdir()
    out = tmp_path / "out"
    env = {**os.environ, "PYTHONPATH": ""}
    r = subprocess.run([sys.executable, "-m", "bsn_edge.cli.bench", "--checkout", str(tree), "--only", "alive",
                        "--out", str(out)], cwd=elsewhere, capture_output=True, text=True, env=env, timeout=120)
    assert r.returncode == 0, r.stderr
    assert (out / "REPORT.md").read_text() == "report"
    assert (out / "alive.md").read_text().startswith(str(Path(bench.__file__).parents[1])), \
        "the benchmark ran against the package bsn-bench belongs to"


def test_the_tree_comes_from_the_flag_then_the_environment_then_beside_the_package_then_here(tmp_path, monkeypatch):
    tree = _tree(tmp_path / "tree")
    monkeypatch.delenv(bench.CHECKOUT_ENV, raising=False)
    assert bench.find_checkout(str(tree)) == tree.resolve()
    monkeypatch.setenv(bench.CHECKOUT_ENV, str(tree))
    assert bench.find_checkout(None) == tree.resolve()
    monkeypatch.delenv(bench.CHECKOUT_ENV)
    monkeypatch.setattr(bench, "CHECKOUT", tmp_path / "site-packages")      # as installed from a wheel
    assert bench.find_checkout(None, cwd=tree) == tree.resolve()
    assert bench.find_checkout(None, cwd=tmp_path) is None
    with pytest.raises(FileNotFoundError, match="not a bsn-edge checkout"):
        bench.find_checkout(str(tmp_path))


def _as_installed(tmp_path, monkeypatch):
    """bsn-bench as an installed wheel sees it: no source tree beside the package nor here; the commands it
    would run, recorded."""
    monkeypatch.delenv(bench.CHECKOUT_ENV, raising=False)
    monkeypatch.setattr(bench, "CHECKOUT", tmp_path / "site-packages")
    monkeypatch.chdir(tmp_path)
    ran = []
    monkeypatch.setattr(bench.subprocess, "run", lambda cmd, cwd, check: ran.append((cmd, cwd)))
    return ran


def test_an_installed_wheel_runs_what_needs_no_tree_from_the_package_and_names_what_it_left_out(
        tmp_path, monkeypatch, capsys):
    ran = _as_installed(tmp_path, monkeypatch)
    assert bench.main(["--only", "vanishing", "alive", "--out", str(tmp_path / "out")]) == 0
    modules = [cmd[cmd.index("-m") + 1] for cmd, _ in ran]
    assert modules == ["bsn_edge.benchmarks.bench_vanishing", "bsn_edge.benchmarks.report"]
    assert all(cwd is None for _, cwd in ran)
    err = capsys.readouterr().err
    assert "left out alive (needs the training runs' weights (models/))" in err and "--checkout" in err


def test_an_installed_wheel_asked_only_for_what_needs_a_tree_is_refused_by_name(tmp_path, monkeypatch, capsys):
    ran = _as_installed(tmp_path, monkeypatch)
    assert bench.main(["--only", "alive", "prune"]) == 2
    err = capsys.readouterr().err
    assert "alive (needs" in err and "prune (needs" in err and "nothing to run" in err and not ran


def test_what_needs_a_tree_is_named_for_benchmarks_that_exist():
    assert set(bench.NEEDS_TREE) <= set(bench.NAMES)


def test_every_benchmark_is_reachable_from_bsn_bench_or_named_as_the_campaigns():
    source = (ROOT / "bsn_edge" / "cli" / "bench.py").read_text()
    reached = set(re.findall(r"benchmarks\.(bench_\w+)", source))
    scripts = {p.stem for p in (ROOT / "benchmarks").glob("bench_*.py")}
    assert scripts - reached - set(bench.CAMPAIGN_TOOLS) == set()
    assert reached <= scripts and set(bench.CAMPAIGN_TOOLS) <= scripts, "no name of a benchmark that is gone"
