"""bsn-report: the onsets, states and latency of a drive read from its frame log, checked against onsets
written by hand, against the CAN log decoded with cantools (not the project's decoder), and a damaged log
still reported with the damage named."""

import json

import can
import cantools
import numpy as np
import pytest

from bsn_edge.alerts.can_codec import DBC_PATH
from bsn_edge.alerts.can_output import CanSender
from bsn_edge.cli import report as report_cli
from bsn_edge.report import make_report, read_drive
from bsn_edge.runtime import Engine, RuntimeConfig, open_source, run
from tests.fakes import long_video, mounted


def _line(frame, levels, state="OK", scores=(0.1, 0.1, 0.1), distances=(None, None, None), **extra):
    return json.dumps({"frame": frame, "t": frame / 10, "levels": list(levels), "scores": list(scores),
                       "distances": list(distances), "state": state, "latency_ms": 20.0,
                       "stage_ms": {"decode": 5.0, "inference": 10.0}, **extra})


def test_onsets_states_and_damage_as_written_by_hand(tmp_path):
    """Each rise of a sector's level is an onset (NONE -> CAUTION, CAUTION -> WARNING, NONE -> WARNING), a fall
    is none; a line cut by a kill and a line that is not UTF-8 are named by number, the rest read."""
    n, c, w = "NONE", "CAUTION", "WARNING"
    lines = [_line(0, (n, n, n), "CALIBRATING"), _line(1, (c, n, n), "CALIBRATING", distances=(8.0, None, None)),
             _line(2, (w, n, w), distances=(6.5, None, 3.0)), '{"frame": 3, "t": 0.3, "lev',
             _line(4, (n, n, w)), json.dumps({"frame": 5, "t": 0.5, "fault": "decode_errors"}),
             _line(6, (c, c, n), "DEGRADED")]
    log = tmp_path / "log.jsonl"
    log.write_bytes(("\n".join(lines) + "\n").encode() + b"\xff\xfe not text\n")
    drive = read_drive(log)
    got = [(o.sector, o.level, o.frame, o.distance_m) for o in drive.onsets]
    assert got == [("LEFT", c, 1, 8.0), ("LEFT", w, 2, 6.5), ("RIGHT", w, 2, 3.0), ("LEFT", c, 6, None),
                   ("CENTRE", c, 6, None)]
    assert [(d.line) for d in drive.damage] == [4, 8]
    assert [s for _, _, s in drive.states()] == ["CALIBRATING", "OK", "DEGRADED"]
    assert drive.faults() == [(0.5, 5, "decode_errors")]
    assert drive.latency()["inference"] == {"p50": 10.0, "p95": 10.0, "p99": 10.0}
    out = tmp_path / "report"
    record = make_report(log, out, say=lambda s: None)
    assert record["damaged_lines"][0]["line"] == 4 and (out / "report.html").read_text().count("<h2>") >= 5
    assert json.loads((out / "report.json").read_text())["onsets"][1] == {
        "sector": "LEFT", "level": "WARNING", "t": 0.2, "frame": 2, "distance_m": 6.5}


class Blinking(Engine):
    """After its self-test: a near blind spot over the frame for 30 frames, none for 30, then again."""

    on = False
    calls = 0

    def infer(self, batch):
        prob, depth = super().infer(batch)
        if not self.on:
            return prob, depth
        self.calls += 1
        near = (self.calls - 1) // 30 % 2 == 0
        return (np.ones_like(prob) if near else np.zeros_like(prob)), np.full_like(depth, 2.0)


