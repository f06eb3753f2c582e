"""What a source hands out: every picture of an MJPEG file or stream at the size its own header declares
(FFmpeg scales them all to the first one's), and a paced folder on its pictures' own times."""

from __future__ import annotations

import http.server
import json
import socketserver
import threading

import cv2
import numpy as np

from bsn_edge.runtime.live_source import LiveSource, Reconnect, open_capture
from bsn_edge.runtime.sources import ImageFolderSource, VideoFileSource
from tests.runtime.test_untrusted_inputs import bsn_run

PORTRAIT = range(6, 9)      # the frames of the 15-frame clip turned on their side


def mjpeg_pictures(clip) -> list[bytes]:
    """The clip's 15 frames as JPEGs, frames 6-8 transposed (96x192 becomes 192x96)."""
    out = []
    for i, p in enumerate(sorted((clip / "rgb").iterdir())):
        img = cv2.imread(str(p))
        out.append(cv2.imencode(".jpg", img.transpose(1, 0, 2).copy() if i in PORTRAIT else img)[1].tobytes())
    return out


def test_a_picture_of_another_size_in_an_mjpeg_file_arrives_at_its_own_size_and_is_never_run(setup, tmp_path):
    model, clip = setup
    pictures = mjpeg_pictures(clip)
    stream = tmp_path / "drive.mjpeg"
    stream.write_bytes(b"".join(pictures))
    truth = [cv2.imdecode(np.frombuffer(j, np.uint8), cv2.IMREAD_COLOR).shape for j in pictures]
    src = VideoFileSource(stream)
    try:
        shapes = [c.frame.shape for c in src if c.frame is not None]
    finally:
        src.close()
    assert shapes == truth, shapes
    summary = tmp_path / "s.json"
    r = bsn_run("--model", str(model), "--source", str(stream), "--summary", str(summary), "--allow-unsigned",
                "--set", "visibility.enabled=false")
    s = json.loads(summary.read_text())
    assert r.returncode == 0 and s["frames"] == 15, (r.returncode, r.stderr[-400:])
    assert s["faults"].get("size_changes") == len(PORTRAIT) and s["valid_frames"] == 15 - len(PORTRAIT), s["faults"]


class Turning(http.server.BaseHTTPRequestHandler):
    """An MJPEG stream of two landscape pictures, then ten portrait ones, then the end."""

    def log_message(self, *args):
        pass

    def do_GET(self):
        self.send_response(200)
        self.send_header("Content-Type", "multipart/x-mixed-replace; boundary=frame")
        self.end_headers()
        for i in range(12):
            shape = (48, 96, 3) if i < 2 else (96, 48, 3)
            _, jpg = cv2.imencode(".jpg", np.full(shape, 20 * i, np.uint8))
            self.wfile.write(b"--frame\r\nContent-Type: image/jpeg\r\nContent-Length: %d\r\n\r\n" % len(jpg)
                             + jpg.tobytes() + b"\r\n")
            self.wfile.flush()


def test_a_live_mjpeg_stream_that_turns_portrait_delivers_portrait_frames():
    srv = socketserver.ThreadingTCPServer(("127.0.0.1", 0), Turning)
    srv.daemon_threads = True
    threading.Thread(target=srv.serve_forever, daemon=True).start()
    url = f"http://127.0.0.1:{srv.server_address[1]}/stream.mjpg"
    src = LiveSource(url, Reconnect(stall_s=2.0, max_tries=0), opener=lambda t: open_capture(t, 2.0))
    seen: list[tuple[int, tuple[int, ...]]] = []
    try:
        for item in src:            # the newest frame wins: a slow reader sees some of them, the last one always
            assert item.frame is not None
            seen.append((item.index, item.frame.shape))
    finally:
        src.close()
        srv.shutdown()
        srv.server_close()
    assert seen and all(shape == ((48, 96, 3) if i < 2 else (96, 48, 3)) for i, shape in seen), seen
    assert seen[-1] == (11, (96, 48, 3)), seen


class VirtualTime:
    """A clock that moves only when the source waits: pacing is seen whatever the machine's speed."""

    def __init__(self) -> None:
        self.now, self.waits = 100.0, []

    def clock(self) -> float:
        return self.now

    def wait(self, seconds: float) -> bool:
        self.waits.append(seconds)
        self.now += seconds
        return False


def test_a_paced_folder_hands_out_each_picture_at_its_own_time(setup):
    _, clip = setup
    t = VirtualTime()
    src = ImageFolderSource(clip / "rgb", fps=10.0, pace=True, clock=t.clock, wait=t.wait)
    handed = [(t.now, c.t) for c in src]
    assert len(handed) == 15
    assert all(abs(now - (100.0 + frame_t)) < 1e-9 for now, frame_t in handed), handed
    unpaced = VirtualTime()
    assert len(list(ImageFolderSource(clip / "rgb", fps=10.0, clock=unpaced.clock, wait=unpaced.wait))) == 15
    assert unpaced.waits == []


def test_a_stop_ends_a_paced_wait_at_once(setup):
    _, clip = setup
    src = ImageFolderSource(clip / "rgb", fps=0.01, pace=True)      # 100 s between pictures
    frames = iter(src)
    next(frames)
    threading.Timer(0.2, src.stop).start()
    assert list(frames) == []        # returns on the stop, not after 100 s (the suite's timeout would catch it)


def test_a_picture_replaced_by_a_fifo_mid_run_is_a_damaged_frame_not_a_hang(setup, tmp_path):
    """The folder is listed when the run starts; a picture that becomes a FIFO afterwards (nobody writes
    into it) once blocked the read for good, and only SIGKILL ended the run."""
    import os
    import shutil

    from tests.fakes import BUSY_S

    _, clip = setup
    frames = tmp_path / "frames"
    shutil.copytree(clip / "rgb", frames)
    src = ImageFolderSource(frames)
    victim = src.files[5]
    victim.unlink()
    os.mkfifo(victim)
    got: list = []
    reader = threading.Thread(target=lambda: got.extend(c.frame is None for c in src), daemon=True)
    reader.start()
    reader.join(BUSY_S)
    assert not reader.is_alive(), "the read of the FIFO blocked"
    assert got == [i == 5 for i in range(15)], got
