"""Reading frames from video files and image folders (OpenCV), as RGB uint8 arrays."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import cv2
import numpy as np

IMAGE_SUFFIXES = {".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff", ".ppm"}


class SourceError(ValueError):
    """A frame source that cannot be opened or read (one-line message)."""


def _image_files(folder: Path) -> list[Path]:
    files = sorted(p for p in folder.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES)
    if not files:
        raise SourceError(f"{folder}: no images ({', '.join(sorted(IMAGE_SUFFIXES))}) in this folder")
    return files


def read_frames(source: str | Path, limit: int | None = None) -> Iterator[np.ndarray]:
    """Yield RGB uint8 frames (H, W, 3) from a video file or a folder of images, in order.

    Raises :class:`SourceError` if the source is missing, unreadable, or changes
    frame size part-way (the first frame fixes the size).
    """
    source = Path(source)
    if not source.exists():
        raise SourceError(f"{source}: no such video file or image folder")
    shape = None
    n = 0

    def check(frame: np.ndarray, where: str) -> np.ndarray:
        nonlocal shape
        if frame.ndim == 2:
            frame = np.repeat(frame[..., None], 3, -1)
        if shape is None:
            shape = frame.shape
        elif frame.shape != shape:
            raise SourceError(f"{where}: frame size {frame.shape[1]}x{frame.shape[0]}, "
                              f"expected {shape[1]}x{shape[0]} like the first frame")
        return cv2.cvtColor(frame, cv2.COLOR_BGR2RGB)

    if source.is_dir():
        for path in _image_files(source):
            if limit is not None and n >= limit:
                return
            img = cv2.imread(str(path), cv2.IMREAD_COLOR)
            if img is None:
                raise SourceError(f"{path}: not a readable image")
            n += 1
            yield check(img, str(path))
        return
    cap = cv2.VideoCapture(str(source))
    if not cap.isOpened():
        raise SourceError(f"{source}: not a video OpenCV can open")
    try:
        while limit is None or n < limit:
            ok, img = cap.read()
            if not ok:
                if n == 0:
                    raise SourceError(f"{source}: no frames could be decoded")
                return
            n += 1
            yield check(img, f"{source} frame {n - 1}")
    finally:
        cap.release()
