"""bench_cameras --keep: earlier models' rows stay only when they were measured on the same clips."""

import json

import pytest

from bsn_edge.benchmarks.bench_cameras import kept_models

SETS = {"no platoon": ["town_0", "town_1"]}


def test_kept_are_the_earlier_models_not_measured_again(tmp_path):
    path = tmp_path / "cameras.json"
    path.write_text(json.dumps({"sets": SETS, "models": {"leg 1": {"x": 1}, "leg 2": {"x": 2}}}))
    assert kept_models(path, SETS, ["leg 2", "leg 3"]) == {"leg 1": {"x": 1}}
    assert kept_models(tmp_path / "none.json", SETS, []) == {}


def test_rows_of_other_clips_are_never_mixed_in(tmp_path):
    path = tmp_path / "cameras.json"
    path.write_text(json.dumps({"sets": {"no platoon": ["town_0"]}, "models": {"leg 1": {}}}))
    with pytest.raises(ValueError, match="other sets"):
        kept_models(path, SETS, [])
