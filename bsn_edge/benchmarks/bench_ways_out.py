"""Twenty ways out of a run, tried from outside on real footage: how each one ends.

    python -m bsn_edge.benchmarks.bench_ways_out --out benchmarks/results

Each case is a real ``bsn-run`` process (the installed command's entry module, the shipped model, a real clip
from ``../shared/data/real``) with a CAN log and a summary asked for, or ``bsn-listen`` / ``bsn-report`` on a
damaged file. For each: the exit code, the last ``BSN_Status`` state decoded from the CAN log (the bus's last
word), whether the summary was written, and how long after the bus last said anything else it said
UNAVAILABLE (for a signal, after the signal was sent; "-" where nothing was on the bus). The bar: rc 2
before the first frame or UNAVAILABLE as the bus's last word, the summary written (where one can be), nothing
of the user's overwritten. Case numbers are those of the issue that listed them.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import cv2

from bsn_edge.alerts import SystemState
from bsn_edge.alerts.can_codec import decode
from bsn_edge.alerts.can_log import read_log
from bsn_edge.cli.common import CHECKOUT

from .real_samples import REAL
from .runner import Report, run

CLIP = REAL / "udacity_test_video.mp4"
ENTRY = "bsn_edge.cli.run_main"          # what the installed bsn-run runs
DEADLINE_S = 120.0


@dataclass
class Outcome:
    rc: int | None
    last_state: str
    summary: str                # "written", "written (refused)", "none", "-" (the tool writes none)
    to_unavailable_s: float | None
    note: str = ""


@dataclass
class Case:
    n: int
    what: str
    argv: Callable[[Path], list[str]]                       # bsn-run's flags, given the case's folder
    during: Callable[[subprocess.Popen, Path], float | None] | None = None   # returns when a signal was sent
    stderr_to: str | None = None                             # a path stderr goes to (/dev/full)
    stdout_to: str | None = None
    check: Callable[[Path], str] = field(default=lambda _d: "")          # a note on what is left


def bus(can_log: Path) -> list[tuple[float, str]]:
    """``(time, state)`` of every status frame of the CAN log."""
    if not can_log.exists():
        return []
    out = []
    for f in read_log(can_log, lambda where, why: None):
        d = decode(f.frame_id, f.data)
        if d is not None and d.name == "BSN_Status" and d.crc_ok:
            out.append((f.timestamp, SystemState(d.signals["System_State"]).name))
    return out


def to_unavailable(states: list[tuple[float, str]], sent: float | None) -> float | None:
    """Seconds from the signal (``sent``), else from the bus's last other word, to the final UNAVAILABLE."""
    if not states or states[-1][1] != "UNAVAILABLE":
        return None
    k = len(states) - 1
    while k > 0 and states[k - 1][1] == "UNAVAILABLE":
        k -= 1
    if sent is not None:
        return round(max(0.0, states[k][0] - sent), 3)
    return 0.0 if k == 0 else round(states[k][0] - states[k - 1][0], 3)


def bsn_run(case: Case, folder: Path) -> Outcome:
    can_log, summary = folder / "bus.log", folder / "summary.json"
    argv = [sys.executable, "-m", ENTRY, *case.argv(folder), "--can-log", str(can_log), "--summary", str(summary)]
    env = {**os.environ, "PYTHONPATH": str(CHECKOUT)}
    with open(case.stdout_to or os.devnull, "w") as out, open(case.stderr_to or folder / "stderr.txt", "w") as err:
        proc = subprocess.Popen(argv, stdout=out, stderr=err, env=env, cwd=folder)
        try:
            sent = case.during(proc, folder) if case.during else None
            proc.wait(DEADLINE_S)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()
        finally:
            note = case.check(folder)           # a mounted disk is let go, whatever happened
    states = bus(can_log)
    said = ""
    if summary.exists():
        try:
            s = json.loads(summary.read_text())
            said = "written" + (f" (refused: {s['refused'][:70]})" if s.get("refused") else
                                f" (signal {s['signal']})" if s.get("signal") else "")
        except (ValueError, KeyError):
            said = "damaged"
    return Outcome(proc.returncode, states[-1][1] if states else "nothing", said or "none",
                   to_unavailable(states, sent), note)


def frames_folder(folder: Path, n: int = 30) -> Path:
    """The clip's first ``n`` frames as JPEGs in ``folder/frames``."""
    out = folder / "frames"
    out.mkdir(exist_ok=True)
    cap = cv2.VideoCapture(str(CLIP))
    for i in range(n):
        ok, img = cap.read()
        if not ok:
            break
        cv2.imwrite(str(out / f"{i:06d}.jpg"), img)
    cap.release()
    return out


