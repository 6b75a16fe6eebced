"""Reading frames (OpenCV) as RGB uint8 arrays: video files, image folders, cameras, network streams.

:class:`VideoSource`, :class:`FolderSource`, :class:`DeviceSource` and :class:`NetworkSource`
(``rtsp://``, ``http://`` MJPEG, through OpenCV's FFmpeg, reconnecting when the stream drops)
are the readers; :meth:`Source.stamped` gives each frame with the time it arrived at the process
(live sources: when its bytes were in, before decoding; OpenCV hands over no stream time stamp
usable as a clock, RTP/RTCP or MJPEG part headers, so arrival is the origin of a frame's age);
the real-time loop runs them as they are, a broken frame yielded as ``None`` and
reading going on (:func:`open_source`). :func:`read_frames` is the strict use of the
same readers for offline commands: an unreadable image or a change of frame size is
an error, and a video ends at its first undecodable frame.
"""

from __future__ import annotations

import abc
import itertools
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import cv2
import numpy as np

IMAGE_SUFFIXES = {".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff", ".ppm"}


class SourceError(ValueError):
    """A frame source that cannot be opened or read (one-line message)."""


class Source(abc.ABC):
    """A stream of frames. ``fps`` is the nominal rate (``None``: as fast as read)."""

    fps: float | None = None
    name: str = "source"
    #: Live sources (cameras) stamp frames with the capture clock, others with index / fps.
    live: bool = False

    @abc.abstractmethod
    def frames(self) -> Iterator[np.ndarray | None]:
        """RGB uint8 frames in order; ``None`` for a frame that could not be read."""

    def stamped(self) -> Iterator[tuple[np.ndarray | None, float]]:
        """:meth:`frames` with the ``time.monotonic()`` each arrived at the process (here: when it was read;
        live sources stamp it before decoding)."""
        for img in self.frames():
            yield img, time.monotonic()

    def describe(self, index: int) -> str:
        """Where frame ``index`` comes from, for messages."""
        return f"{self.name} frame {index}"

    def close(self) -> None:
        """Release the device or file (nothing to release unless a source says otherwise)."""
        return None


class VideoSource(Source):
    """A video file; an undecodable frame is yielded as ``None`` and reading goes on, at most
    ``max_broken`` in a row (0: the video ends at its first undecodable frame)."""

    def __init__(self, path: str | Path, max_broken: int = 25):
        self.path = Path(path)
        if not self.path.is_file():
            raise SourceError(f"{self.path}: no such video file")
        self._cap = cv2.VideoCapture(str(self.path))
        if not self._cap.isOpened():
            raise SourceError(f"{self.path}: not a video OpenCV can open")
        fps = self._cap.get(cv2.CAP_PROP_FPS)
        self.fps = fps if fps and np.isfinite(fps) and fps > 0 else None
        self.name = str(self.path)
        self.max_broken = max_broken

    def frames(self):
        broken = 0
        total = int(self._cap.get(cv2.CAP_PROP_FRAME_COUNT) or 0)
        n = 0
        while True:
            ok, img = self._cap.read()
            n += 1
            if ok and img is not None:
                broken = 0
                yield cv2.cvtColor(img, cv2.COLOR_BGR2RGB)
                continue
            if total and n < total and broken < self.max_broken:
                broken += 1
                yield None
                continue
            return

    def close(self):
        self._cap.release()


class FolderSource(Source):
    """A folder of images, in name order; an unreadable image is yielded as ``None``."""

    def __init__(self, path: str | Path, fps: float | None = None):
        self.path = Path(path)
        self.files = sorted(p for p in self.path.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES)
        if not self.files:
            raise SourceError(f"{self.path}: no images ({', '.join(sorted(IMAGE_SUFFIXES))}) in this folder")
        self.fps, self.name = fps, str(self.path)

    def frames(self):
        for p in self.files:
            img = cv2.imread(str(p), cv2.IMREAD_COLOR)
            yield None if img is None else cv2.cvtColor(img, cv2.COLOR_BGR2RGB)

    def describe(self, index: int) -> str:
        return str(self.files[index])


