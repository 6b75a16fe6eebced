"""A local MJPEG-over-HTTP stream for the network-video tests: 127.0.0.1, a port the OS picks.

:class:`MjpegServer` serves ``multipart/x-mixed-replace`` JPEG frames (``images`` in turn, or
numbered gradient images, the frame number in the top-left pixel block) at ``fps`` from a
daemon thread, each part on a fixed schedule (part ``n`` of a stream ``n / fps`` after it began);
:meth:`MjpegServer.drop` closes every open stream and refuses new ones for a while (a camera
rebooting), :meth:`close` stops it. Each stream ends by itself after ``max_frames``, the server
after ``lifetime_s``.

It stamps its parts: every part sent gets the next number of the server (across streams and
reconnections), ``sent[k]`` is the ``time.monotonic()`` at which part ``k`` was sent (the clock of
``log.jsonl``, on the same machine), each part carries it in an ``X-Timestamp`` header, and with
``stamp=True`` the number is drawn into the image itself (:func:`stamp_image`, read back by
:func:`read_stamp`), so that a recorded frame says which part it was.
"""

from __future__ import annotations

import socket
import threading
import time
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer

import cv2
import numpy as np

BOUNDARY = "omnijaxframe"


def frame_image(n: int, size: tuple[int, int] = (160, 120)) -> np.ndarray:
    """Frame ``n``: a gradient with ``n % 256`` in the top-left 16x16 block (RGB uint8)."""
    w, h = size
    img = np.zeros((h, w, 3), np.uint8)
    img[..., 0] = np.linspace(0, 255, w, dtype=np.uint8)[None, :]
    img[..., 1] = np.linspace(0, 255, h, dtype=np.uint8)[:, None]
    img[:16, :16] = n % 256
    return img


#: Bits of the part number drawn by :func:`stamp_image`: one 16x16 block each along the top row.
STAMP_BITS = 20


def stamp_image(img: np.ndarray, k: int) -> np.ndarray:
    """A copy of ``img`` with ``k`` drawn in its top row, bit i a 16x16 block at x = 16 i (white: 1)."""
    out = img.copy()
    for i in range(STAMP_BITS):
        out[:16, 16 * i:16 * (i + 1)] = 255 if k >> i & 1 else 0
    return out


def read_stamp(img: np.ndarray) -> int:
    """The number :func:`stamp_image` drew (exact through JPEG: each block is flat)."""
    return sum(1 << i for i in range(STAMP_BITS) if img[4:12, 16 * i + 4:16 * i + 12].mean() > 127)


class MjpegServer:
    def __init__(self, fps: float = 25.0, max_frames: int = 100_000, size: tuple[int, int] = (160, 120),
                 images: list[np.ndarray] | None = None, stamp: bool = False, lifetime_s: float = 600.0):
        self.fps, self.max_frames, self.size = fps, max_frames, size
        self.images, self.stamp = images, stamp
        self.streams = 0
        #: ``time.monotonic()`` when each part was sent, by the server's part number
        self.sent: list[float] = []
        self._down_until = 0.0
        self._epoch = 0
        self._lock = threading.Lock()
        self._lifetime_s = lifetime_s
        server = self

        class Handler(BaseHTTPRequestHandler):
            def log_message(self, *args):
                return None

            def do_GET(self):
                with server._lock:
                    down = time.monotonic() < server._down_until
                    epoch = server._epoch
                    server.streams += 0 if down else 1
                if down:
                    self.send_error(503)
                    return
                self.send_response(200)
                self.send_header("Content-Type", f"multipart/x-mixed-replace; boundary={BOUNDARY}")
                self.end_headers()
                start = time.monotonic()
                try:
                    for n in range(server.max_frames):
                        if server._stop.is_set() or server._epoch != epoch:
                            return
                        img = server.images[n % len(server.images)] if server.images else frame_image(n, server.size)
                        with server._lock:
                            k = len(server.sent)
                            server.sent.append(time.monotonic())
                        if server.stamp:
                            img = stamp_image(img, k)
                        ok, jpg = cv2.imencode(".jpg", cv2.cvtColor(img, cv2.COLOR_RGB2BGR))
                        self.wfile.write(f"--{BOUNDARY}\r\nContent-Type: image/jpeg\r\n"
                                         f"X-Timestamp: {server.sent[k]:.6f}\r\n"
                                         f"Content-Length: {len(jpg)}\r\n\r\n".encode() + jpg.tobytes() + b"\r\n")
                        server._stop.wait(max(0.0, start + (n + 1) / server.fps - time.monotonic()))
                except (BrokenPipeError, ConnectionResetError):
                    return

        self._stop = threading.Event()
        self.httpd = ThreadingHTTPServer(("127.0.0.1", 0), Handler)
        self.httpd.daemon_threads = True
        self.port = self.httpd.server_address[1]
        self.url = f"http://127.0.0.1:{self.port}/stream.mjpg"
        self._thread = threading.Thread(target=self.httpd.serve_forever, kwargs={"poll_interval": 0.05}, daemon=True)

    def start(self) -> MjpegServer:
        self._thread.start()
        self._timer = threading.Timer(self._lifetime_s, self.close)  # stops by itself
        self._timer.daemon = True
        self._timer.start()
        return self

    def drop(self, seconds: float) -> None:
        """End every open stream now and answer 503 for ``seconds``."""
        with self._lock:
            self._epoch += 1
            self._down_until = time.monotonic() + seconds

    def close(self) -> None:
        if self._stop.is_set():
            return
        self._stop.set()
        self._timer.cancel()
        self.httpd.shutdown()
        self.httpd.server_close()

    def __enter__(self) -> MjpegServer:
        return self.start()

    def __exit__(self, *exc) -> None:
        self.close()


def free_port() -> int:
    """A port nothing listens on (bound and released)."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]
