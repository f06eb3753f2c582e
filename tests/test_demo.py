"""The README's main job: bsn-demo with the shipped model."""

import dataclasses
import json

import pytest

from bsn_edge.card import ModelCard
from bsn_edge.cli import demo
from bsn_edge.cli.common import CHECKOUT
from bsn_edge.modelfile.read import ModelFile

SHIPPED_RUN = CHECKOUT / "models" / "default"      # the run it was exported from: a checkout's, not the wheel's


@pytest.mark.skipif(not demo.DEFAULT_MODEL.is_file(), reason="the shipped model is not in this checkout")
def test_demo_runs_the_shipped_model(tmp_path):
    assert demo.main(["--out", str(tmp_path), "--frames", "12"]) == 0
    s = json.loads((tmp_path / "summary.json").read_text())
    card = json.loads((SHIPPED_RUN / "checkpoint.json").read_text())["card"]
    assert s["frames"] == s["valid_frames"] == 12 and s["model"]["variant"] == card["variant"]
    for name in ("overlay.mp4", "alerts.jsonl", "alerts.log", "contact_sheet.png"):
        assert (tmp_path / name).stat().st_size > 0, name


def test_demo_without_a_model_says_how_to_make_one(tmp_path, capsys):
    assert demo.main(["--out", str(tmp_path), "--model", str(tmp_path / "none.onnx")]) == 2
    assert "bsn-train and bsn-export" in capsys.readouterr().err


@pytest.mark.skipif(not (demo.DEFAULT_MODEL.is_file() and (SHIPPED_RUN / "checkpoint.json").is_file()),
                    reason="the shipped model or its run is not in this checkout")
def test_the_shipped_run_is_what_the_shipped_model_was_exported_from():
    """Both halves of a release: the ONNX model users run and the run they fine-tune and adapt."""
    onnx = ModelCard.from_metadata(ModelFile.read(demo.DEFAULT_MODEL).metadata, str(demo.DEFAULT_MODEL))
    run = ModelCard.from_dict(json.loads((SHIPPED_RUN / "checkpoint.json").read_text())["card"], str(SHIPPED_RUN))
    assert onnx.sealed and onnx.seven_bit_weights
    for field in ("variant", "spec", "input_size", "camera", "mounting", "config_digest"):
        assert getattr(onnx, field) == getattr(run, field), field
    # a threshold chosen after training says where; then it is the one thing the run does not hold
    assert onnx.training is not None and run.training is not None
    assert dataclasses.replace(onnx.training, threshold_from="") == run.training
    assert onnx.threshold == run.threshold or onnx.training.threshold_from
