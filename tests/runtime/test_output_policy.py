"""One output policy for every command: an existing file is not replaced without --force, a suffix the writer
does not know or a place that cannot be written is refused before the first frame (nothing written, nothing
sent but what the refusal sends), and missing folders are made for every output alike."""

import json

import pytest

from bsn_edge.cli import demo, sheet
from bsn_edge.cli import run as run_cli
from tests.fakes import full_disk_for


def _run(model, clip, *extra):
    return run_cli.main(["--model", str(model), "--source", str(clip / "video.mp4"), "--max-frames", "3", *extra])


@pytest.mark.parametrize("flag,name", [("--overlay", "o.mp4"), ("--log", "f.jsonl"), ("--summary", "s.json"),
                                       ("--can-log", "c.log"), ("--save-calib", "cam.json")])
def test_an_existing_output_is_refused_before_the_first_frame_and_replaced_with_force(setup, tmp_path, capsys,
                                                                                       flag, name):
    model, clip = setup
    path = tmp_path / name
    path.write_bytes(b"the user's own\n")
    assert _run(model, clip, flag, str(path)) == 2
    assert path.read_bytes() == b"the user's own\n"
    assert f"{flag} {path} exists; pass --force to replace it" in capsys.readouterr().err
    assert _run(model, clip, flag, str(path), "--force") == 0
    if flag != "--save-calib":                   # written only once calibration converges
        assert path.read_bytes() != b"the user's own\n"


def test_every_existing_output_is_named_in_one_refusal_and_the_refused_run_writes_nothing(setup, tmp_path, capsys):
    model, clip = setup
    overlay, log = tmp_path / "o.mp4", tmp_path / "f.jsonl"
    overlay.write_bytes(b"mine\n")
    log.write_bytes(b"mine too\n")
    can_log, summary, fresh = tmp_path / "c.log", tmp_path / "s.json", tmp_path / "new" / "cam.json"
    assert _run(model, clip, "--overlay", str(overlay), "--log", str(log), "--can-log", str(can_log),
                "--summary", str(summary), "--save-calib", str(fresh)) == 2
    err = capsys.readouterr().err
    assert f"--overlay {overlay}, --log {log} exist; pass --force to replace them" in err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["f.jsonl", "o.mp4"]     # no CAN log, summary, folder
    assert overlay.read_bytes() == b"mine\n" and log.read_bytes() == b"mine too\n"


@pytest.mark.parametrize("flag,name,known", [("--overlay", "o.txt", ".mp4"), ("--log", "f.csv", ".jsonl"),
                                             ("--summary", "s.yaml", ".json"), ("--can-log", "c.txt", ".blf"),
                                             ("--save-calib", "cam", ".json")])
def test_a_suffix_the_writer_does_not_know_is_refused_and_nothing_is_written(setup, tmp_path, capsys, flag, name,
                                                                              known):
    model, clip = setup
    out = tmp_path / "new" / name
    assert _run(model, clip, flag, str(out)) == 2
    err = capsys.readouterr().err
    assert f"{flag} {out}" in err and known in err
    assert not out.exists()


def test_missing_folders_are_made_for_every_output(setup, tmp_path):
    model, clip = setup
    outs = {"--overlay": "a/o.mp4", "--log": "b/c/f.jsonl", "--summary": "d/s.json", "--can-log": "e/c.log",
            "--save-maps": "f/maps"}
    args = [x for flag, rel in outs.items() for x in (flag, str(tmp_path / rel))]
    assert _run(model, clip, *args) == 0
    for flag, rel in outs.items():
        assert (tmp_path / rel).exists(), flag
    assert json.loads((tmp_path / "d/s.json").read_text())["frames"] == 3


def _last_status(can_log):
    import can

    from bsn_edge.alerts.can_codec import decode

    msgs = [decode(m.arbitration_id, bytes(m.data)) for m in can.LogReader(str(can_log))]
    return [d.signals["System_State"] for d in msgs if d is not None and d.name == "BSN_Status"][-1]


