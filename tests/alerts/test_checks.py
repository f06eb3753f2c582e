"""Checksums and framing against published values, and bsn-listen on damaged logs."""

import signal
import subprocess
import sys
import time

import pytest

from bsn_edge.alerts import AlertFrame, Level, SectorAlert, SystemState
from bsn_edge.alerts.can_codec import CanEncoder
from bsn_edge.alerts.e2e import crc8_sae_j1850, crc16_ccitt
from bsn_edge.alerts.serial_codec import cobs_decode, cobs_encode
from bsn_edge.cli import listen as listen_cli

CHECK = b"123456789"


def test_crcs_match_their_catalogue_check_values():
    # reveng CRC catalogue: CRC-8/SAE-J1850 check=0x4b, CRC-16/IBM-3740 (CCITT-FALSE) check=0x29b1
    assert crc8_sae_j1850(CHECK) == 0x4B
    assert crc16_ccitt(CHECK) == 0x29B1
    assert crc8_sae_j1850(b"") == 0x00 and crc16_ccitt(b"") == 0xFFFF


@pytest.mark.parametrize("raw, encoded", [
    # the examples published with COBS (Cheshire and Baker 1999; Wikipedia's table)
    ("00", "0101"),
    ("0000", "010101"),
    ("001100", "01021101"),
    ("11220033", "0311220233"),
    ("11223344", "0511223344"),
    ("11000000", "0211010101"),
])
def test_cobs_matches_the_published_examples(raw, encoded):
    assert cobs_encode(bytes.fromhex(raw)) == bytes.fromhex(encoded)
    assert cobs_decode(bytes.fromhex(encoded)) == bytes.fromhex(raw)


def candump(fid: int, data: bytes, t: float) -> str:
    return f"({t:.6f}) vcan0 {fid:03X}#{data.hex().upper()}\n"


def frames(n: int) -> list[tuple[int, bytes]]:
    enc = CanEncoder()
    none = SectorAlert(0.0, Level.NONE, None)
    out = []
    for k in range(n):
        out += enc.encode(AlertFrame(k * 0.1, (none,) * 3, SystemState.OK, 10.0, {}))
    return out


def test_listen_reports_bad_lines_with_their_numbers_and_goes_on(tmp_path, capsys):
    fs = frames(4)
    lines = [candump(f, d, i * 0.05) for i, (f, d) in enumerate(fs)]
    lines.insert(2, "# a comment\n")
    lines.insert(4, "garbage that is not candump\n")
    lines.append("(1.000000) vcan0 500#0011")  # truncated: 2 of 8 bytes, and no newline
    log = tmp_path / "a.log"
    log.write_text("".join(lines))
    assert listen_cli.main(["--can-log", str(log)]) == 1
    out = capsys.readouterr()
    assert f"{log}:3: comment line skipped" in out.err and f"{log}:5: not a candump line" in out.err
    assert "8 frames" in out.err and "3 unreadable lines" in out.err and "0 lost" in out.err
    assert out.out.count("hazard ") == 4 and "status 3 [alive 3]" in out.out


def test_a_repeat_is_a_repeat_and_a_bad_crc_does_not_move_the_counter(tmp_path, capsys):
    (h0, d0), _, (h1, d1), _, (h2, d2), _ = frames(3)
    bad = bytearray(d1)
    bad[0] ^= 0x04                       # CRC fails
    log = tmp_path / "b.log"
    log.write_text(candump(h0, d0, 0) + candump(h0, d0, 0.1) + candump(h1, bytes(bad), 0.2) + candump(h1, d1, 0.3)
                   + candump(h2, d2, 0.4))
    assert listen_cli.main(["--can-log", str(log)]) == 1
    err = capsys.readouterr().err
    assert "5 frames, 1 with a bad CRC, 0 lost, 1 repeated" in err


