"""Labelling clips as Ray tasks on a local Ray instance (skipped when Ray is not installed)."""

import shutil

import pytest

from bsn_edge.cli import label as label_cli
from bsn_edge.labels import LabelConfig, labels_dir
from bsn_edge.synth import SynthConfig, write_clip

pytest.importorskip("ray")


def test_ray_labels_clips_and_reports_a_bad_one(tmp_path, capsys):
    good = tmp_path / "good"
    write_clip(SynthConfig(frames=20, height=48, width=96, seed=1), good, video=False)
    other = tmp_path / "other"
    shutil.copytree(good, other)
    (other / "poses.txt").write_text("1 0 0 0\n")
    rc = label_cli.main([str(good), str(other), "--T", "1", "--ray", "local"])
    out = capsys.readouterr().out
    assert rc == 1
    assert "12 numbers" in out, "the bad clip's error comes back from its task"
    assert len(list((labels_dir(good, LabelConfig(horizon_s=1.0)) / "blindspot").iterdir())) == 5
