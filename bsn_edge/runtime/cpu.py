"""What the run costs the machine: the process's CPU per frame once it is running (start-up apart)."""

from __future__ import annotations

import time
from collections.abc import Callable


def process_cpu_s() -> float:
    """The process's user and system CPU so far, every thread, seconds."""
    return time.process_time()


class CpuMeter:
    """The process's CPU (every thread: decoding, warping, the model's, the outputs') between frame ``skip``
    and the last frame, per frame, and as cores busy over that stretch: the model's first runs, the outputs'
    opening and the first cycles are start-up, not the frame's cost. ``cpu`` and ``wall``: the clocks read
    (injected in tests)."""

    def __init__(self, skip: int = 20, every: int = 10, cpu: Callable[[], float] = process_cpu_s,
                 wall: Callable[[], float] = time.perf_counter) -> None:
        """Read at frame ``skip`` and every ``every`` frames after it (the process's CPU clock sums every
        thread's: not a read for every frame)."""
        self.skip, self.every, self._cpu, self._wall = skip, every, cpu, wall
        self._first: tuple[int, float, float] | None = None
        self._last: tuple[int, float, float] | None = None

    def frame(self, n: int) -> None:
        """Frame ``n`` (counted from 1) is done."""
        if n < self.skip or (n - self.skip) % self.every:
            return
        mark = (n, self._cpu(), self._wall())
        if self._first is None:
            self._first = mark
        else:
            self._last = mark

    def figures(self) -> dict[str, float | None]:
        """``cpu_ms_per_frame`` and ``cores_busy`` (CPU seconds per second over the same frames); None for a run
        of no more than ``skip`` frames."""
        if self._first is None or self._last is None:
            return {"cpu_ms_per_frame": None, "cores_busy": None}
        (n0, c0, w0), (n1, c1, w1) = self._first, self._last
        return {"cpu_ms_per_frame": round(1e3 * (c1 - c0) / (n1 - n0), 3),
                "cores_busy": round((c1 - c0) / (w1 - w0), 3) if w1 > w0 else None}