def test_a_level_outside_the_value_table_is_counted_not_a_crash(tmp_path, capsys):
    from bsn_edge.alerts.e2e import e2e_crc
    fs = frames(25)
    hid, data = fs[40]                        # frame 20's hazard message
    bad = bytearray(data)
    bad[0] |= 0x03                            # Left_Level (bits 0-1) = 3, a value the DBC does not define
    bad[7] = e2e_crc(bytes(bad[:7]), hid)     # with a valid CRC: only the field is wrong
    fs[40] = (hid, bytes(bad))
    log = tmp_path / "lv.log"
    log.write_text("".join(candump(f, d, i * 0.05) for i, (f, d) in enumerate(fs)))
    assert listen_cli.main(["--can-log", str(log)]) == 1
    out = capsys.readouterr()
    assert "LEFT LEVEL?3" in out.out and "undefined Left_Level=3" in out.out
    assert "50 frames" in out.err and "1 with an undefined field" in out.err
    assert out.out.count("hazard ") == 25, "every frame after it is still decoded"


def test_lost_frames_make_a_non_zero_exit(tmp_path, capsys):
    fs = frames(12)
    kept = fs[:8] + fs[20:]                   # 6 cycles missing: 6 hazard and 6 status frames
    log = tmp_path / "lost.log"
    log.write_text("".join(candump(f, d, i * 0.05) for i, (f, d) in enumerate(kept)))
    assert listen_cli.main(["--can-log", str(log)]) == 1
    err = capsys.readouterr().err
    assert "12 lost" in err


def test_listen_stopped_by_sigint_keeps_its_bad_crc_count(monkeypatch, capsys):
    import serial

    from bsn_edge.alerts.serial_codec import encode_frame
    good = [encode_frame(f, d) for f, d in frames(2)]
    broken = bytearray(good[2])
    broken[3] ^= 0x10                          # inside the COBS body: the frame's CRC-16 fails

    class Port:
        """Two good frames, one damaged, one good; then the user presses Ctrl-C."""

        def __init__(self) -> None:
            self.chunks = [good[0] + good[1], bytes(broken), good[3]]

        def __enter__(self):
            return self

        def __exit__(self, *exc):
            return False

        def read(self, n):
            if not self.chunks:
                raise KeyboardInterrupt
            return self.chunks.pop(0)

    monkeypatch.setattr(serial, "serial_for_url", lambda url, timeout=None: Port())
    assert listen_cli.main(["--serial", "loop://"]) == 1
    err = capsys.readouterr().err
    assert "3 frames, 1 with a bad CRC" in err


def pack(fields: list[tuple[int, int, int]]) -> bytes:
    """Little-endian (Intel) bit packing of (value, start bit, length) into 7 bytes, by hand."""
    v = 0
    for value, start, length in fields:
        assert 0 <= value < 1 << length
        v |= value << start
    return v.to_bytes(7, "little")


def test_can_frames_are_the_dbc_layout_to_the_bit_with_the_data_id_in_the_crc():
    """Golden frames: the payload packed by hand from the DBC's start bits and scales, the CRC-8
    (catalogue-checked above) over the data ID's two bytes and the payload."""
    enc = CanEncoder()
    f = AlertFrame(0.0, (SectorAlert(1.0, Level.WARNING, 4.5), SectorAlert(0.0, Level.NONE, None),
                        SectorAlert(0.3, Level.CAUTION, 20.0)), SystemState.DEGRADED, 23.5,
                   {"dropped_frames": 3, "decode_errors": 1, "nan_outputs": 2, "tx_errors": 4, "sink_errors": 5})
    (hid, hz), (sid, st) = enc.encode(f)
    assert (hid, sid) == (0x500, 0x501)
    # levels 2 / 0 / 1; scores x127; distances x2 (63.5 = none); counter 0
    want_hz = pack([(2, 0, 2), (0, 2, 2), (1, 4, 2), (127, 8, 7), (0, 15, 7), (38, 22, 7), (9, 29, 7),
                    (127, 36, 7), (40, 43, 7), (0, 52, 4)])
    want_st = pack([(1, 0, 2), (5, 2, 6), (47, 8, 8), (1, 16, 8), (3, 24, 8), (2, 32, 8), (4, 40, 8), (0, 52, 4)])
    assert hz[:7] == want_hz and hz[7] == crc8_sae_j1850(bytes([0x00, 0x05]) + want_hz)
    assert st[:7] == want_st and st[7] == crc8_sae_j1850(bytes([0x01, 0x05]) + want_st)
    assert hz.hex() == "127f8029f1470189" and st.hex() == "152f0103020400b9"


