"""The first signal decides, from the command's first instruction to its last: one caught while ``bsn-run``
imports its modules, one that interrupts a refusal, and the first of two that arrive at once (Python runs
its handlers in the order of the signals' numbers, not of their arrival)."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
import tomllib
from pathlib import Path

import pytest

from bsn_edge.cli import run as run_cli
from bsn_edge.cli.common import CHECKOUT
from tests.fakes import BUSY_S


def child(code: str, **kw) -> subprocess.Popen:
    env = {**os.environ, "PYTHONPATH": str(CHECKOUT)}
    return subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env=env, **kw)


def test_the_command_holds_the_signals_before_it_imports_the_runtime():
    """The module the installed ``bsn-run`` enters (pyproject.toml's [project.scripts]) has a handler on
    TERM before ``bsn_edge.cli.run`` and its imports load: a service manager's stop during them (a tenth
    of a second) once died from the default action, nothing on the bus."""
    entry = tomllib.loads((CHECKOUT / "pyproject.toml").read_text())["project"]["scripts"]["bsn-run"]
    module = entry.split(":")[0]
    code = ("import signal, sys\n"
            "seen = []\n"
            "def hook(event, args):\n"
            "    if event == 'import' and args[0] == 'bsn_edge.cli.run' and not seen:\n"
            "        seen.append(signal.getsignal(signal.SIGTERM) not in (signal.SIG_DFL, None))\n"
            "sys.addaudithook(hook)\n"
            f"import {module}\n"
            "print(seen)\n")
    proc = child(code)
    out, err = proc.communicate(timeout=6 * BUSY_S)
    assert proc.returncode == 0, err
    assert out.strip() == "[True]", f"{module}: TERM handled when bsn_edge.cli.run was imported: {out.strip()}"


def test_a_signal_held_during_start_up_is_the_one_the_run_ends_with():
    code = ("import os, signal\n"
            "from bsn_edge.cli.stop_signal import StopOnSignal, hold_signals\n"
            "hold_signals()\n"
            "os.kill(os.getpid(), signal.SIGTERM)\n"
            "os.kill(os.getpid(), signal.SIGHUP)\n"
            "with StopOnSignal() as s:\n"
            "    print(s.signal, s.later, s.event.is_set())\n")
    proc = child(code)
    out, err = proc.communicate(timeout=6 * BUSY_S)
    assert proc.returncode == 0 and out.split() == ["SIGTERM", "1", "True"], (proc.returncode, out, err)


def _delivered(pid: int, sig: signal.Signals) -> bool:
    """Whether ``sig`` sent to ``pid`` has left its pending set (the C-level handler has run)."""
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("ShdPnd:"):
            return not int(line.split()[1], 16) & (1 << (sig - 1))
    return True


@pytest.mark.skipif(not os.path.exists("/proc/self/status"), reason="needs /proc")
def test_term_then_int_at_once_ends_as_term():
    """TERM arrives, then INT, both while the main thread is inside one long C call, so Python runs both
    handlers after it, INT's first (its number is lower); the run must still end as the first signal asked.
    INT is sent once TERM has been delivered: two signals pending together are delivered by the kernel in
    the order of their numbers, which no process can tell from arrival (a busy machine made them so)."""
    code = ("import hashlib, sys\n"
            "from bsn_edge.cli.stop_signal import StopOnSignal\n"
            "with StopOnSignal() as s:\n"
            "    print('ready', flush=True)\n"
            "    hashlib.pbkdf2_hmac('sha256', b'k', b's', 2_000_000)\n"
            "    print(s.signal, s.later, flush=True)\n")
    proc = child(code, stdin=subprocess.DEVNULL)
    try:
        assert proc.stdout is not None and proc.stdout.readline().strip() == "ready"
        proc.send_signal(signal.SIGTERM)
        deadline = time.monotonic() + BUSY_S
        while not _delivered(proc.pid, signal.SIGTERM) and time.monotonic() < deadline:
            time.sleep(0.001)
        proc.send_signal(signal.SIGINT)
        out, err = proc.communicate(timeout=6 * BUSY_S)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 0 and out.split() == ["SIGTERM", "1"], (proc.returncode, out, err)


def test_a_signal_during_a_refused_start_decides_the_outcome(setup, tmp_path, monkeypatch):
    """TERM while the model is read, and the read then refused: the run ends as stopped by TERM (0, the
    summary naming it), not as a refusal (2, no signal)."""
    model, clip = setup

    def slow_refusal(args, cfg):
        os.kill(os.getpid(), signal.SIGTERM)
        raise ValueError(f"{args.model}: not a model")

    monkeypatch.setattr(run_cli, "_start", slow_refusal)
    summary = tmp_path / "s.json"
    code = run_cli.main(["--model", str(model), "--source", str(clip / "video.mp4"), "--summary", str(summary)])
    s = json.loads(summary.read_text())
    assert code == 0 and s["signal"] == "SIGTERM" and s["stopped"], (code, s)
