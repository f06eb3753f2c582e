"""CAN on python-can's virtual bus and serial on pyserial's loop://: round trips, E2E checks, faults."""

import binascii
import itertools
import shutil
import subprocess
import time

import can
import pytest
import serial

from bsn_edge.alerts import AlertFrame, Fault, Level, SectorAlert, SystemState
from bsn_edge.alerts.can_codec import HAZARD, STATUS, decode
from bsn_edge.alerts.can_output import CanSender
from bsn_edge.alerts.e2e import counter_gap
from bsn_edge.alerts.serial_codec import FrameDecoder, cobs_decode, cobs_encode
from bsn_edge.alerts.serial_output import SerialSender
from tests.fakes import FullBus, GonePort


def frame(t=0.0, state=SystemState.OK):
    return AlertFrame(t, (SectorAlert(0.8, Level.WARNING, 4.5), SectorAlert(0.0, Level.NONE, None),
                          SectorAlert(0.3, Level.CAUTION, 12.0)), state, 23.5, {"dropped_frames": 3, "nan_outputs": 1})


def test_can_round_trip_on_a_virtual_bus(tmp_path):
    log = tmp_path / "alerts.asc"
    with can.Bus(interface="virtual", channel="bsn-test-1", receive_own_messages=False) as rx, \
            CanSender("virtual", "bsn-test-1", log_path=str(log)) as tx:
        for k in range(20):
            assert tx.send(frame(k * 0.1))
        got = [rx.recv(timeout=1.0) for _ in range(40)]
    assert all(m is not None for m in got)
    decoded = [decode(m.arbitration_id, m.data) for m in got]
    hz = [d for d in decoded if d.name == HAZARD]
    st = [d for d in decoded if d.name == STATUS]
    assert len(hz) == len(st) == 20 and all(d.crc_ok for d in decoded)
    assert [d.counter for d in hz] == [k % 15 for k in range(20)]
    assert all(counter_gap(a.counter, b.counter) == 0 for a, b in itertools.pairwise(hz))
    s = hz[0].signals
    assert (s["Left_Level"], s["Centre_Level"], s["Right_Level"]) == (2, 0, 1)
    assert s["Left_Distance"] == 4.5 and s["Centre_Distance"] == 63.5
    assert s["Right_Score"] == pytest.approx(0.3, abs=0.01)
    assert st[0].signals["Frame_Rate"] == 23.5 and st[0].signals["Dropped_Frames"] == 3
    assert log.read_text().count("Rx") + log.read_text().count("Tx") >= 40


def test_a_blf_can_log_holds_all_but_its_last_block_while_the_run_lives(tmp_path):
    """What a kill leaves: the file as it is before the log is closed. BLF's default block (128 KiB, about a
    minute of cycles) once left a 40 s drive's log empty; a reader other than the writer counts the frames."""
    log = tmp_path / "alerts.blf"
    with can.Bus(interface="virtual", channel="bsn-test-blf") as _, \
            CanSender("virtual", "bsn-test-blf", log_path=str(log)) as tx:
        for k in range(100):                        # 5 s of cycles: 200 frames
            assert tx.send(frame(k * 0.05))
        killed = tmp_path / "killed.blf"
        shutil.copyfile(log, killed)
    frames = sum(1 for _ in can.BLFReader(str(killed)))
    assert 200 - 40 <= frames < 200, frames        # a block is about 20 frames, half a second of them
    assert sum(1 for _ in can.BLFReader(str(log))) == 200


def test_corrupted_crc_is_rejected():
    with can.Bus(interface="virtual", channel="bsn-test-2") as rx, CanSender("virtual", "bsn-test-2") as tx:
        tx.send(frame())
        m = rx.recv(timeout=1.0)
    data = bytearray(m.data)
    data[2] ^= 0x10
    assert not decode(m.arbitration_id, bytes(data)).crc_ok
    assert decode(m.arbitration_id, m.data).crc_ok
    assert decode(0x7FF, bytes(8)) is None


def test_a_failing_bus_is_counted_never_raised():
    tx = CanSender("virtual", "unused", bus=FullBus())
    for _ in range(2):   # each send reports what it met, not a running total
        sent = tx.send(frame())
        assert not sent.ok and sent.faults == {Fault.TX_FULL: 1, Fault.TX_ERRORS: 1}
    assert tx.stats.errors == 2 and tx.stats.full == 2 and "buffer full" in tx.stats.last_error
    tx.close()
    tx.close()  # idempotent
    sent = tx.send(frame())
    assert not sent.ok and sent.faults == {Fault.TX_ERRORS: 1} and "closed" in tx.stats.last_error


