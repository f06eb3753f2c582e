"""A network stream that stalls, then refuses: the stall is seen within --stall seconds (not FFmpeg's
default 30), reconnects are counted, and the source fails with a reason once nothing comes back.
Against a local HTTP server (MJPEG over HTTP, as IP cameras serve it)."""

import http.server
import socketserver
import threading
import time

import cv2
import numpy as np

from bsn_edge.runtime.live_source import LiveSource, Reconnect, open_capture

FRAMES = 15


class Stalling(http.server.BaseHTTPRequestHandler):
    """The first connection gets FRAMES JPEG frames, then the connection stays open and silent; every
    later one is refused (404), so the source sees exactly FRAMES frames, however slow its reader."""

    release = threading.Event()
    served = threading.Lock()

    def log_message(self, *args):
        pass

    def do_GET(self):
        if not Stalling.served.acquire(blocking=False):
            self.send_error(404)
            return
        self.send_response(200)
        self.send_header("Content-Type", "multipart/x-mixed-replace; boundary=frame")
        self.end_headers()
        for i in range(FRAMES):
            _, jpg = cv2.imencode(".jpg", np.full((48, 96, 3), 10 * i, np.uint8))
            self.wfile.write(b"--frame\r\nContent-Type: image/jpeg\r\nContent-Length: %d\r\n\r\n" % len(jpg)
                             + jpg.tobytes() + b"\r\n")
            self.wfile.flush()
        Stalling.release.wait(30)


def test_a_stalled_stream_is_seen_within_the_stall_time_then_given_up_when_it_refuses():
    srv = socketserver.ThreadingTCPServer(("127.0.0.1", 0), Stalling)
    srv.daemon_threads = True
    threading.Thread(target=srv.serve_forever, daemon=True).start()
    url = f"http://127.0.0.1:{srv.server_address[1]}/stream.mjpg"
    opened: list[float] = []

    def opener(target):
        opened.append(time.monotonic())
        return open_capture(target, 1.0)

    src = LiveSource(url, Reconnect(stall_s=1.0, first_s=0.1, max_s=0.2, give_up_s=20, max_tries=2), opener=opener)
    seen: list[float] = []
    try:
        for item in src:                        # ends when the reconnects fail
            seen.append(item.t)
    finally:
        Stalling.release.set()
        src.close()
        srv.shutdown()
        srv.server_close()
    # the newest frame wins: a slow reader may skip some, and frames replaced before the loop first
    # asked are counted apart from those dropped while it ran
    assert len(seen) + src.dropped + src.before_start == FRAMES and seen
    assert src.reconnects == 2 and len(opened) == 3
    # FFmpeg's own read timeout is 30 s: the stall is seen after --stall (1 s), then the back-off
    stalled_for = opened[1] - src.last_frame_at
    assert 0.9 < stalled_for < 1.0 + 2.0, f"the stall was seen after {stalled_for:.2f} s"
    assert src.failure and "reconnects failed" in src.failure


STALE = 250     # the grey of the frame a frozen camera returns late


class Freezing:
    """A camera whose ``freeze_at``-th read blocks ``freeze_s`` and then returns a frame anyway (a USB
    camera that hangs and recovers with a stale picture); every frame is painted with its read's index
    (mod 100), the late one ``STALE``."""

    def __init__(self, freeze_at: int | None, freeze_s: float) -> None:
        self.reads, self.freeze_at, self.freeze_s = 0, freeze_at, freeze_s

    def isOpened(self) -> bool:
        return True

    def read(self):
        k = self.reads
        self.reads += 1
        time.sleep(self.freeze_s if k == self.freeze_at else 0.01)
        return True, np.full((8, 8, 3), STALE if k == self.freeze_at else k % 100, np.uint8)

    def get(self, prop):
        return 0

    def release(self) -> None:
        pass


def test_a_camera_that_freezes_and_comes_back_late_is_counted_as_stalled_and_reopened():
    """The 4th read takes 0.6 s against a 0.25 s stall limit: the camera is taken as lost and reopened
    (one reconnect), and the frame it finally returned, stale by then, is never handed out."""
    opened: list[Freezing] = []

    def opener(target):
        opened.append(Freezing(3 if not opened else None, 0.6))
        return opened[-1]

    src = LiveSource(0, Reconnect(stall_s=0.25, first_s=0.05, max_s=0.1, give_up_s=10), opener=opener)
    seen = []
    deadline = time.monotonic() + 5
    try:
        for item in src:
            seen.append(int(item.frame[0, 0, 0]))
            if (len(opened) == 2 and opened[1].reads >= 5) or time.monotonic() > deadline:
                break
    finally:
        src.close()
    assert src.reconnects == 1 and len(opened) == 2
    assert STALE not in seen, "the frame returned after the stall is stale: it must not reach the model"


class Raising(Freezing):
    """A capture backend that raises on its 3rd read (a driver error) instead of returning nothing."""

    def read(self):
        if self.reads == 2 and self.freeze_at is not None:
            self.reads += 1
            raise RuntimeError("VIDIOC_DQBUF: No such device")
        return super().read()


def test_a_capture_that_raises_is_a_lost_camera_reopened_not_a_silent_end():
    opened: list[Raising] = []

    def opener(target):
        opened.append(Raising(-1 if not opened else None, 0.0))
        return opened[-1]

    src = LiveSource(0, Reconnect(stall_s=0.25, first_s=0.05, max_s=0.1, give_up_s=10), opener=opener)
    n = 0
    limit = threading.Timer(5.0, src.stop)       # a reader thread that died would leave the loop waiting
    limit.start()
    try:
        for _ in src:
            n += 1
            if len(opened) == 2 and opened[1].reads >= 5:
                break
    finally:
        limit.cancel()
        src.close()
    assert src.reconnects == 1 and len(opened) == 2 and n >= 5