def test_the_reports_onsets_are_the_buses_decoded_with_cantools(setup, tmp_path):
    model, clip = setup
    video = long_video(clip, tmp_path / "long.mp4", 6)         # 90 frames
    log, can_log = tmp_path / "log.jsonl", tmp_path / "c.log"
    engine = Blinking(model)
    engine.on = True
    with CanSender("virtual", "bsn-report", log_path=str(can_log)) as tx:
        run(engine, open_source(str(video)), [tx], RuntimeConfig(cycle_s=0.1, warmup=0), log=log,
            camera=mounted(engine, clip))
    record = make_report(log, tmp_path / "report", can_log=can_log, say=lambda s: None)
    # the bus's onsets, decoded here with cantools from the DBC
    db = cantools.database.load_file(str(DBC_PATH))
    hazard = db.get_message_by_name("BSN_Hazard")
    last, bus = {}, []
    for msg in can.LogReader(str(can_log)):
        if msg.arbitration_id == hazard.frame_id:
            values = hazard.decode(bytes(msg.data), decode_choices=False)
            for side in ("Left", "Centre", "Right"):
                level = int(values[f"{side}_Level"])
                if level > last.get(side, 0):
                    bus.append((side.upper(), ("NONE", "CAUTION", "WARNING")[level]))
                last[side] = level
    mine = [(o["sector"], o["level"]) for o in record["onsets"]]
    assert len(mine) >= 4 and sorted(mine) == sorted(bus)
    assert record["bus_check"]["agree"]
    # cycle by cycle: every hazard frame cantools decodes against the frame the log says it carried
    cycles = record["bus_check"]["cycles"]
    frames = [hazard.decode(bytes(m.data), decode_choices=False) for m in can.LogReader(str(can_log))
              if m.arbitration_id == hazard.frame_id]
    assert cycles["numbered"] and cycles["disagree"] == 0, cycles
    assert cycles["compared"] + cycles["not_compared"] == len(frames) and cycles["compared"] >= 50, cycles


def test_an_existing_report_is_refused_without_force_and_a_missing_log_is_named(tmp_path, capsys):
    log = tmp_path / "log.jsonl"
    log.write_text(_line(0, ("NONE",) * 3) + "\n")
    out = tmp_path / "r"
    assert report_cli.main([str(log), "--out", str(out)]) == 0
    assert report_cli.main([str(log), "--out", str(out)]) == 2
    assert "exists; pass --force" in capsys.readouterr().err
    assert report_cli.main([str(log), "--out", str(out), "--force"]) == 0
    assert report_cli.main([str(tmp_path / "nope.jsonl"), "--out", str(tmp_path / "r2")]) == 2
    assert "nope.jsonl not found" in capsys.readouterr().err and not (tmp_path / "r2").exists()


def test_without_matplotlib_it_says_which_install_brings_it(tmp_path, capsys, monkeypatch):
    import builtins

    real = builtins.__import__

    def no_matplotlib(name, *args, **kw):
        if name.split(".")[0] == "matplotlib":
            raise ModuleNotFoundError("No module named 'matplotlib'", name="matplotlib")
        return real(name, *args, **kw)

    monkeypatch.setattr(builtins, "__import__", no_matplotlib)
    assert report_cli.main([str(tmp_path / "log.jsonl"), "--out", str(tmp_path / "r")]) == 2
    assert "bsn-edge[report]" in capsys.readouterr().err


@pytest.fixture
def setup(tmp_path_factory, small_light_onnx):
    from bsn_edge.synth import SynthConfig, write_clip

    root = tmp_path_factory.mktemp("report")
    clip = root / "clip"
    write_clip(SynthConfig(frames=15, height=96, width=192, seed=2), clip)
    return small_light_onnx((128, 256)), clip


MARKUP = "<script>alert(1)</script>&<b>"


def test_every_string_of_the_run_reaches_the_page_as_text_not_markup(tmp_path):
    log, summary = tmp_path / "log.jsonl", tmp_path / "summary.json"
    log.write_text(_line(0, ("NONE",) * 3) + "\n" + _line(1, ("CAUTION", "NONE", "NONE")) + "\n")
    summary.write_text(json.dumps({
        "frames": 2, "source": f"/drives/{MARKUP}clip.mp4", "settings_digest": MARKUP, "machine": {"cpu": MARKUP},
        "model": {"variant": MARKUP, "graph_sha256": MARKUP, "config_digest": MARKUP, "signer": MARKUP,
                  "authentic": True, "threshold": 0.25},
        "camera": {"calibration": {"source": MARKUP}, "mounting": {"note": MARKUP}, "hood": MARKUP}}))
    make_report(log, tmp_path / "r", summary=summary, say=lambda s: None)
    page = (tmp_path / "r" / "report.html").read_text()
    assert "<script>" not in page and "<b>" not in page, "a string of the run was written as markup"
    assert page.count("&lt;script&gt;alert(1)&lt;/script&gt;&amp;") >= 6, page.count("&lt;script&gt;")
    assert f"/drives/{MARKUP}clip.mp4".replace("&", "&amp;").replace("<", "&lt;").replace(">", "&gt;") in page


def _can_log(path, frames_):
    path.write_text("".join(f"({i * 0.05:.6f}) vcan0 {f:03X}#{d.hex().upper()}\n" for i, (f, d) in enumerate(frames_)))


