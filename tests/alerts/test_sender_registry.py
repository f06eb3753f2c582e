"""Encoding apart from transport: a sender carries what its encoder gives it, and senders are opened by the
output's scheme from one registry (a new bus is one class and one entry)."""

import can
import pytest

from bsn_edge.alerts.can_codec import CanEncoder
from bsn_edge.alerts.frame import AlertFrame
from bsn_edge.alerts.senders import SENDERS, CanSender, SerialSender, open_sender


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
    assert set(SENDERS) == {"can", "serial"}


@pytest.mark.parametrize("output", ["udp:127.0.0.1:9000", "can", "serial:", "can:virtual"])
def test_an_output_of_no_known_scheme_or_target_is_refused_naming_the_schemes(output):
    with pytest.raises(ValueError, match=r"can:|serial"):
        open_sender(output)
