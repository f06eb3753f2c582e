"""The runtime's one hand-over between threads, on its own: waiting, newest-wins, holding, ending."""

import threading
import time

from bsn_edge.runtime.slot import LatestSlot


def test_a_producer_waits_until_the_consumer_took_the_item():
    slot: LatestSlot[int] = LatestSlot()
    got = []

    def consume():
        while (x := slot.take()) is not None:
            time.sleep(0.002)
            got.append(x)

    t = threading.Thread(target=consume)
    t.start()
    for i in range(50):
        assert slot.put(i) == (True, None)
    slot.end()
    t.join(5)
    assert got == list(range(50)), "every item, in order: a file's frames all count"


def test_the_newest_wins_and_the_replaced_item_is_returned():
    slot: LatestSlot[int] = LatestSlot(newest_wins=True)
    assert slot.put(1) == (True, None)
    assert slot.put(2) == (True, 1), "a live camera's frame not yet taken is replaced, and the caller counts it"
    assert slot.take() == 2
    assert slot.put(3) == (True, None), "a taken item is no longer the slot's"


def test_holding_keeps_the_slot_full_until_the_work_is_done():
    slot: LatestSlot[int] = LatestSlot(hold=True)
    assert slot.offer(1) and slot.take() == 1
    assert not slot.offer(2), "still being worked on: an offer is left out"
    slot.done()
    assert slot.offer(2)


def test_take_ends_on_end_close_or_timeout_and_a_closed_slot_refuses():
    slot: LatestSlot[int] = LatestSlot()
    assert slot.take(timeout=0.01) is None
    slot.put(7)
    slot.end()
    assert slot.take() == 7 and slot.take() is None, "ended: what was there first, then nothing"
    slot = LatestSlot()
    slot.put(1)
    threading.Timer(0.05, slot.close).start()
    t0 = time.monotonic()
    assert slot.put(2) == (False, None) and time.monotonic() - t0 < 2, "a producer waiting on a closed slot returns"
    assert slot.take() is None and not slot.offer(3)
