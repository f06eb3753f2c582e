"""The hand-over of one item between two threads of the runtime: :class:`LatestSlot`.

The source's capture thread hands the newest frame to the loop, the feeder hands a warped frame to
the model, the loop hands a frame to the online calibrator: each through a slot of one. What the
producer does when the slot is still full is the policy that differs: wait for the consumer (a file:
every frame counts), replace the item there (a live camera: the newest frame wins, the one replaced is
dropped and counted by the caller), or leave its own item out (:meth:`LatestSlot.offer`).
"""

from __future__ import annotations

import threading
from typing import Generic, TypeVar

T = TypeVar("T")


class LatestSlot(Generic[T]):
    """A slot of one item between a producer and a consumer thread.

    ``newest_wins``: :meth:`put` replaces an item still there instead of waiting, and returns it.
    ``hold``: a taken item keeps the slot full until the consumer calls :meth:`done` (the producer
    waits for the work on it, not only for its hand-over). ``cond``: a condition shared with other
    state of the owner (its lock guards the slot too). :meth:`end` (the producer has no more) and
    :meth:`close` (both sides stop) are idempotent."""

    def __init__(self, newest_wins: bool = False, hold: bool = False, cond: threading.Condition | None = None) -> None:
        self.newest_wins, self.hold = newest_wins, hold
        self.cond = cond if cond is not None else threading.Condition()
        self._item: T | None = None
        self._full = False          # an item waits, or (hold) is being worked on
        self._waiting = False       # an item waits to be taken
        self._ended = False
        self._closed = False

    @property
    def closed(self) -> bool:
        with self.cond:
            return self._closed

    @property
    def full(self) -> bool:
        with self.cond:
            return self._full

    def put(self, item: T) -> tuple[bool, T | None]:
        """Hand ``item`` over: ``(accepted, replaced)``. Waits while the slot is full, unless
        ``newest_wins`` (an item not yet taken is then replaced and returned); not accepted once closed."""
        with self.cond:
            replaced = None
            if self.newest_wins and self._waiting:
                replaced, self._item, self._full, self._waiting = self._item, None, False, False
            while self._full and not self._closed:
                self.cond.wait()
            if self._closed:
                return False, replaced
            self._item, self._full, self._waiting = item, True, True
            self.cond.notify_all()
            return True, replaced

    def offer(self, item: T) -> bool:
        """Hand ``item`` over only if the slot is free now; False (the caller leaves it out) otherwise."""
        with self.cond:
            if self._full or self._closed:
                return False
            self._item, self._full, self._waiting = item, True, True
            self.cond.notify_all()
            return True

    def take(self, timeout: float | None = None) -> T | None:
        """The item handed over, waiting for one; None once the slot is closed, or ended and empty, or
        after ``timeout`` seconds without one."""
        with self.cond:
            if not self.cond.wait_for(lambda: self._waiting or self._closed or self._ended, timeout):
                return None
            if not self._waiting or self._closed:
                return None
            item, self._item, self._waiting = self._item, None, False
            if not self.hold:
                self._full = False
            self.cond.notify_all()
            return item

    def done(self) -> None:
        """The consumer has finished with the item it took (``hold``): the producer may hand the next."""
        with self.cond:
            self._full = self._waiting
            self.cond.notify_all()

    def end(self) -> None:
        """The producer has no more: :meth:`take` answers None once the slot is empty."""
        with self.cond:
            self._ended = True
            self.cond.notify_all()

    def close(self) -> None:
        """Both sides stop: waiting ones return at once."""
        with self.cond:
            self._closed = True
            self.cond.notify_all()