def test_a_damaged_bus_frame_is_counted_never_an_onset_nor_a_crash(tmp_path):
    from bsn_edge.alerts import AlertFrame, Level, SectorAlert, SystemState
    from bsn_edge.alerts.can_codec import CanEncoder
    from bsn_edge.alerts.e2e import e2e_crc

    enc = CanEncoder()
    none, warn = SectorAlert(0.0, Level.NONE, None), SectorAlert(0.9, Level.WARNING, 3.0)
    fs = []
    for k in range(6):
        right = warn if k >= 3 else none
        fs += enc.encode(AlertFrame(k * 0.1, (none, none, right), SystemState.OK, 10.0, {}))
    hid, data = fs[2]                       # cycle 1's hazard frame
    three = bytearray(data)
    three[0] |= 0x03                        # Left_Level = 3 under a good CRC: undefined
    three[7] = e2e_crc(bytes(three[:7]), hid)
    hid4, data4 = fs[4]                     # cycle 2's hazard frame, a bit flipped: the CRC fails
    flipped = bytearray(data4)
    flipped[0] |= 0x01                      # would read Left CAUTION
    fs[2], fs[4] = (hid, bytes(three)), (hid4, bytes(flipped))
    can_log, log = tmp_path / "c.log", tmp_path / "log.jsonl"
    _can_log(can_log, fs)
    n, w = "NONE", "WARNING"
    log.write_text("".join(_line(k, (n, n, w if k >= 3 else n)) + "\n" for k in range(6)))
    record = make_report(log, tmp_path / "r", can_log=can_log, say=lambda s: None)
    check = record["bus_check"]
    assert check["damaged_frames"] == {"undefined field": 1, "bad CRC": 1}, check
    assert check["sectors"]["LEFT"]["bus"] == 0 and check["sectors"]["RIGHT"]["bus"] == 1
    assert check["agree"], check
    assert "Damaged frames on the bus" in (tmp_path / "r" / "report.html").read_text()


def test_a_stall_cycle_on_the_bus_is_no_fall_and_the_level_after_it_no_new_onset(tmp_path):
    """A stall sends UNAVAILABLE with every level NONE; the WARNING after it is the same onset, not a second
    (a busy machine's stalls made the report say the bus and the log DISAGREE)."""
    from bsn_edge.alerts import AlertFrame, Level, SectorAlert, SystemState
    from bsn_edge.alerts.can_codec import CanEncoder
    from bsn_edge.report.can_check import read_bus

    enc = CanEncoder()
    none, warn = SectorAlert(0.0, Level.NONE, None), SectorAlert(0.9, Level.WARNING, 3.0)
    fs = []
    for k, state in enumerate([SystemState.OK, SystemState.OK, SystemState.UNAVAILABLE, SystemState.OK]):
        right = none if k == 0 else warn
        frame = AlertFrame(k * 0.1, (none, none, right), state, 10.0, {})
        if state == SystemState.UNAVAILABLE:        # what a stall cycle carries
            frame = AlertFrame.unavailable(k * 0.1)
        fs += enc.encode(frame)
    can_log = tmp_path / "c.log"
    _can_log(can_log, fs)
    onsets = [(o.sector, o.level) for o in read_bus(can_log).onsets]
    assert onsets == [("RIGHT", "WARNING")], onsets


