"""Progress of long work, wherever its output goes.

On a terminal, tqdm's bar. Elsewhere (a log file, CI, ``nohup``) a bar is a stream of carriage returns
nobody reads, and tqdm draws none at all: :class:`LineProgress` prints one line instead every
:data:`EVERY_S` seconds and one at the end, with the count, the rate and the time left, so a long run in
a log never looks hung.
"""

from __future__ import annotations

import sys
import time
from collections.abc import Callable, Iterable, Iterator
from typing import IO, Any

from tqdm import tqdm

EVERY_S = 30.0


class LineProgress:
    """tqdm's calls that bsn-edge makes (``update``, ``set_postfix``, ``set_postfix_str``, ``total``, ``n``,
    ``refresh``, ``close``, iteration, ``with``), as a line every ``every_s`` seconds and one at the end."""

    def __init__(self, iterable: Iterable[Any] | None = None, total: float | None = None, desc: str = "",
                 unit: str = "it", initial: int = 0, file: IO[str] | None = None, every_s: float = EVERY_S,
                 clock: Callable[[], float] = time.monotonic) -> None:
        if total is None and iterable is not None and hasattr(iterable, "__len__"):
            total = initial + len(iterable)   # type: ignore[arg-type]
        self.iterable, self.total, self.desc, self.unit = iterable, total, desc, unit
        self.n: float = initial
        self.initial, self.file, self.every_s, self.clock = initial, file or sys.stderr, every_s, clock
        self.postfix = ""
        self.start = self.last = clock()
        self.closed = False
        # the first update carries the start-up (caches, a teacher, the first compiled step): the time left is
        # read from the rate after it
        self.first: tuple[float, float] | None = None

    def __iter__(self) -> Iterator[Any]:
        if self.iterable is None:
            raise TypeError("LineProgress without an iterable cannot be iterated")
        try:
            for item in self.iterable:
                yield item
                self.update(1)
        finally:
            self.close()

    def __enter__(self) -> LineProgress:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def update(self, n: float = 1) -> None:
        self.n += n
        now = self.clock()
        if self.first is None:
            self.first = (now, self.n)
        if now - self.last >= self.every_s:
            self.last = now
            self._print(now)

    def set_postfix(self, refresh: bool = True, **kw: Any) -> None:
        self.postfix = ", ".join(f"{k}={v}" for k, v in kw.items())

    def set_postfix_str(self, s: str = "", refresh: bool = True) -> None:
        self.postfix = s

    def refresh(self) -> None:
        """Nothing to redraw: the next line says it."""

    def close(self) -> None:
        if not self.closed:
            self.closed = True
            self._print(self.clock(), done=True)

    def line(self, now: float, done: bool = False) -> str:
        """What is printed at ``now``: count (of the total, with its share), rate, time left or taken."""
        took = max(now - self.start, 1e-9)
        rate = (self.n - self.initial) / took
        count = f"{self.n:g}" + (f"/{self.total:g} {self.unit} ({100 * self.n / self.total:.0f} %)"
                                 if self.total else f" {self.unit}")
        parts = [f"{self.desc}: {count}" if self.desc else count, f"{rate:.3g} {self.unit}/s"]
        if done:        # a run stopped short of its total (a signal, --max-frames) did not get "done"
            parts.append(f"{'stopped after' if self.total and self.n < self.total else 'done in'} "
                         f"{_duration(took)}")
        elif self.total and self.first is not None and self.n > self.first[1] and now > self.first[0]:
            steady = (self.n - self.first[1]) / (now - self.first[0])
            parts.append(f"{_duration((self.total - self.n) / steady)} left")
        if self.postfix:
            parts.append(self.postfix)
        return ", ".join(parts)

    def _print(self, now: float, done: bool = False) -> None:
        print(self.line(now, done), file=self.file, flush=True)


def _duration(s: float) -> str:
    if s < 120:
        return f"{s:.0f} s"
    if s < 5400:
        return f"{s / 60:.0f} min"
    return f"{s / 3600:.1f} h"


def progress_bar(iterable: Iterable[Any] | None = None, *, total: float | None = None, desc: str = "",
                 unit: str = "it", initial: int = 0, enabled: bool = True, file: IO[str] | None = None
                 ) -> Any:
    """tqdm's bar on a terminal, :class:`LineProgress` elsewhere; nothing shown when not ``enabled``."""
    stream = file or sys.stderr
    if not enabled:
        return tqdm(iterable, total=total, initial=initial, disable=True)
    if getattr(stream, "isatty", lambda: False)():
        return tqdm(iterable, total=total, desc=desc, unit=unit, initial=initial, file=stream)
    return LineProgress(iterable, total, desc, unit, initial, stream)
