"""What a refactor must leave unchanged, as digests: ``record`` runs the labeller and the runtime and
writes what they produced; ``compare`` says what differs between two records.

    .venv/bin/python .ci/behaviour.py record before.json     # on the code before the change
    .venv/bin/python .ci/behaviour.py record after.json      # and after it
    .venv/bin/python .ci/behaviour.py compare before.json after.json

Recorded: every file ``bsn-label`` writes for a synthetic clip (byte for byte; its report without
the seconds it took); ``bsn-run`` with the
shipped model on the real highway clip, calibrating online: its saved maps (byte for byte), every CAN
frame of its log decoded with cantools (all signals but ``Frame_Rate``, which is measured, and
the status CRC, which covers it; no timestamps) and its frame log (all fields but ``latency_ms``).
The real clip lies beside the checkout (``../shared/data/real``); without it the runtime part is left out and said so.
"""

from __future__ import annotations

import hashlib
import json
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
BIN = Path(sys.executable).parent
HIGHWAY = ROOT.parent / "shared" / "data" / "real" / "dashcam_highway.mp4"
MODEL = ROOT / "bsn_edge" / "default_model" / "bsn_shared_light_int8.onnx"
MEASURED_SIGNALS = ("Frame_Rate", "Status_CRC")    # the rate is measured, and the status CRC covers it
MEASURED_KEYS = ("seconds",)                        # how long the labeller took, in its report


def without_measured(path: Path, work: Path) -> bytes:
    """A file's bytes; for a JSON report, with the measured keys taken out and the work folder's path
    (a new temporary one each time) written ``<work>``."""
    if path.suffix != ".json":
        return path.read_bytes()

    def drop(x):
        if isinstance(x, dict):
            return {k: drop(v) for k, v in x.items() if k not in MEASURED_KEYS}
        return [drop(v) for v in x] if isinstance(x, list) else x
    return json.dumps(drop(json.loads(path.read_text().replace(str(work), "<work>"))), sort_keys=True).encode()


def files_digest(folder: Path) -> dict[str, str]:
    return {str(p.relative_to(folder)): hashlib.sha256(without_measured(p, folder.parent)).hexdigest()
            for p in sorted(folder.rglob("*")) if p.is_file()}


def run(*argv: str) -> None:
    subprocess.run([str(BIN / argv[0]), *argv[1:]], check=True, stdout=subprocess.DEVNULL)


def record(out: Path) -> None:
    import can
    import cantools

    from bsn_edge.alerts.can_codec import DBC_PATH

    rec: dict = {}
    with tempfile.TemporaryDirectory() as tmp:
        clip = Path(tmp) / "clip"
        run("bsn-synth", str(clip), "--frames", "40", "--size", "128x256", "--style", "town", "--seed", "3",
            "--no-video")
        before = set(files_digest(clip))
        run("bsn-label", str(clip), "--T", "2", "--jobs", "1")
        rec["labels"] = {k: v for k, v in files_digest(clip).items() if k not in before}
        if HIGHWAY.is_file():
            maps, log, jsonl = Path(tmp) / "maps", Path(tmp) / "bus.log", Path(tmp) / "frames.jsonl"
            run("bsn-run", "--model", str(MODEL), "--source", str(HIGHWAY), "--save-maps", str(maps),
                "--can-log", str(log), "--log", str(jsonl))
            rec["maps"] = files_digest(maps)
            db = cantools.database.load_file(str(DBC_PATH))
            frames = []
            for m in can.LogReader(str(log)):
                sig = db.decode_message(m.arbitration_id, bytes(m.data), decode_choices=False)
                frames.append([m.arbitration_id, {k: v for k, v in sig.items() if k not in MEASURED_SIGNALS}])
            rec["can_frames"] = frames
            rec["frame_log"] = [{k: v for k, v in json.loads(x).items() if k != "latency_ms"}
                                for x in jsonl.read_text().splitlines()]
        else:
            rec["runtime"] = f"left out: {HIGHWAY} not found"
    out.write_text(json.dumps(rec, indent=0) + "\n")
    print(f"wrote {out}: {len(rec['labels'])} label files, {len(rec.get('maps', {}))} maps, "
          f"{len(rec.get('can_frames', []))} CAN frames, {len(rec.get('frame_log', []))} frame-log lines")


def compare(a: Path, b: Path) -> int:
    ra, rb = json.loads(a.read_text()), json.loads(b.read_text())
    bad = 0
    for key in sorted(set(ra) | set(rb)):
        same = ra.get(key) == rb.get(key)
        bad += not same
        size = len(ra.get(key) or ())
        print(f"{key}: {'identical' if same else 'DIFFERENT'} ({size} items)")
    return 1 if bad else 0


def main(argv: list[str] | None = None) -> int:
    args = sys.argv[1:] if argv is None else argv
    if len(args) == 2 and args[0] == "record":
        record(Path(args[1]))
        return 0
    if len(args) == 3 and args[0] == "compare":
        return compare(Path(args[1]), Path(args[2]))
    print(__doc__, file=sys.stderr)
    return 2


if __name__ == "__main__":
    raise SystemExit(main())
