"""Benchmark results carry no path of the machine they were measured on."""

import json

from benchmarks.common import write_result


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
