"""Stand-ins for hardware that fails, shared by the alerts and runtime tests."""

import can
import serial


class FullBus:
    """A CAN bus whose transmit buffer is always full."""

    def send(self, msg, timeout=None):
        raise can.CanOperationError("Transmit buffer full")

    def shutdown(self):
        pass


class GonePort:
    """A serial port that was unplugged."""

    is_open = True

    def write(self, data):
        raise serial.SerialException("device disconnected")

    def close(self):
        pass