def test_a_hazard_payload_under_the_status_id_fails_its_crc():
    from bsn_edge.alerts.can_codec import decode
    none = SectorAlert(0.0, Level.NONE, None)
    (hid, hz), (sid, _) = CanEncoder().encode(AlertFrame(0.0, (none,) * 3, SystemState.OK, 10.0, {}))
    assert decode(hid, hz).crc_ok
    assert not decode(sid, hz).crc_ok, "the data ID is in the CRC: a frame cannot pass for another message"


def _with_a_gap() -> list[tuple[int, bytes]]:
    fs = frames(10)
    return fs[:6] + fs[10:]                    # cycles 3 and 4 missing: 2 hazard and 2 status frames


def test_listen_on_a_can_bus_counts_lost_frames(monkeypatch, capsys):
    """``--can virtual:CH``: the frames bsn-run sends on a bus, read off it, the missing cycles counted."""
    import can

    listener = can.Bus(interface="virtual", channel="bsn-listen-test")     # queues from here on
    opened = []

    def bus(interface, channel):
        opened.append((interface, channel))
        return listener

    with can.Bus(interface="virtual", channel="bsn-listen-test") as sender:
        for fid, data in _with_a_gap():
            sender.send(can.Message(arbitration_id=fid, data=data, is_extended_id=False))
    monkeypatch.setattr(can, "Bus", bus)
    assert listen_cli.main(["--can", "virtual:bsn-listen-test", "--max", "16"]) == 1
    out = capsys.readouterr()
    assert opened == [("virtual", "bsn-listen-test")]
    assert "16 frames, 0 with a bad CRC, 4 lost, 0 repeated" in out.err
    assert out.out.count("(2 lost)") == 2 and out.out.count("hazard ") == 8


def test_listen_on_a_serial_port_counts_lost_frames(monkeypatch, capsys):
    """``--serial URL``: COBS frames off a pyserial loopback port, the missing cycles counted."""
    import serial

    from bsn_edge.alerts.serial_codec import encode_frame
    port = serial.serial_for_url("loop://", timeout=0.2)
    port.write(b"".join(encode_frame(f, d) for f, d in _with_a_gap()))
    opened = []

    def open_url(url, timeout=None):
        opened.append(url)
        return port

    monkeypatch.setattr(serial, "serial_for_url", open_url)
    assert listen_cli.main(["--serial", "loop://", "--max", "16"]) == 1
    out = capsys.readouterr()
    assert opened == ["loop://"]
    assert "16 frames, 0 with a bad CRC, 4 lost, 0 repeated" in out.err
    assert out.out.count("(2 lost)") == 2 and out.out.count("status ") == 8


def test_a_counter_outside_the_dbcs_range_is_flagged_and_moves_no_counter(tmp_path, capsys):
    """Alive counters run 0-14 (the DBC's range; 15 is reserved as invalid). A frame with a good CRC and
    a counter of 15 is flagged and moves no counter state: the counters around it count the one
    frame it stood in for as lost (9 -> 11), not the 20 that counting from 15 and back would make."""
    from bsn_edge.alerts.e2e import e2e_crc
    fs = frames(25)
    hid, data = fs[20]                        # frame 10's hazard message
    bad = bytearray(data)
    bad[6] |= 0xF0                            # Hazard_Counter (bits 52-55) = 15
    bad[7] = e2e_crc(bytes(bad[:7]), hid)
    fs[20] = (hid, bytes(bad))
    log = tmp_path / "c15.log"
    log.write_text("".join(candump(f, d, i * 0.05) for i, (f, d) in enumerate(fs)))
    assert listen_cli.main(["--can-log", str(log)]) == 1
    out = capsys.readouterr()
    assert "(counter 15 outside 0-14)" in out.out
    assert "1 lost" in out.err and "1 with an undefined field" in out.err


def test_a_huge_bad_line_is_echoed_short_and_a_file_of_another_kind_exits_1(tmp_path, capsys):
    log = tmp_path / "big.log"
    log.write_text("x" * 1_000_000 + "\n" + "(1.000000) vcan0 500#" + "00" * 400_000 + "\n")
    assert listen_cli.main(["--can-log", str(log)]) == 1
    err = capsys.readouterr().err
    assert len(err) < 2000 and "a line of 1000001 bytes" in err and "2 unreadable lines" in err, err
    blf = tmp_path / "random.blf"
    blf.write_bytes(bytes(range(256)) * 40)
    assert listen_cli.main(["--can-log", str(blf)]) == 1          # as documented: something was wrong
    err = capsys.readouterr().err
    assert "unreadable" in err and "0 frames" in err


