"""The run's CPU per frame, worked by hand from injected clocks: start-up apart, every thread's CPU counted."""

from bsn_edge.runtime.cpu import CpuMeter


class Clocks:
    def __init__(self) -> None:
        self.cpu, self.wall = 0.0, 0.0


def test_cpu_per_frame_counts_from_the_skipped_frames_on():
    c = Clocks()
    m = CpuMeter(skip=3, every=7, cpu=lambda: c.cpu, wall=lambda: c.wall)
    for n in range(1, 14):                          # read at frames 3 and 10: 11-13 are not counted
        c.cpu += 1.0 if n <= 3 else 0.012 if n <= 10 else 5.0   # start-up is dear; then 12 ms of CPU a frame
        c.wall += 0.5 if n <= 3 else 1 / 30        # at 30 frames a second
        m.frame(n)
    got = m.figures()
    assert got["cpu_ms_per_frame"] == 12.0          # frames 4-10: 7 frames, 84 ms
    assert got["cores_busy"] == 0.36                 # 12 ms a frame, 30 a second


def test_a_run_too_short_to_measure_says_none():
    c = Clocks()
    m = CpuMeter(skip=20, cpu=lambda: c.cpu, wall=lambda: c.wall)
    for n in range(1, 21):
        m.frame(n)
    assert m.figures() == {"cpu_ms_per_frame": None, "cores_busy": None}