class _Outages:
    """A live source's ``counters``: ``drops`` (failed reads), ``outage_s`` (time without frames: from the last
    frame before a failure to the first after it), and the ``reconnects`` and ``failed_opens`` a source that
    reopens itself counts."""

    def __init__(self) -> None:
        self.counters = {"reconnects": 0, "drops": 0, "failed_opens": 0, "outage_s": 0.0}
        self._last: float | None = None
        self._down: float | None = None

    def frame(self, t: float) -> None:
        """A frame arrived at ``t``: an outage under way ends."""
        if self._down is not None:
            self.counters["outage_s"] += t - self._down
            self._down = None
        self._last = t

    def failed(self, t: float) -> None:
        """A read failed at ``t``: an outage begins at the last frame (unless one is under way)."""
        self.counters["drops"] += 1
        if self._down is None:
            self._down = t if self._last is None else self._last

    def ended(self, t: float) -> None:
        """The source ends at ``t`` (given up, or closed) during an outage: it lasted until then."""
        if self._down is not None:
            self.frame(t)


class DeviceSource(Source):
    """A camera device by index (OpenCV); a failed grab is yielded as ``None``, counted in ``counters``
    (``drops``, ``outage_s``) as a network stream's are."""

    def __init__(self, index: int, max_broken: int = 50):
        self._cap = cv2.VideoCapture(index)
        if not self._cap.isOpened():
            raise SourceError(f"camera {index}: cannot open the device")
        fps = self._cap.get(cv2.CAP_PROP_FPS)
        self.fps = fps if fps and fps > 0 else None
        self.name, self.max_broken = f"camera {index}", max_broken
        self.live = True
        self._outages = _Outages()
        self.counters = self._outages.counters

    def frames(self):
        for img, _ in self.stamped():
            yield img

    def stamped(self):
        broken = 0
        while broken < self.max_broken:
            ok = self._cap.grab()
            t = time.monotonic()  # the frame is in: its arrival, before it is decoded
            ok, img = self._cap.retrieve() if ok else (False, None)
            if ok and img is not None:
                broken = 0
                self._outages.frame(t)
                yield cv2.cvtColor(img, cv2.COLOR_BGR2RGB), t
            else:
                broken += 1
                self._outages.failed(t)
                yield None, t
        self._outages.ended(time.monotonic())

    def close(self):
        self._cap.release()


#: URL schemes read as network streams (OpenCV's FFmpeg back-end).
NETWORK_SCHEMES = ("rtsp", "rtsps", "http", "https", "rtmp", "udp", "tcp")


class NetworkSource(Source):
    """A network stream (``rtsp://``, ``http://`` MJPEG, ...) read through OpenCV's FFmpeg back-end.

    When the stream drops (a read fails or times out), the source yields ``None`` (one broken
    frame), then reopens it with exponential back-off (``backoff_s``: first and longest delay)
    and goes on, counting ``reconnects`` and the ``outage_s`` without frames (from the last frame
    before the drop to the first after it); the stream ends only after ``give_up_s`` without a
    frame, or on :meth:`close`. Frames are stamped with their arrival (``live``). The first open
    failing is a :class:`SourceError`.
    """

    def __init__(self, url: str, open_timeout_s: float = 5.0, read_timeout_s: float = 2.0,
                 backoff_s: tuple[float, float] = (0.1, 1.0), give_up_s: float = 60.0):
        self.url, self.name, self.live = url, url, True
        self.open_timeout_s, self.read_timeout_s = open_timeout_s, read_timeout_s
        self.backoff_s, self.give_up_s = backoff_s, give_up_s
        self._outages = _Outages()
        self.counters = self._outages.counters
        self._closed = threading.Event()
        self._reading = False
        self._cap = self._open()
        if self._cap is None:
            raise SourceError(f"{_redact(url)}: cannot open the stream (no answer, or not a video OpenCV can "
                              f"read, within {open_timeout_s:g} s)")
        fps = self._cap.get(cv2.CAP_PROP_FPS)
        self.fps = fps if fps and np.isfinite(fps) and 0 < fps <= 1000 else None

    def _open(self):
        cap = cv2.VideoCapture(self.url, cv2.CAP_FFMPEG,
                               [cv2.CAP_PROP_OPEN_TIMEOUT_MSEC, int(1e3 * self.open_timeout_s),
                                cv2.CAP_PROP_READ_TIMEOUT_MSEC, int(1e3 * self.read_timeout_s)])
        if cap.isOpened():
            return cap
        cap.release()
        return None

    def frames(self):
        for img, _ in self.stamped():
            yield img

    def stamped(self):
        self._reading = True
        try:
            while not self._closed.is_set():
                ok = self._cap.grab() if self._cap is not None else False
                t = time.monotonic()  # the frame's bytes are in: its arrival, before it is decoded
                ok, img = self._cap.retrieve() if ok else (False, None)
                if ok and img is not None:
                    self._outages.frame(t)
                    yield cv2.cvtColor(img, cv2.COLOR_BGR2RGB), t
                    continue
                if self._closed.is_set():
                    return
                self._outages.failed(t)
                yield None, t
                if not self._reconnect():
                    self._outages.ended(time.monotonic())
                    return
        finally:
            self._reading = False
            if self._cap is not None:
                self._cap.release()
                self._cap = None

    def _reconnect(self) -> bool:
        """Reopen the stream with back-off; ``False`` after ``give_up_s`` or on :meth:`close`."""
        if self._cap is not None:
            self._cap.release()
            self._cap = None
        t0 = time.monotonic()
        delay = self.backoff_s[0]
        while not self._closed.wait(delay):
            self._cap = self._open()
            if self._cap is not None:
                self.counters["reconnects"] += 1
                return True
            self.counters["failed_opens"] += 1
            if time.monotonic() - t0 > self.give_up_s:
                return False
            delay = min(2 * delay, self.backoff_s[1])
        return False

    def close(self):
        """Stop reading; the capture is released here, or by the reading thread when it notices."""
        self._closed.set()
        if not self._reading and self._cap is not None:
            self._cap.release()
            self._cap = None


