"""A drive's report written: ``DIR/report.html`` (self-contained) and ``DIR/report.json`` (every number it shows)."""

from __future__ import annotations

import json
import shutil
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import Any

from bsn_edge.report.drive import read_drive

REPORT_FILES = ("report.html", "report.json")


def make_report(log: str | Path, out: str | Path, summary: str | Path | None = None,
                overlay: str | Path | None = None, can_log: str | Path | None = None, force: bool = False,
                say: Callable[[str], Any] = print) -> dict[str, Any]:
    """Read the run (``log`` and ``summary``), draw it, check the bus (``can_log``) and cut the onsets'
    thumbnails (``overlay``); write ``out``/report.html and report.json, returned. ``out`` is refused when it
    exists unless ``force`` (then only the report's two files are replaced); nothing is written until the
    report is whole. ``say`` is told each step."""
    from bsn_edge.report.can_check import check, check_cycles, read_bus
    from bsn_edge.report.page import MAX_THUMBS, latency_histogram, page, thumbnails, timelines

    out = Path(out)
    if out.exists() and not force:
        raise FileExistsError(f"{out} exists; pass --force to replace its report")
    for what, path in (("overlay", overlay), ("CAN log", can_log)):
        if path is not None and not Path(path).is_file():
            raise FileNotFoundError(f"{what} {path} not found")
    say(f"reading {log}" + (f" and {summary}" if summary else ""))
    drive = read_drive(log, summary)
    if drive.damage:
        first = drive.damage[0]
        say(f"{len(drive.damage)} damaged line(s) in {log}, the first at line {first.line}: {first.why}; "
            "the rest is reported")
    try:
        record = drive.to_dict()
    except (AttributeError, TypeError, KeyError) as e:     # a summary of the wrong shape: named, not a crash
        raise ValueError(f"{summary}: not a run's summary ({type(e).__name__}: {str(e)[:80]})") from None
    if can_log is not None:
        say(f"checking the bus: {can_log}")
        bus = read_bus(can_log, drive.names)
        onsets, cycles = check(drive.onsets, bus.onsets, bus.statuses, bus.start, drive.names), \
            check_cycles(drive.records, bus.cycles, bus.start)
        record["bus_check"] = {**onsets, "agree": onsets["agree"] and not cycles["disagree"], "cycles": cycles,
                               "hazard_frames": bus.hazard_frames, "damaged_frames": bus.damaged,
                               "unreadable": bus.unreadable}
        if bus.damaged or bus.unreadable:
            say(f"the CAN log has damaged frames ({', '.join(f'{n} {k}' for k, n in bus.damaged.items())})"
                + (f"; {bus.unreadable}" if bus.unreadable else "") + ": counted, never taken as onsets")
    say(f"drawing {len(drive.records)} frames")
    picture, histogram = timelines(drive), latency_histogram(drive)
    record["cpu"] = drive.summary.get("cpu") or {}
    thumbs = {}
    if overlay is not None:
        say(f"cutting {min(len(drive.onsets), MAX_THUMBS)} onset thumbnails from {overlay}")
        thumbs = thumbnails(overlay, drive.onsets)
    try:
        html = page(drive, record, picture, thumbs, f"bsn-run drive report: {Path(log).name}", histogram)
    except (AttributeError, TypeError, KeyError) as e:
        raise ValueError(f"{summary}: not a run's summary ({type(e).__name__}: {str(e)[:80]})") from None
    out.parent.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(dir=out.parent) as tmp:
        (Path(tmp) / "report.html").write_text(html, encoding="utf-8")
        (Path(tmp) / "report.json").write_text(json.dumps(record, indent=1) + "\n", encoding="utf-8")
        out.mkdir(exist_ok=True)
        for name in REPORT_FILES:
            shutil.move(str(Path(tmp) / name), out / name)
    say(f"wrote {out / 'report.html'} and report.json: {len(drive.onsets)} onsets, {len(drive.damage)} damaged lines")
    return record