def signal_after(seconds: float, *signals: signal.Signals) -> Callable[[subprocess.Popen, Path], float]:
    def during(proc: subprocess.Popen, _folder: Path) -> float:
        time.sleep(seconds)
        sent = time.time()
        for sig in signals:
            proc.send_signal(sig)
        return sent
    return during


def when_log_has(lines: int, then: Callable[[subprocess.Popen, Path], float | None]):
    """Wait until the CAN log holds ``lines`` frames, then ``then``."""
    def during(proc: subprocess.Popen, folder: Path) -> float | None:
        log = folder / "bus.log"
        t0 = time.monotonic()
        while proc.poll() is None and time.monotonic() - t0 < DEADLINE_S:
            if log.exists() and log.read_text().count("\n") >= lines:
                return then(proc, folder)
            time.sleep(0.02)
        return None
    return during


def _fifo_in_folder(d: Path) -> list[str]:
    f = frames_folder(d)
    os.mkfifo(f / "000000_fifo.jpg")
    return ["--source", str(f)]


def _dev_zero_picture(d: Path) -> list[str]:
    f = frames_folder(d)
    os.symlink("/dev/zero", f / "000003_zero.jpg")
    with open(f / "000005_huge.jpg", "wb") as h:
        h.truncate(8 << 30)
    return ["--source", str(f)]


def _mjpeg(d: Path) -> list[str]:
    jpgs = sorted(frames_folder(d).iterdir())
    parts = []
    for i, p in enumerate(jpgs):
        img = cv2.imread(str(p))
        assert img is not None, p
        parts.append(cv2.imencode(".jpg", img.transpose(1, 0, 2).copy() if 10 <= i < 15 else img)[1].tobytes())
    (d / "drive.mjpeg").write_bytes(b"".join(parts))
    return ["--source", str(d / "drive.mjpeg")]


def _deep_settings(d: Path) -> list[str]:
    (d / "v.toml").write_text("[runtime]\ncycle_s = " + "9" * 400 + "\n")
    return ["--source", str(CLIP), "--config", str(d / "v.toml")]


def _overlay_is_source(d: Path) -> list[str]:
    shutil.copy(CLIP, d / "drive.mp4")
    return ["--source", str(d / "drive.mp4"), "--overlay", str(d / "drive.mp4"), "--force"]


def _same_size(d: Path) -> str:
    return "the source kept" if (d / "drive.mp4").stat().st_size == CLIP.stat().st_size else "THE SOURCE CHANGED"


def _tiny_video(d: Path) -> list[str]:
    import numpy as np

    out = cv2.VideoWriter(str(d / "tiny.avi"), cv2.VideoWriter.fourcc(*"MJPG"), 10.0, (12, 10))
    for _ in range(3):
        out.write(np.full((10, 12, 3), 80, np.uint8))
    out.release()
    return ["--source", str(d / "tiny.avi")]


def _fifo_mid_run(d: Path) -> list[str]:
    return ["--source", str(frames_folder(d, 38)), "--pace"]       # 3.8 s at 10 pictures a second


def _replace_with_fifo(proc: subprocess.Popen, folder: Path) -> float | None:
    victim = folder / "frames" / "000030.jpg"                       # read at 3.0 s
    victim.unlink()
    os.mkfifo(victim)
    return signal_after(3.3, signal.SIGTERM)(proc, folder)


def _no_frame_avi(d: Path) -> list[str]:
    out = cv2.VideoWriter(str(d / "empty.avi"), cv2.VideoWriter.fourcc(*"MJPG"), 10.0, (640, 360))
    out.release()
    return ["--source", str(d / "empty.avi")]


def _huge_model(d: Path) -> list[str]:
    with open(d / "big.onnx", "wb") as f:      # under the 512 MB budget: read whole, then refused
        f.truncate(400 << 20)
    return ["--model", str(d / "big.onnx"), "--source", str(CLIP)]


def _maps_into_source(d: Path) -> list[str]:
    f = frames_folder(d)
    return ["--source", str(f), "--save-maps", str(f / "maps")]


def _paced_folder(d: Path) -> list[str]:
    return ["--source", str(frames_folder(d)), "--pace"]


def _seconds(d: Path) -> str:
    s = json.loads((d / "summary.json").read_text())
    return f"{s['frames']} frames in {s['seconds']:.1f} s"


def _log_under_a_file(d: Path) -> list[str]:
    (d / "file").write_text("x")
    return ["--source", str(CLIP), "--log", str(d / "file" / "f.jsonl")]


HIGHWAY = REAL / "dashcam_highway.mp4"      # online calibration converges on it (frame 82 of 221)


