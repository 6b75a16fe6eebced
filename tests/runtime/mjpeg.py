"""A local MJPEG-over-HTTP stream for the network-video tests: 127.0.0.1, a port the OS picks.

:class:`MjpegServer` serves ``multipart/x-mixed-replace`` JPEG frames (``images`` in turn, or
numbered gradient images, the frame number in the top-left pixel block) at ``fps`` from a
daemon thread;
:meth:`MjpegServer.drop` closes every open stream and refuses new ones for a while (a camera
rebooting), :meth:`close` stops it. Each stream ends by itself after ``max_frames``.
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


class MjpegServer:
    def __init__(self, fps: float = 25.0, max_frames: int = 100_000, size: tuple[int, int] = (160, 120),
                 images: list[np.ndarray] | None = None):
        self.fps, self.max_frames, self.size = fps, max_frames, size
        self.images = images
        self.streams = 0
        self._down_until = 0.0
        self._epoch = 0
        self._lock = threading.Lock()
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
                try:
                    for n in range(server.max_frames):
                        if server._stop.is_set() or server._epoch != epoch:
                            return
                        img = server.images[n % len(server.images)] if server.images else frame_image(n, server.size)
                        ok, jpg = cv2.imencode(".jpg", cv2.cvtColor(img, cv2.COLOR_RGB2BGR))
                        self.wfile.write(f"--{BOUNDARY}\r\nContent-Type: image/jpeg\r\n"
                                         f"Content-Length: {len(jpg)}\r\n\r\n".encode() + jpg.tobytes() + b"\r\n")
                        time.sleep(1 / server.fps)
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
        return self

    def drop(self, seconds: float) -> None:
        """End every open stream now and answer 503 for ``seconds``."""
        with self._lock:
            self._epoch += 1
            self._down_until = time.monotonic() + seconds

    def close(self) -> None:
        self._stop.set()
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
