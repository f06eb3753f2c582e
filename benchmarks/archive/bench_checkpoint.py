"""A training checkpoint's state file: written and read as bsn-train does, against its earlier form.

    python -m benchmarks.archive.bench_checkpoint --out benchmarks/results [--model shared-light]

A run's ``state.pt`` holds the weights (``model.pt``'s exact bytes, with their sha256) next to the
optimizer's state, so a kill between the two files never leaves them disagreeing. It used to hold
the weights as a byte string inside ``torch.save``'s pickle (protocol 2, which re-encodes bytes),
built whole in memory, then written; it now holds them as a uint8 tensor, a record of the file's
own, streamed to the file. Both forms, in one run, alternating, for the architecture's weights and
the Adam state of one step: seconds to write (with the atomic rename) and to read back and verify
(:meth:`Run.load_state`, which reads both), and the file's size.
"""

from __future__ import annotations

import argparse
import hashlib
import io
import statistics
import tempfile
import time
from pathlib import Path
from typing import Any

import torch

from bsn_edge.models import create_model, weights_bytes
from bsn_edge.sequence.images import atomic_write_bytes
from bsn_edge.train.run import Run, _write_state

from ..common import class_name, write_result

ROUNDS = 7


def _earlier_write(path: Path, data: bytes, sha: str, resume_state: dict[str, Any]) -> None:
    buf = io.BytesIO()
    torch.save({**resume_state, "weights": data, "weights_sha256": sha}, buf)
    atomic_write_bytes(path, buf.getvalue())


def run(model_name: str, rounds: int = ROUNDS) -> dict[str, Any]:
    torch.manual_seed(0)
    model = create_model(model_name)
    opt = torch.optim.Adam(model.parameters())
    logits, depth, _ = model(torch.randn(2, 3, 64, 128))
    (logits.mean() + depth.mean()).backward()
    opt.step()
    resume = {"optimizer": {"optimizer": opt.state_dict()}, "step": 1}
    data = weights_bytes(model)
    sha = hashlib.sha256(data).hexdigest()
    times: dict[str, dict[str, list[float]]] = {k: {"write": [], "read": []} for k in ("earlier", "current")}
    with tempfile.TemporaryDirectory() as tmp:
        earlier, current = Run(Path(tmp) / "earlier"), Run(Path(tmp) / "current")
        for r in (earlier, current):
            r.path.mkdir()
            atomic_write_bytes(r.model_path, data)
        # Run.load_state reads both forms: the earlier one's read is what it always was
        forms = {"earlier": (lambda: _earlier_write(earlier.state_path, data, sha, resume), earlier.load_state),
                 "current": (lambda: _write_state(current.state_path, data, sha, resume), current.load_state)}
        for k in range(rounds + 1):                   # the first round warms up and is not counted
            for name, (write, read) in forms.items():
                t0 = time.perf_counter()
                write()
                t1 = time.perf_counter()
                got = read()
                t2 = time.perf_counter()
                assert got["step"] == 1 and set(got["weights"]) == set(model.state_dict())
                if k:
                    times[name]["write"].append(t1 - t0)
                    times[name]["read"].append(t2 - t1)
        sizes = {name: r.state_path.stat().st_size for name, r in (("earlier", earlier), ("current", current))}
    rows = [{"form": name, "write_s": statistics.median(t["write"]), "read_s": statistics.median(t["read"]),
             "mb": sizes[name] / 1e6, "n": len(t["write"])} for name, t in times.items()]
    return {"model": model_name, "weights_mb": len(data) / 1e6, "rounds": rounds, "rows": rows}


def markdown(res: dict[str, Any]) -> str:
    by = {r["form"]: r for r in res["rows"]}
    lines = [f"# Checkpoint state file: `{res['model']}` ({res['weights_mb']:.1f} MB of weights + Adam state)", "",
             "Written (atomic rename included) and read back with its weights verified, median of "
             f"{res['rounds']} alternating rounds after one warm-up round.", "",
             "| form | write s | read s | file MB |", "|---|---|---|---|"]
    names = {"earlier": "earlier: weights as a pickled byte string, built in memory",
             "current": "current: weights as a uint8 tensor, streamed"}
    lines += [f"| {names[r['form']]} | {r['write_s']:.3f} | {r['read_s']:.3f} | {r['mb']:.1f} |" for r in res["rows"]]
    e, c = by["earlier"], by["current"]
    lines += ["", f"Current against earlier: write {e['write_s'] / c['write_s']:.1f}x faster, read "
              f"{e['read_s'] / c['read_s']:.1f}x faster, file {100 * (1 - c['mb'] / e['mb']):.0f} % smaller."]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--out", default="benchmarks/results")
    p.add_argument("--model", default="shared-light", help="architecture (default: the default's, shared-light)")
    p.add_argument("--rounds", type=int, default=ROUNDS)
    p.add_argument("--name", default=class_name("checkpoint_state"),
                   help="the report's name in --out (default: by the CPU's class, e.g. checkpoint_state_avx2)")
    args = p.parse_args(argv)
    torch.set_num_threads(2)
    res = run(args.model, args.rounds)
    path = write_result(args.out, args.name, res, markdown(res))
    print(markdown(res))
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
