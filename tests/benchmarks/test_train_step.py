"""The training-step benchmark's architectures side by side, as bsn-train would run them."""

import json

import pytest

from bsn_edge.cli import label as label_cli
from bsn_edge.cli import synth as synth_cli


@pytest.fixture(scope="module")
def clips(tmp_path_factory):
    root = tmp_path_factory.mktemp("clips")
    assert synth_cli.main([str(root / "town_0"), "--frames", "52", "--size", "64x128", "--seed", "0",
                           "--no-video"]) == 0
    assert label_cli.main([str(root / "town_0"), "--jobs", "1"]) == 0
    return root


def test_as_trained_measures_each_architecture_in_what_bsn_train_runs_here(clips, tmp_path, monkeypatch):
    import bsn_edge.benchmarks.bench_train_step as bts

    # a CPU with native bf16: of the fp32 and bf16 channels-last configurations, bsn-train runs bf16
    monkeypatch.setattr(bts, "cpu_has_native_bf16", lambda: True)
    config = "channels last + bf16 autocast"
    assert bts.main(["--data", str(clips), "--out", str(tmp_path), "--model", "shared-light", "small-light",
                     "--as-trained", "--steps", "1", "--rounds", "2", "--batch", "2", "--size", "64x128",
                     "--budget", "7200", "--name", "ts"]) == 0
    res = json.loads((tmp_path / "ts.json").read_text())
    assert [(r["model"], r["config"]) for r in res["rows"]] == [("shared-light", config), ("small-light", config)]
    for r in res["rows"]:
        assert r["n"] == 2 and r["budget_hours"] == pytest.approx(2 * r["seconds_per_step"])
        assert r["samples_per_second"] == pytest.approx(2 / r["seconds_per_step"])
    md = (tmp_path / "ts.md").read_text()
    assert md.startswith("# Training step as bsn-train runs it here") and "h for 7,200 steps" in md


def test_an_unknown_architecture_is_named_with_the_valid_ones(tmp_path, capsys):
    import bsn_edge.benchmarks.bench_train_step as bts

    with pytest.raises(SystemExit):
        bts.main(["--data", str(tmp_path), "--model", "small", "tiny"])
    err = capsys.readouterr().err
    assert "'tiny'" in err and "shared-light" in err