def _save_calib_on_a_disk_that_fills(d: Path) -> list[str]:
    disk = d / "disk"
    disk.mkdir()
    subprocess.run(["mount", "-t", "tmpfs", "-o", "size=256k", "tmpfs", str(disk)], check=True, capture_output=True)
    return ["--source", str(HIGHWAY), "--save-calib", str(disk / "cam.json")]


def _fill(proc: subprocess.Popen, folder: Path) -> None:
    try:                                                   # the run has started: its disk fills up
        with open(folder / "disk" / "filler", "wb") as f:
            while True:
                f.write(b"\0" * 4096)
                f.flush()
    except OSError:
        pass
    return None


def _unmount(d: Path) -> str:
    saved = (d / "disk" / "cam.json").exists()
    subprocess.run(["umount", str(d / "disk")], capture_output=True)
    summary = d / "summary.json"
    failure = json.loads(summary.read_text()).get("sinks", {}).get("camera file") if summary.exists() else None
    return ("camera file saved" if saved else "") + (f"camera file failed at frame {failure['failure']['frame']}"
                                                     if failure else "")


CASES = [
    Case(1, "a FIFO named *.jpg in the source folder", _fifo_in_folder),
    Case(2, "a picture linked to /dev/zero and an 8 GB sparse picture in the folder", _dev_zero_picture),
    Case(3, "an MJPEG file whose pictures 10-14 are portrait", _mjpeg),
    Case(4, "a 400-digit integer in the vehicle file", _deep_settings),
    Case(5, "--overlay names --source, with --force", _overlay_is_source, check=_same_size),
    Case(6, "--save-calib on a disk that fills up before calibration converges (the dashcam highway)",
         _save_calib_on_a_disk_that_fills, during=when_log_has(4, _fill), check=_unmount),
    Case(7, "stderr on a full disk", lambda d: ["--source", str(CLIP), "--max-frames", "60"], stderr_to="/dev/full"),
    Case(7, "stdout on a full disk", lambda d: ["--source", str(CLIP), "--max-frames", "60"], stdout_to="/dev/full"),
    Case(8, "a 12x10 video", _tiny_video),
    Case(9, "a picture replaced by a FIFO mid-run, then SIGTERM after it", _fifo_mid_run,
         during=when_log_has(2, _replace_with_fifo)),
    Case(10, "--log under a file (a file where its folder should be)", _log_under_a_file),
    Case(10, "--stall nan", lambda d: ["--source", str(CLIP), "--stall", "nan"]),
    Case(10, "--max-frames 0", lambda d: ["--source", str(CLIP), "--max-frames", "0"]),
    Case(13, "an AVI with no frame", _no_frame_avi),
    Case(14, "SIGTERM while a 400 MB non-model is read", _huge_model, during=signal_after(0.5, signal.SIGTERM)),
    Case(15, "--save-maps into the source folder", _maps_into_source),
    Case(17, "SIGTERM 0.12 s after the process starts", lambda d: ["--source", str(CLIP)],
         during=signal_after(0.12, signal.SIGTERM)),
    Case(19, "--pace on a folder of 30 pictures (3 s at 10 a second)", _paced_folder, check=_seconds),
    Case(20, "TERM then INT at once, mid-run (the highway clip)", lambda d: ["--source", str(HIGHWAY), "--pace"],
         during=when_log_has(20, signal_after(0.0, signal.SIGTERM, signal.SIGINT))),
]


def blf_after_kill(folder: Path) -> dict[str, Any]:
    """Case 12: SIGKILL 6 s into a paced run of the highway clip (8.8 s) with a .blf CAN log; the frames left
    in it against the frames a candump log beside it (flushed every cycle) holds at the same moment."""
    import can

    log = folder / "bus.blf"
    env = {**os.environ, "PYTHONPATH": str(CHECKOUT)}
    proc = subprocess.Popen([sys.executable, "-m", ENTRY, "--source", str(HIGHWAY), "--pace", "--can-log", str(log)],
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=env)
    time.sleep(6.0)
    proc.kill()
    proc.wait()
    frames = sum(1 for _ in can.BLFReader(str(log))) if log.exists() else 0
    return {"n": 12, "what": "SIGKILL 6 s into a paced run (the highway clip), CAN log in BLF", "rc": proc.returncode,
            "last_state": "-", "summary": "- (killed)", "to_unavailable_s": None,
            "note": f"{frames} frames in the BLF log (the bus sends 2 a cycle, 10 cycles a second)"}


