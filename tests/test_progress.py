"""Long work shows progress off a terminal: a line at a steady interval and one at the end, with the count,
the rate and the time left worked by hand from a fake clock."""

import io
import subprocess
import sys

from bsn_edge.progress import EVERY_S, LineProgress, progress_bar


class Clock:
    def __init__(self) -> None:
        self.t = 0.0

    def __call__(self) -> float:
        return self.t


def test_a_line_every_interval_and_one_at_the_end():
    out, clock = io.StringIO(), Clock()
    bar = LineProgress(range(100, 400), total=400, desc="train", unit="step", initial=100, file=out, clock=clock)
    for i, _ in enumerate(bar):
        clock.t = (i + 1) * 0.5                       # 2 steps a second
        if i == 100:
            bar.set_postfix(loss="0.123")
    lines = out.getvalue().splitlines()
    # a line each time 30 s have passed since the last: at 30, 60, 90, 120 and 150 s; then the end
    assert len(lines) == 6
    assert lines[0] == "train: 160/400 step (40 %), 2 step/s, 2 min left"            # 240 steps at 2/s
    assert lines[1] == "train: 220/400 step (55 %), 2 step/s, 90 s left, loss=0.123"
    assert lines[-1] == "train: 400/400 step (100 %), 2 step/s, done in 2 min, loss=0.123"


def test_work_stopped_short_of_its_total_is_not_done():
    """After SIGINT at 14 % the line once ended "done in 4 s"."""
    out, clock = io.StringIO(), Clock()
    with LineProgress(desc="bsn-run", unit="frame", total=100, file=out, clock=clock) as bar:
        clock.t = 4.0
        bar.update(14)
    assert out.getvalue().splitlines()[-1] == "bsn-run: 14/100 frame (14 %), 3.5 frame/s, stopped after 4 s"


def test_work_of_unknown_size_counts_without_a_total():
    out, clock = io.StringIO(), Clock()
    with LineProgress(desc="frames", unit="frame", file=out, clock=clock) as bar:
        clock.t = EVERY_S
        bar.update(90)
    assert out.getvalue().splitlines() == ["frames: 90 frame, 3 frame/s", "frames: 90 frame, 3 frame/s, done in 30 s"]


def test_off_a_terminal_the_line_progress_is_chosen_and_disabled_shows_nothing():
    assert isinstance(progress_bar(total=3, file=io.StringIO()), LineProgress)
    out = io.StringIO()
    with progress_bar(total=3, file=out, enabled=False) as bar:
        bar.update(3)
    assert out.getvalue() == ""


def test_a_command_in_a_log_says_how_far_it_got():
    """bsn-synth with its output in a pipe (as in CI or nohup): the end line is there."""
    import tempfile

    with tempfile.TemporaryDirectory() as d:
        r = subprocess.run([sys.executable, "-m", "bsn_edge.cli.synth", f"{d}/c", "--frames", "3", "--size", "32x64",
                            "--no-video"], capture_output=True, text=True, check=False)
    assert r.returncode == 0, r.stderr
    assert "3/3 frame (100 %)" in r.stderr and "done in" in r.stderr


def test_the_time_left_is_read_after_the_first_step_which_carries_the_start_up():
    """A training whose first step takes 60 s (caches, the first compiled pass) and then 1 s a step: at 40 s
    after it, 40 of the 400 steps after the first are done, so 359 are left at 1 a second, not at the
    41 steps in 100 s the whole time gives (which said 15 minutes)."""
    out, clock = io.StringIO(), Clock()
    bar = LineProgress(total=400, desc="train", unit="step", file=out, clock=clock, every_s=1e9)
    clock.t = 60.0
    bar.update(1)
    assert "left" not in bar.line(clock.t)                       # no rate after the first step yet
    clock.t = 100.0
    bar.update(40)
    assert bar.line(clock.t) == "train: 41/400 step (10 %), 0.41 step/s, 6 min left"     # 359 s