def test_every_disagreement_is_shown_with_its_time_the_bus_around_it_and_why(tmp_path):
    """The log has one RIGHT WARNING; the bus has it, falls to NONE in an OK cycle, goes UNAVAILABLE, and
    rises again: the second rise is on the bus only, at its cycle's time, with the UNAVAILABLE before it
    named. The log's LEFT CAUTION never reached the bus: the frame log only, at its frame's time."""
    from bsn_edge.alerts import AlertFrame, Level, SectorAlert, SystemState
    from bsn_edge.alerts.can_codec import CanEncoder

    enc = CanEncoder()
    none, warn = SectorAlert(0.0, Level.NONE, None), SectorAlert(0.9, Level.WARNING, 3.0)
    fs = []
    plan = [(SystemState.OK, none), (SystemState.OK, warn), (SystemState.OK, none), (SystemState.UNAVAILABLE, none),
            (SystemState.OK, warn)]
    for k, (state, right) in enumerate(plan):
        fs += enc.encode(AlertFrame.unavailable(k * 0.1) if state == SystemState.UNAVAILABLE
                         else AlertFrame(k * 0.1, (none, none, right), state, 10.0, {}))
    can_log, log = tmp_path / "c.log", tmp_path / "log.jsonl"
    _can_log(can_log, fs)                    # two frames a cycle, 0.05 s apart: cycle k's status at 0.1 k + 0.05
    n, c, w = "NONE", "CAUTION", "WARNING"
    log.write_text("".join(_line(k, (c if k == 2 else n, n, w if k >= 1 else n)) + "\n" for k in range(5)))
    record = make_report(log, tmp_path / "r", can_log=can_log, say=lambda s: None)
    found = {(d["where"], d["sector"], d["level"]): d for d in record["bus_check"]["disagreements"]}
    assert set(found) == {("bus only", "RIGHT", "WARNING"), ("frame log only", "LEFT", "CAUTION")}, found
    bus_only = found[("bus only", "RIGHT", "WARNING")]
    assert bus_only["t_s"] == pytest.approx(0.4), bus_only          # cycle 4's hazard, from the CAN log's first frame
    assert [a["state"] for a in bus_only["around"]] == ["OK", "UNAVAILABLE", "OK"], bus_only["around"]
    assert "UNAVAILABLE just before" in bus_only["why"]
    assert found[("frame log only", "LEFT", "CAUTION")]["t_s"] == pytest.approx(0.2)
    page = (tmp_path / "r" / "report.html").read_text()
    assert "UNAVAILABLE just before" in page and "0.40 s" in page


def test_the_page_says_values_in_words_and_units_not_json():
    """Once: empty header rows, raw JSON (``{"height_m": 1.5, "pitch_deg": -2.8842130437072666}``), bare null, and
    "converged: no" for a run whose camera file gave the mounting."""
    from bsn_edge.report.page import _converged, _table, plain

    assert plain({"height_m": 1.5, "pitch_deg": -2.8842130437072666, "yaw_deg": 0.0}) == \
        "height 1.5 m, pitch -2.88 deg, yaw 0 deg"
    assert plain(None) == "-" and plain({}) == "-" and plain(True) == "yes"
    assert plain({"cpu": "AMD EPYC", "cores": 2}) == "cpu AMD EPYC, cores 2"
    assert "<th>" not in _table([["a", "b"]]) and "<th>x</th>" in _table([["a"]], ["x"])
    assert _converged({"source": "camera file", "converged_at": None}) == \
        "not calibrated online: the mounting is the camera file's"
    assert _converged({"source": "online", "converged_at": {"frame": 82, "seconds": 3.28}}) == "at frame 82, 3.28 s in"
    assert _converged({"source": "online", "converged_at": None}) == "no"


def test_bsn_listen_prints_the_onsets_the_report_matches(tmp_path, capsys):
    """``bsn-listen --onsets``: the log's rises in the report's form, a stall's UNAVAILABLE cycle no new one."""
    from bsn_edge.alerts import AlertFrame, Level, SectorAlert, SystemState
    from bsn_edge.alerts.can_codec import CanEncoder
    from bsn_edge.cli import listen

    enc = CanEncoder()
    none = SectorAlert(0.0, Level.NONE, None)
    caution, warn = SectorAlert(0.5, Level.CAUTION, 9.0), SectorAlert(0.9, Level.WARNING, 3.0)
    plan = [(none, none), (caution, none), (caution, warn), None, (caution, warn)]   # None: a stall cycle
    fs = []
    for k, p in enumerate(plan):
        fs += enc.encode(AlertFrame.unavailable(k * 0.1) if p is None
                         else AlertFrame(k * 0.1, (p[0], none, p[1]), SystemState.OK, 10.0, {}))
    can_log = tmp_path / "c.log"
    _can_log(can_log, fs)                   # cycle k's hazard at 0.1 k s into the log
    assert listen.main(["--can-log", str(can_log), "--onsets"]) == 0
    rows = [ln.split() for ln in capsys.readouterr().out.splitlines()[1:]]
    assert rows == [["0.10", "s", "LEFT", "CAUTION", "1"], ["0.20", "s", "RIGHT", "WARNING", "2"]], rows


