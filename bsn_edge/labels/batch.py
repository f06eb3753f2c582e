"""Labelling many clips: in parallel processes here, or as Ray tasks on a cluster.

A bad clip is reported and skipped; it never stops the others or loses their labels.
"""

from __future__ import annotations

import multiprocessing as mp
import queue
import traceback
from collections.abc import Callable
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from bsn_edge.labels.config import LabelConfig
from bsn_edge.labels.generator import ClipRejectedError, Sources, label_sequence


@dataclass(frozen=True)
class ClipResult:
    """Outcome of one clip: ``ok``, ``rejected`` (sources not trustworthy) or ``failed`` (error)."""

    seq: str
    status: str
    message: str = ""
    label_frames: int = 0
    resumed_frames: int = 0
    seconds: float = 0.0


def label_clip(seq: str, cfg: LabelConfig, sources: Sources,
               progress: Callable[[int], None] | None = None,
               on_total: Callable[[int], None] | None = None) -> ClipResult:
    """Label one clip and turn every failure into a result instead of an exception."""
    try:
        rep = label_sequence(seq, cfg, sources, progress=progress, on_total=on_total)
    except ClipRejectedError as e:
        return ClipResult(seq, "rejected", str(e))
    except (OSError, ValueError) as e:
        return ClipResult(seq, "failed", f"{type(e).__name__}: {e}")
    except Exception as e:  # a bug in one clip must not take the batch down
        return ClipResult(seq, "failed", f"{type(e).__name__}: {e}\n{traceback.format_exc(limit=3)}")
    return ClipResult(seq, "ok", "", rep["label_frames"], rep["resumed_frames"], rep["seconds"])


def _worker(seq: str, cfg: LabelConfig, sources: Sources, q: Any) -> ClipResult:
    return label_clip(seq, cfg, sources, progress=lambda n: q.put(("step", n)),
                      on_total=lambda n: q.put(("total", n)))


def label_many(seqs: list[str | Path], cfg: LabelConfig, sources: Sources, jobs: int = 1,
               progress: Callable[[int], None] | None = None,
               on_total: Callable[[int], None] | None = None) -> list[ClipResult]:
    """Label ``seqs`` with ``jobs`` worker processes (1: in this process); results in input order."""
    seqs = [str(s) for s in seqs]
    if jobs <= 1 or len(seqs) == 1:
        return [label_clip(s, cfg, sources, progress, on_total) for s in seqs]
    ctx = mp.get_context("spawn")  # no forked copies of threads or BLAS state
    with ctx.Manager() as manager, ProcessPoolExecutor(jobs, mp_context=ctx) as pool:
        q = manager.Queue()
        futures = [pool.submit(_worker, s, cfg, sources, q) for s in seqs]
        while True:
            try:
                kind, n = q.get(timeout=0.2)
            except queue.Empty:
                if all(f.done() for f in futures):
                    break
                continue
            if kind == "step" and progress:
                progress(n)
            elif kind == "total" and on_total:
                on_total(n)
        return [f.result() for f in futures]


def label_many_ray(seqs: list[str | Path], cfg: LabelConfig, sources: Sources, address: str,
                   progress: Callable[[int], None] | None = None) -> list[ClipResult]:
    """Label ``seqs`` as Ray tasks on the cluster at ``address`` (``local`` starts one here).

    Every node must see the sequence folders at the same paths (a shared file system).
    """
    try:
        import ray
    except ImportError:
        raise RuntimeError("Ray is not installed: pip install 'bsn-edge[ray]'") from None
    started = not ray.is_initialized()
    if started:
        if address == "local":
            ray.init(include_dashboard=False, log_to_driver=False)
        else:
            ray.init(address=address, include_dashboard=False, log_to_driver=False)
    try:
        task = ray.remote(label_clip)
        refs = {task.remote(str(s), cfg, sources): i for i, s in enumerate(seqs)}
        out: list[ClipResult | None] = [None] * len(seqs)
        pending = list(refs)
        while pending:
            done, pending = ray.wait(pending, num_returns=1)
            for ref in done:
                res = ray.get(ref)
                out[refs[ref]] = res
                if progress:
                    progress(res.label_frames)
        return [r for r in out if r is not None]
    finally:
        if started:
            ray.shutdown()
