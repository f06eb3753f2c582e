"""bsn-bench from a checkout: one benchmark and the report."""

import json

from bsn_edge.cli import bench


def test_bench_runs_a_benchmark_and_writes_the_report(tmp_path):
    assert bench.main(["--only", "synth", "--out", str(tmp_path)]) == 0
    res = json.loads((tmp_path / "synth.json").read_text())
    assert {r["style"] for r in res["rows"]} == {"town", "suburb"} and res["machine"]["cores"]
    report = (tmp_path / "REPORT.md").read_text()
    assert "Measured on" in report and "Synthetic world" in report
