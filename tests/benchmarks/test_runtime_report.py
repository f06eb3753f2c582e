"""The runtime benchmark's report: medians over repeated runs judged against the bars, and per-CPU-class
report names, checked against values worked out by hand."""

import json

import pytest

from bsn_edge.benchmarks import common
from bsn_edge.benchmarks.bench_runtime import median_table


def _row(e2e: float, model_only: float, tail: float, repeat: int) -> dict:
    return {"clip": "udacity 1280x720", "model_file": "m.onnx", "camera_file": True, "loop": "overlap nice 10, no spin",
            "e2e_fps": e2e, "model_only_fps": model_only, "p99_over_p50": tail, "repeat": repeat}


def test_the_summary_takes_each_rows_median_over_the_runs_and_judges_the_bars_on_it():
    rows = [_row(27.0, 40.0, 1.2, 0), _row(36.0, 38.0, 2.5, 1), _row(31.0, 50.0, 1.4, 2)]
    lines = median_table(rows, 3, fps_bar=30.0)
    (line,) = [ln for ln in lines if ln.startswith("| udacity")]
    # medians: 31.0 end to end, 40.0 model only -> 78 %, p99 / p50 1.40: fps and tail pass, share fails
    assert "| 31.0 (27.0 / 36.0 / 31.0) | 40.0 (40.0 / 38.0 / 50.0) | 78 % | 1.40 | FAIL: share |" in line


def test_one_run_has_no_summary():
    assert median_table([_row(31.0, 40.0, 1.2, 0)], 1, fps_bar=30.0) == []


@pytest.mark.parametrize(("isa", "name"), [(["AVX-512", "VNNI", "AVX2"], "runtime"), (["AVX2", "AVX-VNNI"], "runtime"),
                                            (["AVX2"], "runtime_avx2"), (["AVX-512", "AVX2"], "runtime_avx2")])
def test_a_cpu_classes_report_keeps_its_own_name(monkeypatch, isa, name):
    monkeypatch.setattr(common, "machine", lambda: {"isa": isa})
    assert common.class_name("runtime") == name


def test_a_benchmark_run_stopped_part_way_goes_on_from_its_state(monkeypatch, tmp_path):
    """The seeded tables span sittings: a finished run is reused, a stopped one resumed, a new one started."""
    from bsn_edge.cli import train as train_cli
    from bsn_edge.train.run import Run

    calls: list[list[str]] = []
    monkeypatch.setattr(train_cli, "main", lambda argv: calls.append(argv) or 0)
    new, stopped, done = (tmp_path / n for n in ("new", "stopped", "done"))
    for folder in (stopped, done):
        folder.mkdir()
        Run(folder).state_path.write_bytes(b"")
    # a checkpoint on the way has no threshold yet; the last one has the threshold chosen on validation
    Run(stopped).checkpoint_path.write_text(json.dumps({"card": {"threshold": None}, "step": 300}))
    Run(done).checkpoint_path.write_text(json.dumps({"card": {"threshold": 0.35}, "step": 3000}))
    for folder in (new, stopped, done):
        common.train_run(tmp_path / "data", folder, ["train.steps=10"])
    assert len(calls) == 2 and "--resume" not in calls[0] and "--resume" in calls[1]
    assert calls[1][calls[1].index("--out") + 1] == str(stopped)


def test_the_ceiling_is_what_two_cores_can_do_for_both_parts_and_never_above_the_model_alone():
    from bsn_edge.benchmarks.runtime_budget import ceiling
    # the model keeps both cores busy (20 ms of CPU in 10 ms): 2 cores / (20 + 5) ms = 80 frames/s of its 100
    assert ceiling(10.0, 20.0, 5.0) == pytest.approx({"fps": 80.0, "share": 0.8})
    # a model that leaves most of a core idle: reading fits in the gaps, the model's own rate is the limit
    assert ceiling(10.0, 12.0, 4.0) == pytest.approx({"fps": 100.0, "share": 1.0})
    assert ceiling(10.0, 10.0, 10.0, cores=1) == pytest.approx({"fps": 50.0, "share": 0.5})
    with pytest.raises(ValueError, match="positive"):
        ceiling(0.0, 20.0, 5.0)


def test_the_cpu_budget_times_reading_and_the_model_of_the_shipped_model_on_a_short_clip(tmp_path):
    from bsn_edge.benchmarks.runtime_budget import cpu_budget
    from bsn_edge.default_model import DEFAULT_MODEL
    from tests.fakes import noise_video
    if not DEFAULT_MODEL.is_file():
        pytest.skip("the shipped model is not in this checkout")
    video = noise_video(tmp_path / "clip.mp4", 20, 640, 360)
    b = cpu_budget(str(DEFAULT_MODEL), video, 12, None)
    assert {"read_wall_ms", "read_cpu_ms", "decode_cpu_ms", "model_wall_ms", "model_cpu_ms", "ceiling_fps",
            "ceiling_share"} <= set(b)
    assert 0 < b["decode_cpu_ms"] < b["read_cpu_ms"] and b["model_cpu_ms"] > 0 and 0 < b["ceiling_share"] <= 1


def test_the_cpu_budget_table_gives_each_rows_median_over_its_runs():
    from bsn_edge.benchmarks.runtime_budget import budget_table

    def b(read_cpu: float, share: float) -> dict:
        return {"clip": "highway 960x540", "model_file": "m.onnx", "camera_file": False, "read_wall_ms": 5.0,
                "read_cpu_ms": read_cpu, "decode_cpu_ms": 4.0, "model_wall_ms": 20.0, "model_cpu_ms": 38.0,
                "ceiling_fps": 45.0, "ceiling_share": share}

    lines = budget_table([b(9.0, 0.90), b(7.0, 0.93), b(11.0, 0.86)])
    (line,) = [ln for ln in lines if ln.startswith("| highway")]
    assert line == "| highway 960x540 | m.onnx | calibrating | 5.0 (9.0) | 4.0 | 20.0 (38.0) | 45.0 (3) | 90 % |"
