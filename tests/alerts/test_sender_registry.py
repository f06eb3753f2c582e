"""Encoding apart from transport: a sender carries what its encoder gives it, and senders are opened by the
output's scheme from one registry (a new bus is one class and one entry)."""

import sys

import can
import pytest

from bsn_edge.alerts.can_codec import CanEncoder
from bsn_edge.alerts.can_output import CanSender
from bsn_edge.alerts.frame import AlertFrame
from bsn_edge.alerts.senders import SENDERS, open_sender
from bsn_edge.alerts.serial_output import SerialSender


class Fixed:
    """An encoder of another protocol: one frame of its own, whatever the alert."""

    def encode(self, frame, messages=None):
        return [(0x7AB, b"\x01\x02\x03")]


def test_a_can_sender_carries_what_its_encoder_gives_it():
    with can.Bus(interface="virtual", channel="bsn-reg-enc") as rx, \
            open_sender("can:virtual:bsn-reg-enc", Fixed()) as tx:
        assert isinstance(tx, CanSender) and tx.send(AlertFrame.unavailable(0.0))
        m = rx.recv(1.0)
    assert (m.arbitration_id, bytes(m.data)) == (0x7AB, b"\x01\x02\x03")


def test_the_default_encoder_is_the_protocols_and_serial_is_a_scheme():
    with open_sender("serial:loop://") as tx:
        assert isinstance(tx, SerialSender) and isinstance(tx.encoder, CanEncoder)
        assert tx.send(AlertFrame.unavailable(0.0))
    assert set(SENDERS) == {"can", "serial", "udp"}


@pytest.mark.parametrize("output", ["tcp:127.0.0.1:9000", "can", "serial:", "can:virtual", "udp:9000",
                                    "udp:127.0.0.1:0", "udp:127.0.0.1:70000", "udp::9000"])
def test_an_output_of_no_known_scheme_or_target_is_refused_naming_the_schemes(output):
    with pytest.raises(ValueError, match=r"can:|serial|udp:"):
        open_sender(output)


def test_a_new_output_is_one_class_with_a_scheme():
    """A Sender subclass that names a scheme is openable by it, with nothing else edited."""
    from bsn_edge.alerts.senders import Sender

    got: list = []

    class Collect(Sender):
        scheme = "collect-test"

        def _send(self, frames):
            got.append(frames)

        @classmethod
        def from_target(cls, target, encoder, log_path, bus):
            return cls(encoder)

    try:
        with open_sender("collect-test:anything") as tx:
            assert tx.send(AlertFrame.unavailable(0.0)) and len(got[0]) == 2
    finally:
        SENDERS.pop("collect-test")


def _udp_frames(datagram: bytes) -> list[tuple[float, int, bytes]]:
    """The datagram's layout as docs/protocol.md gives it, read here with struct (not the sender's code)."""
    import struct

    assert datagram[:4] == b"BSN1"
    out, k = [], 4
    while k < len(datagram):
        t, fid, n = struct.unpack_from(">dIB", datagram, k)
        out.append((t, fid, datagram[k + 13: k + 13 + n]))
        k += 13 + n
    return out


def test_udp_carries_the_bus_frames_in_datagrams_that_the_dbc_decodes():
    """One datagram a cycle holding the CAN frames, each with its time, id and bytes; cantools decodes them from
    the shipped DBC, counters and CRCs as the CAN bus carries them."""
    import socket
    import time

    import cantools

    from bsn_edge.alerts import Level, SectorAlert, SystemState
    from bsn_edge.alerts.can_codec import DBC_PATH
    from bsn_edge.alerts.e2e import e2e_crc

    db = cantools.database.load_file(str(DBC_PATH))
    rx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    rx.bind(("127.0.0.1", 0))
    rx.settimeout(2.0)
    warn = SectorAlert(0.9, Level.WARNING, 3.0)
    none = SectorAlert(0.0, Level.NONE, None)
    before = time.time()
    with rx, open_sender(f"udp:127.0.0.1:{rx.getsockname()[1]}") as tx:
        for k in range(3):
            assert tx.send(AlertFrame(0.1 * k, (none, none, warn), SystemState.OK, 20.0, {}))
        got = [_udp_frames(rx.recv(2048)) for _ in range(3)]
    for k, frames in enumerate(got):
        assert [fid for _, fid, _ in frames] == [0x500, 0x501]
        for t, fid, data in frames:
            assert before <= t <= time.time() and data[7] == e2e_crc(data[:7], fid)
            values = db.get_message_by_frame_id(fid).decode(data, decode_choices=False)
            if fid == 0x500:
                assert values["Right_Level"] == 2 and values["Left_Level"] == 0 and values["Hazard_Counter"] == k
            else:
                assert values["System_State"] == 0 and values["Status_Counter"] == k