@pytest.mark.parametrize("flag,name", [("--log", "f.jsonl"), ("--overlay", "o.mp4"), ("--save-calib", "cam.json")])
def test_an_output_under_a_file_is_refused_with_unavailable_on_the_can_log_and_the_summary(setup, tmp_path, capsys,
                                                                                          flag, name):
    """The disk refuses it (a file where its folder should be): the bus asked for (here the CAN log) hears
    UNAVAILABLE and the summary says why, as for every other refusal (once nothing was written at all)."""
    from bsn_edge.alerts import SystemState

    model, clip = setup
    (tmp_path / "file").write_text("x")
    can_log, summary = tmp_path / "c.log", tmp_path / "s.json"
    assert _run(model, clip, flag, str(tmp_path / "file" / name), "--can-log", str(can_log),
                "--summary", str(summary)) == 2
    assert "its folder cannot be made" in capsys.readouterr().err
    assert _last_status(can_log) == SystemState.UNAVAILABLE
    assert "its folder cannot be made" in json.loads(summary.read_text())["refused"]


@pytest.mark.parametrize("wrong", [("--max-frames", "0"), ("--stall", "nan"), ("--stall", "-1")])
def test_numbers_no_run_can_use_are_refused_with_unavailable_and_the_summary(setup, tmp_path, capsys, wrong):
    from bsn_edge.alerts import SystemState

    model, clip = setup
    can_log, summary = tmp_path / "c.log", tmp_path / "s.json"
    assert _run(model, clip, *wrong, "--can-log", str(can_log), "--summary", str(summary)) == 2
    named = {"--max-frames": "--max-frames", "--stall": "stall_s"}[wrong[0]]      # the flag, or the key it sets
    assert named in json.loads(summary.read_text())["refused"]
    assert _last_status(can_log) == SystemState.UNAVAILABLE


def test_the_contact_sheet_and_the_demo_keep_what_is_there_without_force(setup, tmp_path, capsys):
    _, clip = setup
    png = tmp_path / "sheet.png"
    png.write_bytes(b"mine")
    assert sheet.main([str(clip), "--out", str(png)]) == 2 and png.read_bytes() == b"mine"
    assert sheet.main([str(clip), "--out", str(tmp_path / "sheet.jpg")]) == 2
    assert sheet.main([str(clip), "--out", str(png), "--force"]) == 0 and png.read_bytes() != b"mine"
    (tmp_path / "demo").mkdir()
    (tmp_path / "demo" / "notes.txt").write_text("mine")
    assert demo.main(["--out", str(tmp_path / "demo"), "--frames", "3"]) == 2
    assert "holds files already; pass --force" in capsys.readouterr().err


def test_a_summary_that_cannot_be_written_at_the_end_fails_the_run(setup, tmp_path, capsys, monkeypatch):
    model, clip = setup
    out = tmp_path / "s.json"
    full_disk_for(out, monkeypatch)
    assert _run(model, clip, "--summary", str(out)) == 1
    err = capsys.readouterr().err
    assert f"error: cannot write the summary {out}" in err and "No space left on device" in err
    assert not out.exists()


def test_a_summary_that_cannot_be_written_after_a_stop_at_start_up_fails_too(setup, tmp_path, capsys, monkeypatch):
    """A signal before the first frame: the summary is written with the signal's code, or the run fails."""
    out = tmp_path / "early.json"
    full_disk_for(out, monkeypatch)

    def stopped_at_once(self):
        self.signal = "SIGTERM"          # TERM alone ends a run with 0: only the summary's failure makes it 1
        self.event.set()
        return self

    monkeypatch.setattr(run_cli.StopOnSignal, "__enter__", stopped_at_once)
    model, clip = setup
    assert _run(model, clip, "--summary", str(out)) == 1
    assert "cannot write the summary" in capsys.readouterr().err
    assert not out.exists()


def test_a_pipe_given_as_the_summary_is_written_into_and_stays_a_pipe(setup, tmp_path):
    import os
    import stat
    import threading

    model, clip = setup
    fifo = tmp_path / "summary.json"
    os.mkfifo(fifo)
    got: list[bytes] = []
    reader = threading.Thread(target=lambda: got.append(fifo.read_bytes()), daemon=True)
    reader.start()
    assert _run(model, clip, "--summary", str(fifo)) == 0
    reader.join(timeout=30)
    assert stat.S_ISFIFO(fifo.stat().st_mode), "the pipe was replaced by a file"
    assert json.loads(got[0])["frames"] == 3


