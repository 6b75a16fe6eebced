"""Reading frames (OpenCV) as RGB uint8 arrays: one reader of video files, one of image folders, one of cameras.

:class:`VideoSource`, :class:`FolderSource` and :class:`DeviceSource` are the readers;
the real-time loop runs them as they are, a broken frame yielded as ``None`` and
reading going on (:func:`open_source`). :func:`read_frames` is the strict use of the
same readers for offline commands: an unreadable image or a change of frame size is
an error, and a video ends at its first undecodable frame.
"""

from __future__ import annotations

import abc
import itertools
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


class DeviceSource(Source):
    """A camera device by index (OpenCV); a failed grab is yielded as ``None``."""

    def __init__(self, index: int, max_broken: int = 50):
        self._cap = cv2.VideoCapture(index)
        if not self._cap.isOpened():
            raise SourceError(f"camera {index}: cannot open the device")
        fps = self._cap.get(cv2.CAP_PROP_FPS)
        self.fps = fps if fps and fps > 0 else None
        self.name, self.max_broken = f"camera {index}", max_broken
        self.live = True

    def frames(self):
        broken = 0
        while broken < self.max_broken:
            ok, img = self._cap.read()
            if ok and img is not None:
                broken = 0
                yield cv2.cvtColor(img, cv2.COLOR_BGR2RGB)
            else:
                broken += 1
                yield None

    def close(self):
        self._cap.release()


def open_source(spec: str, fps: float | None = None) -> Source:
    """A source from a command-line spec: a video file, an image folder, or a camera index."""
    if spec.isdigit():
        return DeviceSource(int(spec))
    path = Path(spec)
    if path.is_dir():
        return FolderSource(path, fps)
    if path.exists():
        return VideoSource(path)
    raise SourceError(f"{spec}: no such video file, image folder or camera index")


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
