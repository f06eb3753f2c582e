"""The README's main job: bsn-demo with the shipped model."""

import json

import pytest

from bsn_edge.cli import demo


@pytest.mark.skipif(not demo.DEFAULT_MODEL.is_file(), reason="the shipped model is not in this checkout")
def test_demo_runs_the_shipped_model(tmp_path):
    assert demo.main(["--out", str(tmp_path), "--frames", "12"]) == 0
    s = json.loads((tmp_path / "summary.json").read_text())
    assert s["frames"] == s["valid_frames"] == 12 and s["model"]["variant"] == "small-light"
    for name in ("overlay.mp4", "alerts.jsonl", "alerts.log", "contact_sheet.png"):
        assert (tmp_path / name).stat().st_size > 0, name


def test_demo_without_a_model_says_how_to_make_one(tmp_path, capsys):
    assert demo.main(["--out", str(tmp_path), "--model", str(tmp_path / "none.onnx")]) == 2
    assert "bsn-train and bsn-export" in capsys.readouterr().err
