"""The runtime benchmark's report: medians over repeated runs judged against the bars, and per-CPU-class
report names, checked against values worked out by hand."""

import pytest

from benchmarks import common
from benchmarks.bench_runtime import median_table


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
    Run(stopped).state_path.write_bytes(b"")
    Run(done).checkpoint_path.write_text("{}")
    for folder in (new, stopped, done):
        common.train_run(tmp_path / "data", folder, ["train.steps=10"])
    assert len(calls) == 2 and "--resume" not in calls[0] and "--resume" in calls[1]
    assert calls[1][calls[1].index("--out") + 1] == str(stopped)
