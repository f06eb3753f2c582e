"""``bsn-report``: see a run of ``bsn-run`` instead of reading its JSON."""

from __future__ import annotations

import argparse
import sys

from bsn_edge.cli.common import fail

PROG = "bsn-report"
INSTALL = "pip install 'bsn-edge[report]' (or [full]; from a clone: pip install -c constraints.txt -e \".[report]\")"


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog=PROG,
        description="Make one self-contained page of a bsn-run drive (DIR/report.html, pictures embedded, "
                    "opens from a file in any browser) and the numbers behind it (DIR/report.json): per sector "
                    "the score, level and distance over time against the CAUTION and WARNING thresholds; the "
                    "system state and the faults; each stage's latency per frame with p50/p95/p99; when "
                    "calibration converged; one thumbnail per level onset from the overlay; the run's model, "
                    "settings, source and machine. With --can-log the bus is checked against the frame log. "
                    "Needs matplotlib ([report] or [full] extra).")
    p.add_argument("log", metavar="LOG.jsonl", help="the run's frame log (bsn-run --log)")
    p.add_argument("--summary", metavar="S.json", help="the run's summary (bsn-run --summary): calibration, "
                                                        "identity and thresholds")
    p.add_argument("--overlay", metavar="O.mp4", help="the run's overlay video (bsn-run --overlay): a thumbnail "
                                                       "of each level onset")
    p.add_argument("--can-log", metavar="CAN.log", help="the run's CAN log (bsn-run --can-log: .log, .asc, .blf): "
                                                         "its onsets checked against the frame log's")
    p.add_argument("--out", required=True, metavar="DIR", help="folder of the report (refused if it exists)")
    p.add_argument("--force", action="store_true", help="replace the report in an existing --out")
    return p


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        import matplotlib  # noqa: F401
    except ModuleNotFoundError:
        return fail(PROG, f"it draws with matplotlib, which is not installed: {INSTALL}")
    from bsn_edge.report import make_report

    try:
        record = make_report(args.log, args.out, args.summary, args.overlay, args.can_log, args.force,
                             say=lambda s: print(f"{PROG}: {s}", file=sys.stderr, flush=True))
    except (FileNotFoundError, FileExistsError, ValueError) as e:
        return fail(PROG, str(e))
    check = record.get("bus_check")
    if check is not None and not check["agree"]:
        cycles = check.get("cycles") or {}
        first = (check["disagreements"] or cycles.get("disagreements") or [{}])[0]
        where = f" (the first at {first['t_s']:.2f} s: {first['why']})" if first else ""
        print(f"{PROG}: the bus and the frame log disagree: {len(check['disagreements'])} onset(s), "
              f"{cycles.get('disagree', 0)} cycle(s){where}; the report shows each", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
