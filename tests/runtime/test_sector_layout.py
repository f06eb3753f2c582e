"""A fourth sector from the vehicle file alone: ``bsn-run`` with a four-sector layout on a real clip, its CAN log
decoded by cantools with the DBC ``bsn-run --print-dbc`` generates for that file (python-can reads the log), the
frame log and the report speaking of the same four sectors, and ``bsn-listen`` checking the frames."""

import json
from pathlib import Path

import can
import cantools
import pytest

from bsn_edge.cli import listen as listen_cli
from bsn_edge.cli import report as report_cli
from bsn_edge.cli import run as run_cli
from bsn_edge.default_model import DEFAULT_MODEL

REAL = Path(__file__).resolve().parents[3] / "shared" / "data" / "real"
CLIP = REAL / "dashcam_highway.mp4"
FOUR = ("FAR_LEFT", "LEFT", "RIGHT", "FAR_RIGHT")
VEHICLE = """[sectors]
layout = [{ name = "FAR_LEFT", to_deg = -20.0 }, { name = "LEFT", to_deg = 0.0 },
          { name = "RIGHT", to_deg = 20.0 }, { name = "FAR_RIGHT" }]
"""


@pytest.fixture(scope="module")
def four_sector_run(tmp_path_factory):
    if not CLIP.is_file():
        pytest.skip(f"real data absent: {CLIP}")
    out = tmp_path_factory.mktemp("four")
    (out / "vehicle.toml").write_text(VEHICLE)
    assert run_cli.main(["--model", str(DEFAULT_MODEL), "--source", str(CLIP), "--config", str(out / "vehicle.toml"),
                         "--max-frames", "90", "--can-log", str(out / "bus.log"), "--log", str(out / "frames.jsonl"),
                         "--summary", str(out / "summary.json")]) == 0
    return out


def test_print_dbc_writes_the_vehicles_dbc(four_sector_run, capsys):
    assert run_cli.main(["--config", str(four_sector_run / "vehicle.toml"), "--print-dbc"]) == 0
    text = capsys.readouterr().out
    (four_sector_run / "vehicle.dbc").write_text(text)
    db = cantools.database.load_file(str(four_sector_run / "vehicle.dbc"))
    assert {m.name for m in db.messages} == {"BSN_Hazard", "BSN_Hazard2", "BSN_Status"}


def test_four_sectors_decoded_from_the_can_log_with_the_generated_dbc(four_sector_run, capsys):
    run_cli.main(["--config", str(four_sector_run / "vehicle.toml"), "--print-dbc"])
    db = cantools.database.load_string(capsys.readouterr().out, database_format="dbc")
    first, second = db.get_message_by_name("BSN_Hazard"), db.get_message_by_name("BSN_Hazard2")
    cycles, pending = [], None
    with can.LogReader(str(four_sector_run / "bus.log")) as reader:
        for m in reader:
            if m.arbitration_id == first.frame_id:
                pending = db.decode_message(m.arbitration_id, bytes(m.data), decode_choices=False)
            elif m.arbitration_id == second.frame_id:
                assert pending is not None, "the second hazard frame follows the first in its cycle"
                cycles.append({**pending, **db.decode_message(m.arbitration_id, bytes(m.data), decode_choices=False)})
                pending = None
    assert len(cycles) >= 30, "a cycle every 0.1 s of the clip's 3.6 s"
    names = ["Far_Left", "Left", "Right", "Far_Right"]
    assert all(all(f"{n}_Level" in c and f"{n}_Score" in c for n in names) for c in cycles)
    assert max(c[f"{n}_Score"] for c in cycles for n in names) > 0, "the model saw blind spots in some sector"
    frames = [json.loads(line) for line in (four_sector_run / "frames.jsonl").read_text().splitlines()]
    said = [f for f in frames if "levels" in f]
    assert said and all(len(f["levels"]) == 4 for f in said)
    summary = json.loads((four_sector_run / "summary.json").read_text())
    assert [s["name"] for s in summary["settings"]["sectors"]["layout"]] == list(FOUR)


def test_the_report_and_the_listener_read_the_four_sectors(four_sector_run, capsys):
    d = four_sector_run
    assert report_cli.main([str(d / "frames.jsonl"), "--summary", str(d / "summary.json"),
                            "--can-log", str(d / "bus.log"), "--out", str(d / "report")]) == 0
    record = json.loads((d / "report" / "report.json").read_text())
    assert set(record["bus_check"]["sectors"]) == set(FOUR)
    assert record["bus_check"]["cycles"]["compared"] > 0 and record["bus_check"]["cycles"]["disagree"] == 0
    capsys.readouterr()
    assert listen_cli.main(["--can-log", str(d / "bus.log"), "--config", str(d / "vehicle.toml")]) == 0
    heard = capsys.readouterr().out
    assert "hazard2" in heard and "FAR_RIGHT" in heard and "FAR_LEFT" in heard
