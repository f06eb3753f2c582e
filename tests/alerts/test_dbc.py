"""The bus's DBC generated from the sector layout: the shipped file is the default layout's, its bits are the ones
integrators have decoded since the first release, and a layout of more sectors than a frame holds gets a second
hazard frame that cantools decodes from the generated text."""

import cantools
import pytest

from bsn_edge.alerts import AlertFrame, Level, SectorAlert, SystemState
from bsn_edge.alerts.can_codec import CanEncoder, decode, to_alert_text
from bsn_edge.alerts.dbc import DBC_PATH, bus_layout, signal_name
from bsn_edge.alerts.e2e import e2e_crc

FOUR = ("FAR_LEFT", "LEFT", "RIGHT", "FAR_RIGHT")

# BSN_Hazard (0x500) as first shipped: (signal, start bit, length, scale), written out by hand from that file
V1_HAZARD = [("Left_Level", 0, 2, 1), ("Centre_Level", 2, 2, 1), ("Right_Level", 4, 2, 1), ("Left_Unseen", 6, 1, 1),
             ("Centre_Unseen", 7, 1, 1), ("Left_Score", 8, 7, 1 / 127), ("Centre_Score", 15, 7, 1 / 127),
             ("Right_Score", 22, 7, 1 / 127), ("Left_Distance", 29, 7, 0.5), ("Centre_Distance", 36, 7, 0.5),
             ("Right_Distance", 43, 7, 0.5), ("Right_Unseen", 50, 1, 1), ("Hazard_Counter", 52, 4, 1),
             ("Hazard_CRC", 56, 8, 1)]


def test_the_shipped_dbc_is_the_default_layouts_generated_one():
    """Regenerate with ``bsn-run --print-dbc > bsn_edge/alerts/bsn_alerts.dbc``."""
    assert DBC_PATH.read_text() == bus_layout().text(), "regenerate (see the docstring)"


def test_the_default_layouts_hazard_frame_keeps_the_bits_integrators_decode():
    msg = cantools.database.load_file(str(DBC_PATH)).get_message_by_name("BSN_Hazard")
    assert msg.frame_id == 0x500 and msg.length == 8
    got = [(s.name, s.start, s.length, s.scale) for s in msg.signals]
    assert [(n, a, b) for n, a, b, _ in got] == [(n, a, b) for n, a, b, _ in V1_HAZARD]
    assert [c for *_, c in got] == pytest.approx([c for *_, c in V1_HAZARD])


def test_signal_names_of_a_sector_with_an_underscore():
    assert signal_name("FAR_LEFT", "Level") == "Far_Left_Level" and signal_name("CENTRE", "Unseen") == "Centre_Unseen"


def test_four_sectors_go_in_two_hazard_frames_that_cantools_decodes_from_the_generated_text():
    layout = bus_layout(FOUR)
    assert [(h.name, h.frame_id, h.sectors) for h in layout.hazards] == [
        ("BSN_Hazard", 0x500, FOUR[:3]), ("BSN_Hazard2", 0x502, FOUR[3:])]
    db = cantools.database.load_string(layout.text(), database_format="dbc")     # a second reader of the text
    for msg in db.messages:     # no two signals of a frame share a bit
        bits = [b for s in msg.signals for b in range(s.start, s.start + s.length)]
        assert len(bits) == len(set(bits)) and max(bits) < 64, msg.name
    readings = (SectorAlert(0.1, Level.NONE, None), SectorAlert(0.5, Level.CAUTION, 12.0),
                SectorAlert(0.0, Level.NONE, None, True), SectorAlert(0.9, Level.WARNING, 4.5))
    frames = CanEncoder(layout).encode(AlertFrame(0.0, readings, SystemState.DEGRADED, 10.0))
    assert [fid for fid, _ in frames] == [0x500, 0x502, 0x501]
    got = {}
    for fid, data in frames:
        assert data[7] == e2e_crc(data[:7], fid), "each frame carries its own CRC over its own id"
        got |= db.decode_message(fid, data, decode_choices=False)
    assert [got[signal_name(s, "Level")] for s in FOUR] == [0, 1, 0, 2]
    assert [got[signal_name(s, "Unseen")] for s in FOUR] == [0, 0, 1, 0]
    assert got["Far_Right_Distance"] == 4.5 and got["Left_Distance"] == 12.0 and got["Far_Left_Distance"] == 63.5
    assert got["Far_Right_Score"] == pytest.approx(round(0.9 * 127) / 127)
    second = decode(0x502, frames[1][1], layout)
    assert second is not None and second.crc_ok
    assert to_alert_text(second, 0).startswith("hazard2 0 [alive 0]: FAR_RIGHT WARNING 0.90 4.5 m")


def test_an_unavailable_frame_says_none_in_every_sector_of_any_layout():
    frames = CanEncoder(bus_layout(FOUR)).encode(AlertFrame.unavailable(0.0))
    db = bus_layout(FOUR).database()
    got = {k: v for fid, data in frames for k, v in db.decode_message(fid, data, decode_choices=False).items()}
    assert all(got[signal_name(s, "Level")] == 0 for s in FOUR) and got["System_State"] == 2


@pytest.mark.parametrize("n, frames", [(1, 1), (3, 1), (4, 2), (6, 2), (7, 3), (9, 3)])
def test_each_layout_size_fits_its_frames(n, frames):
    layout = bus_layout(tuple(f"S{k}" for k in range(n)))
    assert len(layout.hazards) == frames
    db = cantools.database.load_string(layout.text(), database_format="dbc")
    assert {m.frame_id for m in db.messages} == {0x500, 0x501, *range(0x502, 0x502 + frames - 1)}
