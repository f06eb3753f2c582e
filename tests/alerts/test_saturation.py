"""Every counting signal of the status message saturates at the largest value its DBC field holds, and
the distances and frame rate stay inside theirs: a count past a field's range must never make the strict
encoder raise, or the bus would go silent at the 64th sink error. The largest values are read from the
DBC's own text with a regular expression (not through cantools, which encodes), and checked against the
field's width: 2**bits - 1 raw steps."""

import itertools
import re

import pytest

from bsn_edge.alerts import SystemState
from bsn_edge.alerts.can_codec import DBC_PATH, HAZARD, STATUS, CanEncoder, decode
from bsn_edge.alerts.frame import AlertFrame, SectorAlert
from bsn_edge.alerts.health import Fault
from bsn_edge.alerts.state_machine import Level

SIGNAL = re.compile(r"^\s*SG_ (\w+) : (\d+)\|(\d+)@1\+ \(([-\d.e]+),([-\d.e]+)\) \[([-\d.e]+)\|([-\d.e]+)\]", re.M)
MESSAGE = re.compile(r"^BO_ (\d+) (\w+):", re.M)


def dbc_fields() -> dict[str, dict[str, tuple[int, float, float]]]:
    """{message: {signal: (bits, scale, largest value)}} as the DBC's text gives them."""
    text = DBC_PATH.read_text()
    heads = [(m.start(), m.group(2)) for m in MESSAGE.finditer(text)] + [(len(text), "")]
    out: dict[str, dict[str, tuple[int, float, float]]] = {}
    for (start, name), (end, _) in itertools.pairwise(heads):
        out[name] = {m.group(1): (int(m.group(3)), float(m.group(4)), float(m.group(7)))
                     for m in SIGNAL.finditer(text[start:end])}
    return out


FIELDS = dbc_fields()
# each counting status signal, and the faults that add up into it
COUNTERS = {"Decode_Errors": (Fault.DECODE_ERRORS, Fault.SIZE_CHANGES),
            "Dropped_Frames": (Fault.DROPPED_FRAMES,),
            "Invalid_Outputs": (Fault.NAN_OUTPUTS,),
            "Tx_Errors": (Fault.TX_ERRORS, Fault.TX_FULL, Fault.SERIAL_ERRORS),
            "Sink_Errors": (Fault.SINK_ERRORS,)}
NONE = SectorAlert(0.0, Level.NONE, None)


def _status(faults: dict[str, int], fps: float = 10.0) -> dict:
    frames = CanEncoder().encode(AlertFrame(0.0, (NONE,) * 3, SystemState.OK, fps, faults))
    got = {d.name: d for d in (decode(i, data) for i, data in frames)}
    assert got[STATUS].crc_ok
    return got[STATUS].signals


def test_the_dbc_read_here_is_the_shipped_one_and_its_ranges_match_their_widths():
    assert set(FIELDS) == {HAZARD, STATUS}
    assert FIELDS[STATUS]["Sink_Errors"] == (6, 1.0, 63.0)
    for message in FIELDS.values():
        for name, (bits, scale, top) in message.items():
            # levels: a value table of three; the camera's reason: of seven
            if not name.endswith(("_CRC", "_Counter", "_Level", "Camera_Reason")):
                assert top == pytest.approx((2 ** bits - 1) * scale), name


def test_every_counting_signal_is_covered():
    counting = {n for n, (bits, scale, _) in FIELDS[STATUS].items() if scale == 1 and bits >= 6
                and not n.endswith(("_CRC", "_Counter"))}
    assert counting == set(COUNTERS)


@pytest.mark.parametrize("signal,fault", [(s, f) for s, faults in COUNTERS.items() for f in faults])
@pytest.mark.parametrize("count", [1, 62, 63, 64, 254, 255, 256, 10_000])
def test_a_count_saturates_at_its_fields_largest_value(signal, fault, count):
    top = int(FIELDS[STATUS][signal][2])
    assert int(_status({fault: count})[signal]) == min(count, top)


@pytest.mark.parametrize("signal", [s for s, faults in COUNTERS.items() if len(faults) > 1])
def test_counts_that_add_up_into_one_signal_saturate_on_their_sum(signal):
    top = int(FIELDS[STATUS][signal][2])
    each = top // 2 + 1                       # no one count reaches the top; their sum passes it
    assert int(_status(dict.fromkeys(COUNTERS[signal], each))[signal]) == top


@pytest.mark.parametrize("fps,want", [(0.0, 0.0), (24.75, 25.0), (127.5, 127.5), (128.0, 127.5), (5000.0, 127.5)])
def test_the_frame_rate_saturates_at_its_fields_largest_value(fps, want):
    assert FIELDS[STATUS]["Frame_Rate"][2] == 127.5
    assert _status({}, fps)["Frame_Rate"] == want


@pytest.mark.parametrize("distance,score,want_d,want_s", [(0.0, 0.0, 0.0, 0.0), (62.9, 0.5, 63.0, 64 / 127),
                                                          (63.2, 1.0, 63.0, 1.0), (1e6, 7.0, 63.0, 1.0),
                                                          (None, -3.0, 63.5, 0.0)])
def test_distances_and_scores_stay_inside_their_fields(distance, score, want_d, want_s):
    """63.5 m, the field's largest value, means no blind spot in range: a far one reads 63.0, never that."""
    top = FIELDS[HAZARD]["Left_Distance"][2]
    assert top == 63.5
    sector = SectorAlert(score, Level.WARNING, distance)
    frames = CanEncoder().encode(AlertFrame(0.0, (sector,) * 3, SystemState.OK, 10.0, {}))
    hz = next(d for d in (decode(i, data) for i, data in frames) if d.name == HAZARD)
    for side in ("Left", "Centre", "Right"):
        assert hz.signals[f"{side}_Distance"] == pytest.approx(want_d)
        assert hz.signals[f"{side}_Score"] == pytest.approx(want_s, abs=1e-6)
