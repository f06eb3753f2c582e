"""The heartbeat on a live source, on a simulated clock: every cycle goes out at most half a cycle after it
is due, and no two status frames are further apart on the clock than one and a half cycles. Woken every two
cycles instead, frames would go out in pairs up to three cycles apart; the bounds here are the hand-worked
ones for a wake every half cycle (a cycle due just after a wake waits at most half a cycle for the next)."""

import itertools

import pytest

from bsn_edge.alerts.can_codec import STATUS, decode
from bsn_edge.alerts.health import Health
from bsn_edge.alerts.senders import Sender
from bsn_edge.runtime.cycle import CycleEmitter, Heartbeat
from tests.fakes import SimClock


class Stamped(Sender):
    """Keeps the simulated time each status frame went out; each send takes ``cost_s`` of the clock, as a
    real bus write does (so wakes drift against the cycle, as they do on a real machine)."""

    name = "stamped"

    def __init__(self, clock: SimClock, cost_s: float = 0.0) -> None:
        super().__init__()
        self.clock, self.cost_s, self.sent_at = clock, cost_s, []

    def _send(self, frames):
        if any(decode(i, d).name == STATUS for i, d in frames):
            self.sent_at.append(self.clock())
        self.clock.now += self.cost_s


@pytest.mark.parametrize("cycle_s", [0.05, 0.1, 0.37])
def test_status_frames_go_out_within_half_a_cycle_of_due_and_never_more_than_one_and_a_half_apart(cycle_s):
    """A send costs 5 % of a cycle: a cycle is at most a wake's interval plus one send late (0.55 cycles)
    and two frames at most a cycle plus that apart (1.55). Woken once a cycle, the cost piles up until a
    cycle goes out a whole cycle late."""
    clock = SimClock(until=60 * cycle_s)
    cost = 0.05 * cycle_s
    sender = Stamped(clock, cost)
    emitter = CycleEmitter([sender], Health(), cycle_s)
    Heartbeat(emitter, clock=clock, wait=clock.wait).run()       # on this thread, on the simulated clock
    times = sender.sent_at
    assert len(times) >= 59
    due = [100.0 + k * cycle_s for k in range(len(times))]
    late = max(t - d for t, d in zip(times, due, strict=True))
    assert late <= cycle_s / 2 + cost + 1e-9, f"a cycle went out {late / cycle_s:.2f} cycles late"
    gaps = [b - a for a, b in itertools.pairwise(times)]
    assert max(gaps) <= 1.5 * cycle_s + cost + 1e-9, f"status frames {max(gaps) / cycle_s:.2f} cycles apart"


def test_a_clock_that_jumps_between_wakes_still_sends_every_cycle_due():
    """Cycles missed while the process was not scheduled go out at the next wake, none skipped."""
    clock = SimClock(until=1.0)
    sender = Stamped(clock)
    emitter = CycleEmitter([sender], Health(), 0.1)
    jumps = iter([0.05, 0.35, 0.05, 0.05] + [0.05] * 100)

    def wait(_seconds: float) -> bool:
        clock.now += next(jumps)
        return clock.now >= clock.until

    Heartbeat(emitter, clock=clock, wait=wait).run()
    assert emitter.sent_cycles == len(sender.sent_at) == 11      # the cycles due at 100.0, 100.1, ... 101.0
