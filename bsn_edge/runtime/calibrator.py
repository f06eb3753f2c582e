"""Online calibration off the frame path: :class:`OnlineCalibrator`.

The estimator (:class:`~bsn_edge.calibration.mount_fit.MountFit`: corners, optical flow and an
essential matrix per frame pair) costs more than a frame's warp. It runs on a thread of its own,
fed one frame in ``every``: the frame loop only copies that frame into a slot of one. When the
estimator is still busy with the previous one, the loop waits for it (``wait``: so which frames are
used does not depend on timing, and the estimator never takes more than one frame's work in
``every`` frames of the loop's time), or, from a live source (``wait=False``), skips the frame
(counted in ``skipped``); with ``every`` frames between, it is done long before. What the loop
reads back (:meth:`result`) is the estimate from every frame fed before the last one, taken as that
one is handed over: the frame at which the loop adopts a mounting does not depend on timing either.

When the loop does not wait for it (a live source), the worker runs at a lower scheduling priority
(``nice``; on Linux per thread): on two cores the model's threads and the frame path come first,
and the estimator takes what they leave (a model whose threads spin-wait for each other slows far
more when a third thread takes one of its cores than that thread's share would say). When the loop
waits for it (a file), it keeps the loop's priority: a loop waiting on a thread that yields to the
loop's own threads would only wait longer.
"""

from __future__ import annotations

import threading
from typing import Any

import numpy as np

from bsn_edge.calibration.mount_fit import MountFit, MountFitConfig
from bsn_edge.camera import Intrinsics
from bsn_edge.mounting import Mounting
from bsn_edge.runtime.priority import check_nice, lower_priority
from bsn_edge.runtime.slot import LatestSlot

# The online estimator tracks fewer corners in a smaller picture than ``bsn-calibrate --mount``: a
# pair then costs a fraction of the CPU, and convergence needs many pairs more than precise ones
# (benchmarks/results/calibration.md), so more pairs a second fit in the same share of the CPU.
ONLINE_FIT = MountFitConfig(work_width=480, max_corners=400, window_px=11)


class OnlineCalibrator:
    """Feeds frames to a :class:`MountFit` on a worker thread; :meth:`result` is the latest estimate.

    ``cfg``: the estimator's settings (:data:`ONLINE_FIT` unless given). ``background=False`` runs
    the estimator in :meth:`feed` itself (tests, benchmarks of the estimate alone)."""

    def __init__(self, intrinsics: Intrinsics, dist: tuple[float, ...], height_m: float, every: int = 3,
                 cfg: MountFitConfig | None = None, background: bool = True, nice: int = 10,
                 wait: bool = True) -> None:
        if every < 1:
            raise ValueError(f"every must be >= 1, got {every}")
        check_nice(nice)
        self.nice, self.wait = nice, wait
        self.skipped = 0
        self.fit = MountFit(intrinsics, dist, cfg or ONLINE_FIT)
        self.height_m, self.every, self.background = height_m, int(every), background
        self.seen = 0
        self.error = ""
        self._mounting: Mounting | None = None
        self._report: dict[str, Any] = {}
        self._settled: tuple[Mounting | None, dict[str, Any]] = (None, {})
        self._lock = threading.RLock()      # the estimate's state, and the slot's
        # held: the loop waits for the estimator's work on a frame, not only for its hand-over
        self._slot: LatestSlot[np.ndarray] = LatestSlot(hold=True, cond=threading.Condition(self._lock))
        self._thread: threading.Thread | None = None
        if background:
            self._thread = threading.Thread(target=self._work, name="online-calibration", daemon=True)
            self._thread.start()

    def feed(self, frame: np.ndarray) -> None:
        """Offer the loop's next frame; one in ``every`` goes to the estimator (copied: the caller may
        reuse its buffer)."""
        self.seen += 1
        if (self.seen - 1) % self.every:
            return
        if not self.background:
            self._settled = (self._mounting, dict(self._report))
            self._step(frame)
            return
        with self._lock:
            if not self.wait and self._slot.full:
                self.skipped += 1
                return
            accepted, _ = self._slot.put(frame.copy())
            if accepted:    # still under the lock: the estimate of every frame before this one
                self._settled = (self._mounting, dict(self._report))

    def result(self) -> tuple[Mounting | None, dict[str, Any]]:
        """The converged mounting (None until then) and the report, from the frames fed before the last."""
        with self._lock:
            return self._settled[0], dict(self._settled[1])

    def close(self) -> None:
        """Stop the worker; idempotent."""
        self._slot.close()
        if self._thread is not None and self._thread is not threading.current_thread():
            self._thread.join(timeout=5.0)

    def _work(self) -> None:
        if not self.wait:
            lower_priority(self.nice)
        while (frame := self._slot.take()) is not None:
            try:
                self._step(frame)
            except Exception as e:
                with self._lock:
                    self.error = f"{type(e).__name__}: {e}"
            self._slot.done()

    def _step(self, frame: np.ndarray) -> None:
        if not self.fit.add(frame):
            return
        m, report = self.fit.estimate(self.height_m)
        with self._lock:
            self._report = report
            if m is not None and report["converged"] and self._mounting is None:
                self._mounting = m
