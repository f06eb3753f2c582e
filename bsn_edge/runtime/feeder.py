"""Frames read and warped for the model: :class:`Feeder`, on the caller's thread or a thread of its own.

In the background the feeder decodes and warps frame t+1 while the model runs frame t, handing each
prepared frame over through a slot of one. From a file every frame is used: the feeder waits while
the slot is full, so a run's outputs do not depend on timing. From a live source the newest frame
wins: a prepared frame the model had no time for is replaced by the next one and counted in
``dropped`` (the source itself counts the frames it skipped before they were decoded).

Every prepared frame is warped into an input buffer of its own, which the caller has until it asks
for the next frame or hands it back (:meth:`Feeder.release`) once the model has read it. Three
buffers are enough: one in the model, one in the slot, one being written. A caller that keeps
``held`` frames in the model at once (two inferences side by side) hands each back itself and needs
``held + 2``.

The feeder's thread may run at a lower scheduling priority (``nice``): the model's threads then keep
the cores, and decode and warp fill the gaps they leave (between operators, while a thread waits
for the other); when the model is done and waits for the next frame, the feeder's thread is the only
one left to run, at full speed.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass

import numpy as np

from bsn_edge.model_frame import ModelFrame
from bsn_edge.runtime.priority import check_nice, lower_priority
from bsn_edge.runtime.slot import LatestSlot
from bsn_edge.runtime.sources import Captured, Source


@dataclass(frozen=True)
class Prepared:
    """A frame ready for the model: the capture, its model frame and the buffer it was warped into
    (both None when the frame did not decode), whether the camera was still calibrating when it was
    warped, the warp's seconds and when it was ready (``time.perf_counter()``)."""

    cap: Captured
    mf: ModelFrame | None
    buf: np.ndarray | None
    calibrating: bool
    warp_s: float
    ready_at: float


# (captured frame, input buffer) -> (model frame, calibrating), the warped frame written into the buffer; None
# for a frame not to be warped (of another size than the source's: counted by the loop, nothing built for it)
Warp = Callable[[Captured, np.ndarray], tuple[ModelFrame, bool] | None]