def test_the_bus_is_compared_with_the_log_cycle_by_cycle(tmp_path):
    """The log's LEFT CAUTION went out at cycle 1 (its ``bus_from``); the bus has it at cycle 3 instead. The
    onsets agree in number and order, so only the cycle-by-cycle check sees it: cycles 1 and 3 differ, each
    with its time, frame and the cycles around it; the UNAVAILABLE cycle 2 is not compared, and the command
    exits 1 naming the first."""
    from bsn_edge.alerts import AlertFrame, Level, SectorAlert, SystemState
    from bsn_edge.alerts.can_codec import CanEncoder

    enc = CanEncoder()
    none, caution = SectorAlert(0.0, Level.NONE, None), SectorAlert(0.5, Level.CAUTION, 9.0)
    fs = []
    for k in range(5):
        fs += enc.encode(AlertFrame.unavailable(k * 0.1) if k == 2
                         else AlertFrame(k * 0.1, (caution if k == 3 else none, none, none), SystemState.OK, 10.0, {}))
    can_log, log = tmp_path / "c.log", tmp_path / "log.jsonl"
    _can_log(can_log, fs)
    n, c = "NONE", "CAUTION"
    log.write_text("".join(_line(k, (c if k == 1 else n, n, n), bus_from=k) + "\n" for k in range(5)))
    record = make_report(log, tmp_path / "r", can_log=can_log, say=lambda s: None)
    check = record["bus_check"]
    assert check["sectors"]["LEFT"]["only_in_log"] == [] and check["sectors"]["LEFT"]["only_on_bus"] == []
    cycles = check["cycles"]
    assert (cycles["compared"], cycles["agree"], cycles["disagree"], cycles["not_compared"]) == (4, 2, 2, 1), cycles
    one, three = cycles["disagreements"]
    assert (one["cycle"], one["frame"], one["bus"][0], one["log"][0]) == (1, 1, "NONE", "CAUTION")
    assert (three["cycle"], three["frame"], three["bus"][0], three["log"][0]) == (3, 3, "CAUTION", "NONE")
    assert three["t_s"] == pytest.approx(0.3) and [a["cycle"] for a in three["around"]] == [1, 2, 3, 4]
    assert not check["agree"]
    assert report_cli.main([str(log), "--out", str(tmp_path / "r2"), "--can-log", str(can_log)]) == 1


def test_a_log_without_cycle_numbers_is_compared_by_onsets_only(tmp_path):
    from bsn_edge.alerts import AlertFrame, Level, SectorAlert, SystemState
    from bsn_edge.alerts.can_codec import CanEncoder

    enc = CanEncoder()
    none = SectorAlert(0.0, Level.NONE, None)
    fs = [f for k in range(3) for f in enc.encode(AlertFrame(k * 0.1, (none,) * 3, SystemState.OK, 10.0, {}))]
    can_log, log = tmp_path / "c.log", tmp_path / "log.jsonl"
    _can_log(can_log, fs)
    log.write_text("".join(_line(k, ("NONE",) * 3) + "\n" for k in range(3)))
    record = make_report(log, tmp_path / "r", can_log=can_log, say=lambda s: None)
    assert record["bus_check"]["agree"] and not record["bus_check"]["cycles"]["numbered"]
    assert "compared by its onsets only" in (tmp_path / "r" / "report.html").read_text()


def test_a_log_of_another_layout_is_read_by_its_summarys_sectors_or_numbered_without_one(tmp_path):
    """A four-sector run's frame log: with its summary the sectors are the layout's names; without, they are
    numbered from the first frame's count (never the default's three, which would call every line damaged)."""
    import json

    from bsn_edge.report.drive import read_drive

    log = tmp_path / "frames.jsonl"
    lines = [{"frame": k, "t": 0.1 * k, "levels": ["NONE", "NONE", "CAUTION" if k else "NONE", "NONE"],
              "scores": [0.0, 0.0, 0.3 if k else 0.0, 0.0], "distances": [None, None, 8.0, None]} for k in range(3)]
    log.write_text("".join(json.dumps(x) + "\n" for x in lines))
    layout = [{"name": "FAR_LEFT", "to_deg": -20.0}, {"name": "LEFT", "to_deg": 0.0},
              {"name": "RIGHT", "to_deg": 20.0}, {"name": "FAR_RIGHT", "to_deg": None}]
    summary = tmp_path / "summary.json"
    summary.write_text(json.dumps({"frames": 3, "settings": {"sectors": {"layout": layout}}}))
    named = read_drive(log, summary)
    assert named.names == ("FAR_LEFT", "LEFT", "RIGHT", "FAR_RIGHT") and not named.damage
    assert [(o.sector, o.level, o.frame) for o in named.onsets] == [("RIGHT", "CAUTION", 1)]
    bare = read_drive(log)
    assert bare.names == ("SECTOR1", "SECTOR2", "SECTOR3", "SECTOR4") and not bare.damage
    assert [o.sector for o in bare.onsets] == ["SECTOR3"]