def tool(n: int, what: str, argv: list[str], note: Callable[[subprocess.CompletedProcess], str]) -> dict[str, Any]:
    r = subprocess.run([sys.executable, "-m", *argv], capture_output=True, text=True, timeout=DEADLINE_S,
                       env={**os.environ, "PYTHONPATH": str(CHECKOUT)})
    return {"n": n, "what": what, "rc": r.returncode, "last_state": "-", "summary": "-", "to_unavailable_s": None,
            "note": note(r) + (" TRACEBACK" if "Traceback" in r.stderr else "")}


def others(folder: Path) -> list[dict[str, Any]]:
    """Cases 11, 16 and 18: the readers of a run's files, on damaged ones."""
    ok = folder / "ok"
    ok.mkdir()
    subprocess.run([sys.executable, "-m", ENTRY, "--source", str(CLIP), "--max-frames", "40", "--log",
                    str(ok / "f.jsonl"), "--can-log", str(ok / "c.log"), "--summary", str(ok / "s.json")],
                   capture_output=True, env={**os.environ, "PYTHONPATH": str(CHECKOUT)}, check=True)
    deep = ok / "f.jsonl"
    deep.write_text(deep.read_text() + "[" * 5000 + "]" * 5000 + "\n")
    lines = (ok / "c.log").read_text().splitlines()
    silent = ok / "silent.log"          # 5 s of silence in the middle: every later frame 5 s later
    silent.write_text("\n".join(ln if i < len(lines) // 2 else ln.replace(
        ln.split(")")[0][1:], f"{float(ln.split(')')[0][1:]) + 5.0:.6f}") for i, ln in enumerate(lines)) + "\n")
    padded = ok / "padded.log"
    padded.write_bytes((ok / "c.log").read_bytes() + b"\0" * 5000 + os.urandom(3000) + b"\n")
    return [
        tool(11, "bsn-report on a frame log with a line nested 5,000 deep",
             ["bsn_edge.cli.report", str(ok / "f.jsonl"), "--out", str(ok / "r1")],
             lambda r: "report written" if (ok / "r1" / "report.html").exists() else "NO REPORT"),
        tool(16, "bsn-listen on a CAN log with 5 s of silence",
             ["bsn_edge.cli.listen", "--can-log", str(silent)],
             lambda r: next((ln.strip() for ln in (r.stdout + r.stderr).splitlines() if "silence" in ln),
                            "no word of it")),
        tool(18, "bsn-report --can-log on a log with NUL padding and random bytes",
             ["bsn_edge.cli.report", str(ok / "f.jsonl"), "--can-log", str(padded), "--out", str(ok / "r2")],
             lambda r: ("report written" if (ok / "r2" / "report.html").exists() else "NO REPORT")
             + "; " + (r.stdout + r.stderr).strip().splitlines()[-1][:80]),
    ]


def measure(args: argparse.Namespace, _p: argparse.ArgumentParser) -> Report | None:
    if not CLIP.exists():
        print(f"no real clip at {CLIP}: nothing to measure")
        return None
    rows: list[dict[str, Any]] = []
    with tempfile.TemporaryDirectory() as tmp:
        for k, case in enumerate(CASES):
            d = Path(tmp) / f"case{k}"
            d.mkdir()
            o = bsn_run(case, d)
            rows.append({"n": case.n, "what": case.what, **vars(o)})
            print(f"{case.n:>2} {case.what}: rc {o.rc}, {o.last_state}, summary {o.summary}", flush=True)
        d = Path(tmp) / "blf"
        d.mkdir()
        rows.append(blf_after_kill(d))
        d = Path(tmp) / "readers"
        d.mkdir()
        rows.extend(others(d))
    rows.sort(key=lambda r: r["n"])
    md = ["# Ways out of a run: how each ends", "",
          f"`bsn-run` (`python -m {ENTRY}`, the shipped model, `{CLIP.name}` or its first frames) with a CAN log "
          "and a summary; the last state is the last `BSN_Status` decoded from the CAN log; seconds to "
          "UNAVAILABLE from the signal, else from the bus's last other word (0: UNAVAILABLE was its only word).", "",
          "| # | case | rc | bus's last word | summary | s to UNAVAILABLE | note |", "|---|---|---|---|---|---|---|"]
    for r in rows:
        t = "-" if r["to_unavailable_s"] is None else f"{r['to_unavailable_s']:.2f}"
        md.append(f"| {r['n']} | {r['what']} | {r['rc']} | {r['last_state']} | {r['summary']} | {t} | {r['note']} |")
    return Report({"rows": rows}, md, [f"{len(rows)} cases"])


def parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--out", default="benchmarks/results")
    p.add_argument("--name", default="ways_out", help="the report's name in --out")
    return p


def main(argv: list[str] | None = None) -> int:
    return run(measure, parser(), argv)


if __name__ == "__main__":
    raise SystemExit(main())