class Feeder:
    """Iterate to get :class:`Prepared` frames of ``source``, at most ``limit``; ``close()`` stops it.

    ``background=False`` reads and warps on the caller's thread, into one buffer (``buffers[0]``).
    ``background=True`` needs ``held + 2`` of them (:meth:`buffers_needed`) and a thread of its own,
    ``nice`` steps below the caller's priority (0: the same); an exception there is raised on the
    caller's thread when the iteration reaches it. With ``held`` > 1 (background only) asking for the
    next frame releases nothing: the caller hands each buffer back when the model has read it."""

    BUFFERS = 3          # in the background: one in the model, one in the slot, one being written

    @staticmethod
    def buffers_needed(held: int = 1) -> int:
        """Input buffers a background feeder needs when the caller keeps ``held`` frames at once."""
        return Feeder.BUFFERS + held - 1

    def __init__(self, source: Source, warp: Warp, buffers: list[np.ndarray], background: bool,
                 limit: int | None = None, nice: int = 0, held: int = 1) -> None:
        check_nice(nice)
        if held < 1 or (held > 1 and not background):
            raise ValueError(f"held must be 1, or more with a background feeder; got {held}")
        if background and len(buffers) < self.buffers_needed(held):
            raise ValueError(f"a background feeder that lets {held} frame(s) be held needs "
                             f"{self.buffers_needed(held)} input buffers, got {len(buffers)}")
        if not buffers:
            raise ValueError("a feeder needs an input buffer")
        self.source, self.warp, self.background, self.limit, self.nice = source, warp, background, limit, nice
        self.newest_wins = source.live
        self._buffers = list(buffers)
        self._free = list(buffers)
        self._auto_release = held == 1
        self._held: list[np.ndarray] = []        # the buffers of the frames the caller has
        self._cond = threading.Condition()       # the buffers' lock, and the slot's
        self._slot: LatestSlot[Prepared] = LatestSlot(newest_wins=self.newest_wins, cond=self._cond)
        self._closed = False
        self._error: BaseException | None = None
        self._dropped = 0
        self._thread: threading.Thread | None = None

    @property
    def dropped(self) -> int:
        """Prepared frames replaced by a newer one before the model took them (live sources only)."""
        with self._cond:
            return self._dropped

    def prepare(self, cap: Captured, buf: np.ndarray) -> Prepared:
        """``cap`` warped into ``buf`` (nothing to warp when it did not decode, or the warp declines it)."""
        if cap.frame is None:
            return Prepared(cap, None, None, False, 0.0, time.perf_counter())
        t0 = time.perf_counter()
        warped = self.warp(cap, buf)
        t1 = time.perf_counter()
        if warped is None:
            return Prepared(cap, None, None, False, t1 - t0, t1)
        return Prepared(cap, warped[0], buf, warped[1], t1 - t0, t1)

    def release(self, buf: np.ndarray | None) -> None:
        """The model has read ``buf``: the feeder may warp the next frame into it. Asking for the next
        frame releases the one before anyway; releasing early lets the feeder start sooner."""
        with self._cond:
            for i, b in enumerate(self._held):
                if b is buf:
                    del self._held[i]
                    self._free.append(buf)
                    self._cond.notify_all()
                    return

    def __iter__(self) -> Iterator[Prepared]:
        if not self.background:
            yield from self._inline()
            return
        self._thread = threading.Thread(target=self._work, name="bsn-feeder", daemon=True)
        self._thread.start()
        while True:
            if self._auto_release:
                for buf in list(self._held):
                    self.release(buf)
            item = self._slot.take()
            with self._cond:
                if item is not None and item.buf is not None:
                    self._held.append(item.buf)
                if item is None:
                    if self._error is not None:
                        raise self._error
                    return
            yield item

    def close(self) -> None:
        """Stop reading (idempotent): the source is told to stop too (a camera that delivers nothing
        would otherwise keep the feeder's thread waiting), then the thread is waited for."""
        with self._cond:
            self._closed = True
            self._cond.notify_all()
        self._slot.close()
        if self._thread is not None and self._thread is not threading.current_thread():
            self.source.stop()
            self._thread.join(timeout=5.0)

    # -- internals -------------------------------------------------------------------------------

    def _inline(self) -> Iterator[Prepared]:
        for n, cap in enumerate(self.source, 1):
            yield self.prepare(cap, self._buffers[0])
            if self._closed or (self.limit is not None and n >= self.limit):
                return

    def _take_buffer(self) -> np.ndarray | None:
        with self._cond:
            while not self._free and not self._closed:
                self._cond.wait()
            return None if self._closed else self._free.pop()

    def _give_back(self, buf: np.ndarray) -> None:
        with self._cond:
            self._free.append(buf)
            self._cond.notify_all()

    def _put(self, item: Prepared) -> bool:
        """Hand ``item`` over (a live source's newest replaces one not yet taken, which is counted as
        dropped and its buffer freed); False when the feeder was closed meanwhile."""
        with self._cond:
            accepted, replaced = self._slot.put(item)
            if replaced is not None:
                self._dropped += 1
                if replaced.buf is not None:
                    self._free.append(replaced.buf)
                    self._cond.notify_all()
            return accepted

    def _work(self) -> None:
        n = 0
        lower_priority(self.nice)
        try:
            for cap in self.source:
                buf = self._take_buffer()
                if buf is None:
                    return
                item = self.prepare(cap, buf)
                if item.buf is None:            # nothing was warped into it: it goes back at once
                    self._give_back(buf)
                if not self._put(item):
                    return
                n += 1
                if self.limit is not None and n >= self.limit:
                    return
        except BaseException as e:        # raised on the consumer's thread, in order after the frames before
            with self._cond:
                self._error = e
        finally:
            self._slot.end()