def _redact(url: str) -> str:
    """``url`` without a password (``rtsp://user:secret@host`` -> ``rtsp://user:***@host``)."""
    from urllib.parse import urlsplit, urlunsplit

    parts = urlsplit(url)
    if parts.password is None:
        return url
    netloc = parts.netloc.replace(f":{parts.password}@", ":***@", 1)
    return urlunsplit(parts._replace(netloc=netloc))


def open_source(spec: str, fps: float | None = None) -> Source:
    """A source from a command-line spec: a video file, an image folder, a camera index, or a network
    stream URL (``rtsp://``, ``http://``, ...)."""
    if spec.split("://", 1)[0].lower() in NETWORK_SCHEMES and "://" in spec:
        return NetworkSource(spec)
    if spec.isdigit():
        return DeviceSource(int(spec))
    path = Path(spec)
    if path.is_dir():
        return FolderSource(path, fps)
    if path.exists():
        return VideoSource(path)
    raise SourceError(f"{spec}: no such video file, image folder, camera index or stream URL "
                      f"({', '.join(s + '://' for s in NETWORK_SCHEMES)})")


def frames_fps(source: str | Path) -> float | None:
    """The frame rate a video file declares (``None`` for a folder of images, or a video that does not say)."""
    path = Path(source)
    if not path.is_file():
        return None
    reader = VideoSource(path, max_broken=0)
    try:
        return reader.fps
    finally:
        reader.close()


def read_frames(source: str | Path, limit: int | None = None) -> Iterator[np.ndarray]:
    """Yield RGB uint8 frames (H, W, 3) from a video file or a folder of images, in order, at most ``limit``.

    Raises :class:`SourceError` if the source is missing, unreadable, yields no frame,
    or changes frame size part-way (the first frame fixes the size).
    """
    path = Path(source)
    if not path.exists():
        raise SourceError(f"{path}: no such video file or image folder")
    reader = FolderSource(path) if path.is_dir() else VideoSource(path, max_broken=0)
    shape = None
    try:
        for n, img in enumerate(itertools.islice(reader.frames(), limit)):
            if img is None:
                raise SourceError(f"{reader.describe(n)}: not a readable image")
            if shape is None:
                shape = img.shape
            elif img.shape != shape:
                raise SourceError(f"{reader.describe(n)}: frame size {img.shape[1]}x{img.shape[0]}, "
                                  f"expected {shape[1]}x{shape[0]} like the first frame")
            yield img
        if shape is None and limit != 0:
            raise SourceError(f"{path}: no frames could be decoded")
    finally:
        reader.close()