@pytest.mark.parametrize("link", [False, True])
def test_two_outputs_naming_one_file_are_refused_and_neither_is_written(setup, tmp_path, capsys, link):
    """Neither of the two is written; the CAN log, free, hears UNAVAILABLE (the bus's last word)."""
    from bsn_edge.alerts import SystemState

    model, clip = setup
    first = tmp_path / "out.json"
    second = first
    if link:
        second = tmp_path / "other.json"
        first.write_text("")
        first.unlink()
        second.symlink_to(first)
    assert _run(model, clip, "--summary", str(first), "--save-calib", str(second), "--can-log",
                str(tmp_path / "c.log")) == 2
    assert "--summary and --save-calib both name" in capsys.readouterr().err
    assert not first.exists() and _last_status(tmp_path / "c.log") == SystemState.UNAVAILABLE


@pytest.mark.parametrize("flag,what", [("--overlay", "source"), ("--summary", "calib"), ("--summary", "model"),
                                       ("--log", "hard link to the source")])
def test_an_output_that_names_an_input_is_refused_even_with_force(setup, tmp_path, capsys, flag, what):
    """With --force the source video, the camera file and the model were once replaced by the run's outputs."""
    import os
    import shutil

    model, clip = setup
    video, calib, mine = tmp_path / "in.mp4", tmp_path / "cam.json", tmp_path / "m.onnx"
    shutil.copy(clip / "video.mp4", video)
    shutil.copy(clip / "calibration.json", calib)
    shutil.copy(model, mine)
    target = {"source": video, "calib": calib, "model": mine}.get(what)
    if target is None:                      # another name of the same file
        target = tmp_path / "also.jsonl"
        os.link(video, target)
    before = {p: p.read_bytes() for p in (video, calib, mine)}
    # the CAN log and, when it is not the culprit, the summary are free: they say why
    free = [("--can-log", tmp_path / "c.log")] + ([] if flag == "--summary" else [("--summary", tmp_path / "s.json")])
    code = run_cli.main(["--model", str(mine), "--source", str(video), "--calib", str(calib), "--max-frames", "3",
                         flag, str(target), "--force", *(x for f, p in free for x in (f, str(p)))])
    err = capsys.readouterr().err
    assert code == 2 and "an output never replaces what the run reads" in err, err
    assert {p: p.read_bytes() for p in before} == before, "an input was written"
    from bsn_edge.alerts import SystemState

    assert _last_status(tmp_path / "c.log") == SystemState.UNAVAILABLE
    if flag != "--summary":
        assert "an output never replaces" in json.loads((tmp_path / "s.json").read_text())["refused"]


def test_maps_saved_into_the_source_folder_are_refused(setup, tmp_path, capsys):
    model, clip = setup
    import shutil

    frames = tmp_path / "frames"
    shutil.copytree(clip / "rgb", frames)
    code = run_cli.main(["--model", str(model), "--source", str(frames), "--max-frames", "3", "--save-maps",
                         str(frames / "maps")])
    err = capsys.readouterr().err
    assert code == 2 and "lies in the run's --source folder" in err, err
    assert not (frames / "maps").exists()


def test_a_video_with_no_frame_is_an_error_not_a_clean_run(setup, tmp_path, capsys):
    import cv2

    model, _ = setup
    empty = tmp_path / "empty.avi"
    writer = cv2.VideoWriter(str(empty), cv2.VideoWriter.fourcc(*"MJPG"), 25.0, (192, 96))
    writer.release()                            # a header and no frame
    summary = tmp_path / "s.json"
    code = run_cli.main(["--model", str(model), "--source", str(empty), "--summary", str(summary)])
    out = capsys.readouterr()
    assert code != 0, out.out
    assert "faults: none" not in out.out or "delivered no frame" in out.err, (out.out, out.err)
    if summary.exists():
        assert json.loads(summary.read_text())["frames"] == 0
