"""The online calibrator's thread: below the frame path's priority, and never a stall for a live source."""

import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from bsn_edge.camera import Intrinsics
from bsn_edge.runtime.calibrator import OnlineCalibrator


class SlowFit:
    """Stands in for the estimator: each frame takes ``seconds``; remembers which frames it had."""

    def __init__(self, seconds: float) -> None:
        self.seconds, self.had = seconds, []

    def add(self, frame):
        time.sleep(self.seconds)
        self.had.append(int(frame[0, 0]))
        return False


def calibrator(fit, **kw):
    cal = OnlineCalibrator(Intrinsics.from_fov(64, 32, 80.0), (), 1.5, every=1, **kw)
    cal.fit = fit
    return cal


def frame(i):
    return np.full((32, 64), i, np.uint8)


def nice_of(tid: int) -> int:
    # field 19 of /proc/<pid>/task/<tid>/stat, counted after the command name's closing parenthesis
    stat = Path(f"/proc/self/task/{tid}/stat").read_text()
    return int(stat[stat.rindex(")") + 2:].split()[16])


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="per-thread priority is read from /proc")
def test_the_estimator_runs_below_the_frame_paths_priority_unless_the_loop_waits_for_it():
    own = nice_of(threading.get_native_id())
    for wait, want in ((False, min(19, own + 10)), (True, own)):
        cal = calibrator(SlowFit(0.0), nice=10, wait=wait)
        cal.feed(frame(0))
        time.sleep(0.1)
        assert nice_of(cal._thread.native_id) == want, f"wait={wait}"
        cal.close()
    assert nice_of(threading.get_native_id()) == own, "the caller's thread keeps its priority"


def test_from_a_live_source_a_busy_estimator_skips_frames_instead_of_stalling_the_loop():
    fit = SlowFit(0.05)
    live = calibrator(fit, wait=False)
    t0 = time.perf_counter()
    for i in range(10):
        live.feed(frame(i))
    took = time.perf_counter() - t0
    time.sleep(0.1)
    live.close()
    assert took < 0.04, "the loop never waited for the estimator"
    assert live.skipped >= 8 and fit.had[:1] == [0]

    fit = SlowFit(0.01)
    recorded = calibrator(fit, wait=True)
    for i in range(10):
        recorded.feed(frame(i))
    time.sleep(0.05)
    recorded.close()
    assert recorded.skipped == 0 and fit.had == list(range(10)), "from a file every frame fed is used"