def test_serial_round_trip_on_loop():
    port = serial.serial_for_url("loop://", timeout=0.1)
    tx = SerialSender("loop://", port=port)
    for k in range(5):
        assert tx.send(frame(k * 0.1))
    dec = FrameDecoder()
    got = list(dec.feed(port.read(4096)))
    assert len(got) == 10 and dec.errors == 0
    d = [decode(fid, data) for fid, data in got]
    assert all(x.crc_ok for x in d) and d[0].signals["Left_Level"] == 2
    tx.close()


def test_serial_decoder_resyncs_after_garbage():
    from bsn_edge.alerts.serial_codec import encode_frame
    good = encode_frame(0x500, bytes(range(8)))
    bad = bytearray(good)
    bad[5] ^= 0xFF
    dec = FrameDecoder()
    out = list(dec.feed(b"\x13\x37junk\x00" + bytes(bad) + good[:4]))
    out += list(dec.feed(good[4:]))
    assert out == [(0x500, bytes(range(8)))] and dec.errors == 2
    for blob in (b"", b"\x00", bytes(300), bytes(range(1, 256)) * 2):
        assert cobs_decode(cobs_encode(blob)) == blob


def test_a_vanished_serial_port_is_counted_and_reopened():
    tx = SerialSender("loop://", port=GonePort(), retry_s=0.0)
    sent = tx.send(frame())
    assert not sent.ok and sent.faults == {Fault.SERIAL_ERRORS: 1} and "disconnected" in tx.stats.last_error
    sent = tx.send(frame())
    assert sent.ok and not sent.faults and tx.stats.reconnects == 1   # loop:// opens again


@pytest.mark.skipif(shutil.which("socat") is None, reason="socat is not installed")
def test_serial_across_processes_through_a_pty_pair(tmp_path):
    a, b = tmp_path / "a", tmp_path / "b"
    proc = subprocess.Popen(["socat", f"pty,raw,echo=0,link={a}", f"pty,raw,echo=0,link={b}"])
    # each wait ends as soon as its condition holds; the deadlines only bound a failure
    try:
        deadline = time.monotonic() + 30
        while not (a.exists() and b.exists()) and time.monotonic() < deadline:
            time.sleep(0.01)
        rx = serial.Serial(str(b), timeout=0.1)
        with SerialSender(str(a)) as tx:
            assert tx.send(frame())
        dec, got = FrameDecoder(), []
        while len(got) < 2 and time.monotonic() < deadline:
            got += dec.feed(rx.read(64))
        assert len(got) == 2 and all(decode(f, d).crc_ok for f, d in got) and dec.errors == 0
        rx.close()
    finally:
        proc.terminate()
        proc.wait(timeout=5)


def test_only_a_full_transmit_queue_counts_as_full():
    """python-can says "full" only in words (socketcan) or as the kernel's ENOBUFS; any other send
    error is an error, not a full queue."""
    import errno

    from bsn_edge.alerts.senders import transmit_buffer_full
    assert transmit_buffer_full(can.CanOperationError("Transmit buffer full"))
    assert transmit_buffer_full(can.CanOperationError("Failed to transmit: No buffer space available",
                                                      error_code=errno.ENOBUFS))
    assert not transmit_buffer_full(can.CanOperationError("Failed to transmit: Network is down",
                                                          error_code=errno.ENETDOWN))
    assert not transmit_buffer_full(can.CanOperationError("bus off"))


def test_a_frame_with_a_good_crc_but_a_wrong_magic_byte_is_an_error():
    """The CRC covers the magic byte, so a frame of another protocol on the same port can pass it:
    the decoder refuses it by its magic (CRC-16/CCITT-FALSE from the standard library's crc_hqx)."""
    for magic in (b"A", b"\x00", b"\xff"):
        body = magic + (7).to_bytes(2, "little") + b"\x01\x02\x03"
        wire = cobs_encode(body + binascii.crc_hqx(body, 0xFFFF).to_bytes(2, "little")) + b"\x00"
        dec = FrameDecoder()
        assert list(dec.feed(wire)) == [] and dec.errors == 1, magic
    body = b"B" + (7).to_bytes(2, "little") + b"\x01\x02\x03"      # the same frame with the right magic
    dec = FrameDecoder()
    wire = cobs_encode(body + binascii.crc_hqx(body, 0xFFFF).to_bytes(2, "little")) + b"\x00"
    assert list(dec.feed(wire)) == [(7, b"\x01\x02\x03")] and dec.errors == 0
