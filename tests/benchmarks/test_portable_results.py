"""Benchmark results carry no path of the machine they were measured on."""

import json

from bsn_edge.benchmarks.common import portable, write_result


def test_results_name_the_checkout_relatively_and_home_as_tilde(tmp_path, monkeypatch):
    work, home = tmp_path / "checkout", tmp_path / "home"
    (work / "models").mkdir(parents=True)
    home.mkdir()
    monkeypatch.chdir(work)
    monkeypatch.setenv("HOME", str(home))
    result = {"init": f"{work}/models/default", "cache": f"{home}/.cache/bsn-edge/run3", "other": "/data/clips"}
    path = write_result(work / "results", "portable", result, f"Run `{work}/models/default` from `{home}/.cache`.")
    got = json.loads(path.read_text())
    assert (got["init"], got["cache"], got["other"]) == ("models/default", "~/.cache/bsn-edge/run3", "/data/clips")
    md = (work / "results" / "portable.md").read_text()
    assert "Run `models/default` from `~/.cache`." in md and str(tmp_path) not in md


def test_result_paths_beside_the_checkout_are_written_from_it(tmp_path, monkeypatch):
    """A report names the real data as ``../shared/...`` and the checkout's own files relatively, never
    this machine's absolute paths."""
    checkout = tmp_path / "main"
    checkout.mkdir()
    monkeypatch.chdir(checkout)
    text = f'{{"frames": "{tmp_path}/shared/data/real/a.mp4", "run": "{checkout}/models/default"}}'
    assert portable(text) == '{"frames": "../shared/data/real/a.mp4", "run": "models/default"}'
