"""Labelling many clips: in parallel processes here, or as Ray tasks on a cluster.

A bad clip is reported and skipped; it never stops the others or loses their labels.
"""

from __future__ import annotations

import contextlib
import multiprocessing as mp
import os
import queue
import signal
import threading
import time
import traceback
from collections.abc import Callable, Iterator
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from multiprocessing.managers import SyncManager
from pathlib import Path
from typing import Any

from bsn_edge.labels.config import LabelConfig
from bsn_edge.labels.generator import ClipRejectedError, Sources, StaleLabelsError, label_sequence


@dataclass(frozen=True)
class ClipResult:
    """Outcome of one clip: ``ok``, ``rejected`` (sources not trustworthy, or the clip too short),
    ``stale`` (labels made otherwise are there) or ``failed`` (error)."""

    seq: str
    status: str
    message: str = ""
    label_frames: int = 0
    resumed_frames: int = 0
    seconds: float = 0.0


def label_clip(seq: str, cfg: LabelConfig, sources: Sources,
               progress: Callable[[int], None] | None = None,
               on_total: Callable[[int], None] | None = None, force: bool = False) -> ClipResult:
    """Label one clip and turn every failure into a result instead of an exception."""
    try:
        rep = label_sequence(seq, cfg, sources, progress=progress, on_total=on_total, force=force)
    except ClipRejectedError as e:
        return ClipResult(seq, "rejected", str(e))
    except StaleLabelsError as e:
        return ClipResult(seq, "stale", str(e))
    except (OSError, ValueError) as e:       # our own messages: they say what is wrong, in the user's words
        return ClipResult(seq, "failed", str(e))
    except Exception as e:  # a bug in one clip must not take the batch down
        return ClipResult(seq, "failed", f"{type(e).__name__}: {e}\n{traceback.format_exc(limit=3)}")
    return ClipResult(seq, "ok", "", rep["label_frames"], rep["resumed_frames"], rep["seconds"])


def _worker(seq: str, cfg: LabelConfig, sources: Sources, q: Any, force: bool) -> ClipResult:
    return label_clip(seq, cfg, sources, progress=lambda n: q.put(("step", n)),
                      on_total=lambda n: q.put(("total", n)), force=force)


def _die_with_parent(parent: int) -> None:
    """Worker initializer: end this worker when the process that started it is gone (killed
    with SIGKILL, say), instead of labelling on for nobody."""
    try:
        import ctypes

        libc = ctypes.CDLL("libc.so.6", use_errno=True)
        libc.prctl(1, signal.SIGTERM)   # PR_SET_PDEATHSIG: the kernel sends SIGTERM when the parent dies
    except (OSError, AttributeError):
        pass

    def watch() -> None:   # other systems (and a race with the prctl call): poll
        while os.getppid() == parent:
            time.sleep(1.0)
        os._exit(1)

    threading.Thread(target=watch, name="bsn-parent-watch", daemon=True).start()


@contextlib.contextmanager
def worker_pool(jobs: int) -> Iterator[tuple[ProcessPoolExecutor, Any]]:
    """``jobs`` spawned worker processes and a queue they can report on; every process started here
    (the workers and the queue's manager) ends when this process ends, however it ends."""
    ctx = mp.get_context("spawn")  # no forked copies of threads or BLAS state
    manager = SyncManager(ctx=ctx)
    manager.start(_die_with_parent, (os.getpid(),))
    try:
        with ProcessPoolExecutor(jobs, mp_context=ctx, initializer=_die_with_parent,
                                 initargs=(os.getpid(),)) as pool:
            yield pool, manager.Queue()
    finally:
        manager.shutdown()


def label_many(seqs: list[str | Path], cfg: LabelConfig, sources: Sources, jobs: int = 1,
               progress: Callable[[int], None] | None = None,
               on_total: Callable[[int], None] | None = None, force: bool = False) -> list[ClipResult]:
    """Label ``seqs`` with ``jobs`` worker processes (1: in this process); results in input order.
    Workers end with this process."""
    names = [str(s) for s in seqs]
    if jobs <= 1 or len(names) == 1:
        return [label_clip(s, cfg, sources, progress, on_total, force) for s in names]
    with worker_pool(jobs) as (pool, q):
        futures = [pool.submit(_worker, s, cfg, sources, q, force) for s in names]
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
                   progress: Callable[[int], None] | None = None, force: bool = False) -> list[ClipResult]:
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
        task: Any = ray.remote(label_clip)     # Any: ray's stubs miscount a function's arguments
        refs = {task.remote(str(s), cfg, sources, None, None, force): i for i, s in enumerate(seqs)}
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
