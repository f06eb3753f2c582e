"""Outputs that block (a FIFO nobody reads stands in for a hung disk or network mount) and signals at
any moment: the loop and the bus go on, the status says DEGRADED within a second, SIGTERM ends the run
within a second with UNAVAILABLE last. The CAN log is decoded with cantools from the shipped DBC."""

import ast
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import cantools
import pytest

from bsn_edge.alerts.can_codec import DBC_PATH
from bsn_edge.cli.common import CHECKOUT
from tests.fakes import BUSY_S, long_video


def env() -> dict[str, str]:
    return {**os.environ, "PYTHONPATH": str(CHECKOUT)}


def bsn_run(*argv: str) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "bsn_edge.cli.run", *argv], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, env=env(), text=True)


def statuses(can_log: Path) -> list[tuple[float, dict]]:
    """(time, signals) of every BSN_Status frame in a candump log, decoded by cantools."""
    import can
    db = cantools.database.load_file(str(DBC_PATH))
    return [(m.timestamp, db.decode_message(m.arbitration_id, bytes(m.data), decode_choices=False))
            for m in can.LogReader(str(can_log)) if m.arbitration_id == db.get_message_by_name("BSN_Status").frame_id]


def wait_for(cond, seconds: float = 60.0) -> None:
    deadline = time.monotonic() + seconds
    while not cond() and time.monotonic() < deadline:
        time.sleep(0.02)


@pytest.mark.parametrize("output", ["--log", "--overlay"])
def test_an_output_that_blocks_when_opened_degrades_and_sigterm_still_ends_the_run(setup, tmp_path, output):
    model, clip = setup
    video = long_video(clip, tmp_path / "long.mp4", 20)       # 300 frames, 30 s paced
    fifo = tmp_path / ("out.jsonl" if output == "--log" else "out.mp4")
    os.mkfifo(fifo)
    can_log, summ = tmp_path / "bus.log", tmp_path / "s.json"
    proc = bsn_run("--model", str(model), "--source", str(video), "--pace", "--calib", str(clip / "calibration.json"),
                   output, str(fifo), "--can-log", str(can_log), "--summary", str(summ))
    try:
        # the loop and the bus go on: frames keep coming on the CAN log with the FIFO still unread
        wait_for(lambda: can_log.exists() and sum(1 for _ in statuses(can_log)) >= 25)
        got = statuses(can_log)
        assert len(got) >= 25, f"the bus stopped: {len(got)} status frames ({proc.poll()})"
        first = got[0][0]
        degraded = [t for t, s in got if s["System_State"] == 1 and s["Sink_Errors"] == 1]
        assert degraded and degraded[0] - first <= BUSY_S, f"DEGRADED {degraded[:1]} s after the first status {first}"
        # and never OK again; a stall's UNAVAILABLE may come between on a busy machine
        after = [s["System_State"] for t, s in got if t > degraded[0]]
        assert set(after) <= {1, 2}, f"states after DEGRADED: {after}"
        t0 = time.monotonic()
        proc.send_signal(signal.SIGTERM)
        _, err = proc.communicate(timeout=30)
        ended = time.monotonic() - t0
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 0 and "Traceback" not in err, err
    assert ended < BUSY_S, f"SIGTERM took {ended:.2f} s to end the run"
    assert statuses(can_log)[-1][1]["System_State"] == 2, "UNAVAILABLE last"
    failure = json.loads(summ.read_text())["sinks"]["log" if output == "--log" else "overlay"]["failure"]
    assert failure["frame"] is None and "stuck in opening it" in failure["error"]
    assert "failed when it was opened" in err


def test_a_can_log_that_blocks_when_opened_is_refused_within_a_second(setup, tmp_path):
    model, clip = setup
    fifo = tmp_path / "bus.log"
    os.mkfifo(fifo)
    t0 = time.monotonic()
    proc = bsn_run("--model", str(model), "--source", str(clip / "video.mp4"), "--can-log", str(fifo))
    try:
        _, err = proc.communicate(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 2 and "did not open within 1 s" in err and str(fifo) in err, err
    assert time.monotonic() - t0 < 30


def test_signals_are_watched_before_the_runtime_is_imported():
    """``bsn-run``'s module imports nothing outside the standard library and the project's light helpers
    before ``main`` installs its handlers: a signal while the runtime's modules load is handled."""
    code = ("import sys; before = set(sys.modules); import bsn_edge.cli.run; "
            "print(sorted(m.split('.')[0] for m in set(sys.modules) - before))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env(), check=True).stdout
    third_party = {m for m in ast.literal_eval(out) if m not in sys.stdlib_module_names and not m.startswith(
        ("bsn_edge", "__editable__"))}
    assert not third_party, f"imported before the handlers: {sorted(third_party)}"
    tree = ast.parse((CHECKOUT / "bsn_edge" / "cli" / "run.py").read_text())
    main = next(n for n in tree.body if isinstance(n, ast.FunctionDef) and n.name == "main")
    first = main.body[0]
    assert isinstance(first, ast.With) and ast.unparse(first.items[0].context_expr).startswith("StopOnSignal(")


def caught(pid: int) -> int:
    """The signals a process has handlers for (its SigCgt mask)."""
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("SigCgt:"):
            return int(line.split()[1], 16)
    return 0


@pytest.mark.skipif(not Path("/proc/self/status").exists(), reason="needs /proc")
@pytest.mark.parametrize(("sig", "code"), [(signal.SIGTERM, 0), (signal.SIGINT, 130), (signal.SIGHUP, 129),
                                           (signal.SIGQUIT, 131)])
def test_a_signal_as_soon_as_it_is_watched_ends_start_up_cleanly(setup, tmp_path, sig, code):
    model, clip = setup
    proc = bsn_run("--model", str(model), "--source", str(clip / "video.mp4"), "--can-log", str(tmp_path / "c.log"))
    try:
        # Python itself catches SIGINT from its start (KeyboardInterrupt); SIGTERM is caught once main()
        # watches both, which is the moment this test looks for
        bit = 1 << (signal.SIGTERM - 1)
        wait_for(lambda: proc.poll() is not None or caught(proc.pid) & bit, 30)
        t0 = time.monotonic()
        proc.send_signal(sig)
        _, err = proc.communicate(timeout=30)
        ended = time.monotonic() - t0
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == code and "Traceback" not in err, err
    assert ended < BUSY_S, f"{sig.name} took {ended:.2f} s to end the run"
