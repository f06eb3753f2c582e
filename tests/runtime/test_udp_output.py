"""bsn-run's outputs as data: ``--output SCHEME:TARGET`` and the vehicle file's ``[bus] outputs`` open any
registered sender; proved with UDP, whose datagrams carry the very frames the CAN log holds."""

import socket
import struct

import can

from bsn_edge.cli import run as run_cli


def _frames(datagram: bytes) -> list[tuple[int, bytes]]:
    """(id, bytes) of each frame, by docs/protocol.md's layout (read here with struct)."""
    assert datagram[:4] == b"BSN1"
    out, k = [], 4
    while k < len(datagram):
        _, fid, n = struct.unpack_from(">dIB", datagram, k)
        out.append((fid, datagram[k + 13: k + 13 + n]))
        k += 13 + n
    return out


def _receiver() -> socket.socket:
    rx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    rx.bind(("127.0.0.1", 0))
    rx.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 20)     # the whole run's datagrams, read after it
    rx.settimeout(0.5)
    return rx


def _drain(rx: socket.socket) -> list[tuple[int, bytes]]:
    got = []
    try:
        while True:
            got += _frames(rx.recv(4096))
    except TimeoutError:
        return got


def test_a_udp_output_named_on_the_command_line_carries_what_the_can_log_holds(setup, tmp_path):
    model, clip = setup
    log = tmp_path / "c.log"
    with _receiver() as rx:
        assert run_cli.main(["--model", str(model), "--source", str(clip / "video.mp4"), "--calib",
                             str(clip / "calibration.json"), "--can-log", str(log),
                             "--output", f"udp:127.0.0.1:{rx.getsockname()[1]}"]) == 0
        got = _drain(rx)
    on_can = [(m.arbitration_id, bytes(m.data)) for m in can.LogReader(str(log))]
    assert len(on_can) >= 30 and got == on_can


def test_the_vehicle_files_outputs_are_opened_and_a_bad_one_is_refused_by_its_key(setup, tmp_path, capsys):
    model, clip = setup
    with _receiver() as rx:
        cfg = tmp_path / "car.toml"
        cfg.write_text(f'[bus]\noutputs = ["udp:127.0.0.1:{rx.getsockname()[1]}"]\n')
        assert run_cli.main(["--model", str(model), "--source", str(clip / "video.mp4"), "--calib",
                             str(clip / "calibration.json"), "--config", str(cfg)]) == 0
        got = _drain(rx)
    assert len(got) >= 30 and {fid for fid, _ in got} == {0x500, 0x501}
    capsys.readouterr()
    cfg.write_text('[bus]\noutputs = ["tcp:127.0.0.1:9000"]\n')
    assert run_cli.main(["--model", str(model), "--source", str(clip / "video.mp4"), "--config", str(cfg)]) == 2
    err = capsys.readouterr().err
    assert "bus.outputs" in err and "udp" in err, err
    assert run_cli.main(["--model", str(model), "--source", str(clip / "video.mp4"), "--output", "udp:nohost"]) == 2
    assert "udp:HOST:PORT" in capsys.readouterr().err