def test_every_decode_fault_reaches_the_bus_frames_of_another_size_included():
    """Decode_Errors carries every frame that gave the model nothing to read: 2 that would not decode
    and 3 of another size make 5 in byte 2, packed by hand; the other counters are their own."""
    none = SectorAlert(0.0, Level.NONE, None)
    f = AlertFrame(0.0, (none,) * 3, SystemState.OK, 10.0,
                   {"decode_errors": 2, "size_changes": 3, "dropped_frames": 7})
    _, (_, st) = CanEncoder().encode(f)
    want = pack([(0, 0, 2), (0, 2, 6), (20, 8, 8), (5, 16, 8), (7, 24, 8), (0, 32, 8), (0, 40, 8), (0, 52, 4)])
    assert st[:7] == want and st[7] == crc8_sae_j1850(bytes([0x01, 0x05]) + want)
    many = AlertFrame(0.0, (none,) * 3, SystemState.OK, 10.0, {"decode_errors": 200, "size_changes": 100})
    assert CanEncoder().encode(many)[1][1][2] == 255, "the sum saturates at 255"


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGHUP])
def test_listen_ended_by_a_service_manager_or_a_closed_terminal_prints_its_summary(sig):
    """TERM and HUP end listening as Ctrl-C does: the summary on standard error, no death by the signal."""
    proc = subprocess.Popen([sys.executable, "-m", "bsn_edge.cli.listen", "--serial", "loop://"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    time.sleep(1.5)                        # past its imports, listening
    proc.send_signal(sig)
    proc.send_signal(signal.SIGINT)        # the first signal decides
    _, err = proc.communicate(timeout=20)
    assert proc.returncode in (0, 1), (proc.returncode, err)
    assert "0 frames, 0 with a bad CRC" in err


def test_a_stuck_counter_alone_fails_the_log(tmp_path, capsys):
    # every CRC good, nothing lost: the only fault is a hazard frame sent twice with one counter
    fs = frames(6)
    fs.insert(4, fs[4])                        # cycle 2's hazard frame repeated
    log = tmp_path / "stuck.log"
    log.write_text("".join(candump(f, d, i * 0.05) for i, (f, d) in enumerate(fs)))
    assert listen_cli.main(["--can-log", str(log)]) == 1, "a repeated frame alone must fail the log"
    err = capsys.readouterr().err
    assert "13 frames, 0 with a bad CRC, 0 lost, 1 repeated, 0 with an undefined field" in err, err


def test_a_frame_with_two_wrong_fields_is_counted_once(tmp_path, capsys):
    from bsn_edge.alerts.e2e import e2e_crc
    fs = frames(4)
    hid, data = fs[2]
    bad = bytearray(data)
    bad[0] |= 0x03                             # Left_Level = 3
    bad[6] = (bad[6] & 0x0F) | 0xF0            # the counter's nibble = 15, outside 0..14
    bad[7] = e2e_crc(bytes(bad[:7]), hid)      # a good CRC over both
    fs[2] = (hid, bytes(bad))
    log = tmp_path / "two.log"
    log.write_text("".join(candump(f, d, i * 0.05) for i, (f, d) in enumerate(fs)))
    assert listen_cli.main(["--can-log", str(log)]) == 1
    err = capsys.readouterr().err
    assert "8 frames, 0 with a bad CRC" in err and "1 with an undefined field" in err, err


def test_a_silent_bus_is_flagged_and_every_frame_is_timed(tmp_path, capsys):
    # every frame whole, nothing lost by the counters: only the bus fell silent for 5 s
    fs = frames(6)
    times = [i * 0.05 for i in range(6)] + [5.3 + i * 0.05 for i in range(6)]
    log = tmp_path / "silent.log"
    log.write_text("".join(candump(f, d, t) for (f, d), t in zip(fs, times, strict=True)))
    assert listen_cli.main(["--can-log", str(log)]) == 1
    out = capsys.readouterr()
    assert "1 silences over 1.5 s" in out.err and "silent 5.10 s" in out.out, (out.out, out.err)
    assert out.out.splitlines()[0].lstrip().startswith("0.000 s"), out.out.splitlines()[0]
