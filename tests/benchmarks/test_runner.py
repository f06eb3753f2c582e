"""The benchmarks' one runner: what it writes, and the exit status of each way a sitting ends."""

import argparse
import json

from bsn_edge.benchmarks.runner import RefusedError, Report, run


def parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="bench_x")
    p.add_argument("--out")
    p.add_argument("--name", default="x")
    return p


def test_a_report_is_written_beside_the_machine_and_its_status_returned(tmp_path, capsys):
    code = run(lambda a, p: Report({"iou": 0.5}, ["# X", "", "| a |"], ["| a |"], status=1), parser(),
               ["--out", str(tmp_path)])
    assert code == 1
    data = json.loads((tmp_path / "x.json").read_text())
    assert data["iou"] == 0.5 and data["benchmark"] == "x" and "cores" in data["machine"]
    md = (tmp_path / "x.md").read_text()
    assert md.startswith("# X\n\n| a |\n") and "Measured on" in md and "cores" in md
    assert capsys.readouterr().out.strip() == "| a |"


def test_a_report_may_name_its_own_file(tmp_path):
    assert run(lambda a, p: Report({}, ["# Y"], name="campaign_y"), parser(), ["--out", str(tmp_path)]) == 0
    assert (tmp_path / "campaign_y.md").is_file() and not (tmp_path / "x.md").exists()


def test_nothing_to_measure_writes_nothing_and_a_refused_sitting_says_why_with_status_2(tmp_path, capsys):
    assert run(lambda a, p: None, parser(), ["--out", str(tmp_path)]) == 0
    assert not any(tmp_path.iterdir())

    def refuse(a, p):
        raise RefusedError("the ledger trains in bf16, this CPU in fp32")

    assert run(refuse, parser(), ["--out", str(tmp_path)]) == 2
    assert not any(tmp_path.iterdir())
    assert "bench_x: the ledger trains in bf16" in capsys.readouterr().out
