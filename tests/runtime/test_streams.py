"""A network stream that stalls, then refuses: the stall is seen within --stall seconds (not FFmpeg's
default 30), reconnects are counted, and the source fails with a reason once nothing comes back.
Against a local HTTP server (MJPEG over HTTP, as IP cameras serve it)."""

import http.server
import socketserver
import threading
import time

import cv2
import numpy as np

from bsn_edge.runtime.sources import LiveSource, Reconnect

FRAMES = 15


class Stalling(http.server.BaseHTTPRequestHandler):
    """Serves FRAMES JPEG frames, then keeps the connection open and sends nothing."""

    release = threading.Event()

    def log_message(self, *args):
        pass

    def do_GET(self):
        self.send_response(200)
        self.send_header("Content-Type", "multipart/x-mixed-replace; boundary=frame")
        self.end_headers()
        for i in range(FRAMES):
            _, jpg = cv2.imencode(".jpg", np.full((48, 96, 3), 10 * i, np.uint8))
            self.wfile.write(b"--frame\r\nContent-Type: image/jpeg\r\nContent-Length: %d\r\n\r\n" % len(jpg)
                             + jpg.tobytes() + b"\r\n")
            self.wfile.flush()
            time.sleep(0.02)
        Stalling.release.wait(30)


def test_a_stalled_stream_is_seen_within_the_stall_time_then_given_up_when_it_refuses():
    srv = socketserver.ThreadingTCPServer(("127.0.0.1", 0), Stalling)
    srv.daemon_threads = True
    threading.Thread(target=srv.serve_forever, daemon=True).start()
    url = f"http://127.0.0.1:{srv.server_address[1]}/stream.mjpg"
    src = LiveSource(url, Reconnect(stall_s=1.0, first_s=0.1, max_s=0.2, give_up_s=20, max_tries=2))
    try:
        got, last_frame, first_reconnect = 0, None, None
        deadline = time.monotonic() + 25
        for _ in src:
            got += 1
            last_frame = time.monotonic()
            if got + src.dropped == FRAMES:          # the newest frame wins: a slow reader may skip some
                srv.shutdown()                  # from now on the server refuses new connections
                srv.server_close()
                break
        while time.monotonic() < deadline and src.reconnects == 0:
            time.sleep(0.01)
        first_reconnect = time.monotonic()
        for _ in src:                           # ends when the reconnects fail
            pass
    finally:
        Stalling.release.set()
        src.close()
    assert got + src.dropped == FRAMES and got > 0
    assert src.reconnects >= 1 and first_reconnect - last_frame < 1.0 + 2.0, "the stall is seen within about 1 s"
    assert src.failure and "reconnects failed" in src.failure
