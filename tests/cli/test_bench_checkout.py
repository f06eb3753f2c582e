"""``bsn-bench`` runs the package's benchmarks (``bsn_edge.benchmarks``) in the source tree it finds or is given,
told where it is, wherever it is run from; every benchmark of the package is reachable from it or named as one of
the campaign's own."""

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

from bsn_edge.cli import bench

ROOT = Path(__file__).resolve().parents[2]


def _tree(root: Path) -> Path:
    """A source tree as bsn-bench knows one: the files of it the benchmarks read."""
    for mark in bench.MARKS:
        (root / mark).parent.mkdir(parents=True, exist_ok=True)
        (root / mark).write_text("")
    return root


def _recorded(monkeypatch) -> list[tuple[list[str], Path | None, dict | None]]:
    ran: list[tuple[list[str], Path | None, dict | None]] = []
    monkeypatch.setattr(bench.subprocess, "run", lambda cmd, cwd, check, env: ran.append((cmd, cwd, env)))
    return ran


def test_bsn_bench_runs_the_packages_benchmarks_in_the_tree_it_is_given_and_tells_them_where_it_is(
        tmp_path, monkeypatch):
    tree = _tree(tmp_path / "tree")
    ran = _recorded(monkeypatch)
    monkeypatch.chdir(tmp_path)
    assert bench.main(["--checkout", str(tree), "--only", "alive", "--out", str(tmp_path / "out")]) == 0
    assert [cmd[cmd.index("-m") + 1] for cmd, _, _ in ran] == ["bsn_edge.benchmarks.bench_alive",
                                                                "bsn_edge.benchmarks.report"]
    assert all(cwd == tree.resolve() and env[bench.CHECKOUT_ENV] == str(tree.resolve()) for _, cwd, env in ran)


def test_a_benchmark_reads_the_tree_it_is_told_of():
    """What ``$BSN_EDGE_CHECKOUT`` names is the checkout the package's modules read (configs, models, lab)."""
    code = "from bsn_edge.benchmarks import bench_alive; print(bench_alive.DEFAULT_RUNS)"
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120,
                       env={**os.environ, bench.CHECKOUT_ENV: "/somewhere/else"})
    assert r.returncode == 0, r.stderr
    assert r.stdout.strip() == str(Path("/somewhere/else/models/default").resolve())


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
    return _recorded(monkeypatch)


def test_an_installed_wheel_runs_what_needs_no_tree_from_the_package_and_names_what_it_left_out(
        tmp_path, monkeypatch, capsys):
    ran = _as_installed(tmp_path, monkeypatch)
    assert bench.main(["--only", "vanishing", "alive", "--out", str(tmp_path / "out")]) == 0
    modules = [cmd[cmd.index("-m") + 1] for cmd, _, _ in ran]
    assert modules == ["bsn_edge.benchmarks.bench_vanishing", "bsn_edge.benchmarks.report"]
    assert all(cwd is None and env is None for _, cwd, env in ran)
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
    reached = set(re.findall(r"\.(bench_\w+)\"", source)) | {f"bench_{n}" for n in bench.BY_OUT_ONLY}
    scripts = {p.stem for p in (ROOT / "bsn_edge" / "benchmarks").glob("bench_*.py")}
    assert scripts - reached - set(bench.CAMPAIGN_TOOLS) == set()
    assert reached <= scripts and set(bench.CAMPAIGN_TOOLS) <= scripts, "no name of a benchmark that is gone"