def test_udp_to_nobody_is_a_counted_failed_send_never_an_exception():
    """Nobody listens: the network's refusal (ICMP port unreachable) comes back on the connected socket and
    each refused send is counted as a transmit error, which the status message carries."""
    import socket

    from bsn_edge.alerts.health import Fault

    probe = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    probe.bind(("127.0.0.1", 0))
    port = probe.getsockname()[1]
    probe.close()                          # a port just freed: nobody is listening there
    with open_sender(f"udp:127.0.0.1:{port}") as tx:
        sent = [tx.send(AlertFrame.unavailable(0.1 * k)) for k in range(6)]
    failed = [s for s in sent if not s.ok]
    assert failed and all(s.faults.get(Fault.TX_ERRORS) == 1 for s in failed), sent
    assert tx.stats.errors == len(failed) and "Connection refused" in tx.stats.last_error


def test_bsn_listen_judges_the_udp_datagrams_and_counts_one_of_another_layout(capsys):
    """``bsn-listen --udp PORT``: each frame of bsn-run's datagrams printed and checked as a CAN bus's are; a
    datagram that is not of the layout is counted as unreadable (exit 1), the rest still read."""
    import socket
    import threading
    import time

    from bsn_edge.cli import listen

    probe = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    probe.bind(("127.0.0.1", 0))
    port = probe.getsockname()[1]
    probe.close()
    codes = []
    t = threading.Thread(target=lambda: codes.append(listen.main(["--udp", f"127.0.0.1:{port}", "--max", "6",
                                                                  "--duration", "20"])))
    t.start()
    time.sleep(0.5)                        # the listener binds first
    with open_sender(f"udp:127.0.0.1:{port}") as tx, socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as junk:
        junk.sendto(b"XXXX not ours", ("127.0.0.1", port))
        for k in range(3):
            tx.send(AlertFrame.unavailable(0.1 * k))
            time.sleep(0.05)
    t.join(25)
    out = capsys.readouterr()
    assert codes == [1] and out.out.count("[alive") == 6, (codes, out)
    assert "datagram 1: not a bsn-run datagram" in out.err and "1 unreadable lines" in out.err


def test_a_new_output_is_one_new_file(tmp_path, monkeypatch):
    """A module named ``*_output`` beside the package's outputs is found by name, its sender opened by its scheme
    (written here to a folder of the package's path, as a file in ``bsn_edge/alerts`` would be), with the
    layout's encoder and the vehicle file's settings: nothing else is edited."""
    import bsn_edge.alerts as package
    from bsn_edge.alerts import senders
    from bsn_edge.alerts.bus_config import BusConfig

    (tmp_path / "memory_output.py").write_text(
        "from bsn_edge.alerts.senders import Sender\n\n"
        "class MemorySender(Sender):\n"
        "    name = scheme = 'memory'\n"
        "    kept: list = []\n\n"
        "    @classmethod\n"
        "    def from_target(cls, target, encoder, log_path, bus):\n"
        "        return cls(encoder)\n\n"
        "    def _send(self, frames):\n"
        "        self.kept.extend(frames)\n")
    monkeypatch.setattr(package, "__path__", [*package.__path__, str(tmp_path)])
    monkeypatch.delitem(SENDERS, "memory", raising=False)
    senders.load_outputs.cache_clear()
    try:
        with senders.open_sender("memory:anything", bus=BusConfig()) as tx:
            assert type(tx).__name__ == "MemorySender" and tx.send(AlertFrame.unavailable(0.0))
            assert [fid for fid, _ in tx.kept] == [0x500, 0x501], "the protocol's frames, encoded for it"
    finally:
        SENDERS.pop("memory", None)
        sys.modules.pop("bsn_edge.alerts.memory_output", None)
        senders.load_outputs.cache_clear()


def test_the_outputs_are_found_by_their_modules_names():
    from bsn_edge.alerts.senders import load_outputs

    assert {"can", "serial", "udp"} <= set(load_outputs())
