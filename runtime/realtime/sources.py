"""The capture thread that keeps only the latest frame, and the loop's synthetic and faulty sources.

Sources (:mod:`runtime.frames`: video files, image folders, camera devices, network streams; here: a
synthetic world, and a wrapper injecting faults) yield RGB uint8 frames; a :class:`Capture`
runs one in its own thread and keeps only the newest frame with its time stamp
(``time.monotonic()`` when it arrived: for a live source when its bytes were in, else when it
became available): the loop takes it when ready, frames it never took are counted as dropped,
frames older than ``max_age_s`` when taken are rejected as stale (not processed late). ``paced``
sources (video files, image folders and synthetic scenarios played "live") release frames at their
frame rate like a camera; unpaced ones hand over every frame (offline processing). A live source
(camera, network stream) is its own clock: it is never paced but drained, from the moment its
capture starts (before the background is learnt), so that no backlog builds up in the stream while
the loop starts; until the loop is ready (:meth:`Capture.begin`) only the newest frame is kept,
and what it replaced is counted as ``skipped_at_start``.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np

from runtime.frames import Source


@dataclass
class Frame:
    """A captured frame: its index in the source, the time it arrived, the image, and its stamp.

    ``t`` is ``time.monotonic()`` when the frame arrived (live sources: its bytes in, before decoding)
    or became available (files, folders, synthetic scenes): latency and frame age are measured from it;
    ``stamp`` is the frame's own time in seconds (the tracker's clock): ``index / fps``
    for files, folders and synthetic scenes, ``t`` for live sources. ``image`` is ``None``
    for a frame the source failed to deliver (a broken frame).
    """

    index: int
    t: float
    image: np.ndarray | None
    stamp: float = 0.0


class Capture:
    """Runs a source in a thread, keeping only the latest frame (see the module docstring).

    ``frames`` continues an iterator already started on ``source.stamped()`` (after the
    background was learnt from its first ``first_index`` frames); a live source's capture starts
    on the source itself, and the background is learnt from it (:meth:`images`)."""

    def __init__(self, source: Source, paced: bool = True, max_age_s: float | None = None,
                 frames: Iterator[tuple[np.ndarray | None, float]] | None = None, first_index: int = 0,
                 shape: tuple[int, ...] | None = None):
        self.source, self.paced, self.shape = source, paced, shape
        self._frames = source.stamped() if frames is None else frames
        self._first = first_index
        self._live = source.live
        period = 1.0 / source.fps if source.fps else 0.04
        self.max_age_s = max_age_s if max_age_s is not None else 2.5 * period
        self._period = period
        self._lock = threading.Condition()
        self._latest: Frame | None = None
        self._taken = True
        self._done = False
        self._begun = False
        self._stop = threading.Event()
        self.counts = {"captured": 0, "dropped": 0, "stale": 0, "broken": 0, "wrong_size": 0, "skipped_at_start": 0}
        self._thread = threading.Thread(target=self._run, name="capture", daemon=True)

    def start(self) -> Capture:
        """Start reading (once; a live source's capture is started before the background is learnt)."""
        if self._thread.ident is None:
            self._thread.start()
        return self

    def __enter__(self) -> Capture:
        return self.start()

    def __exit__(self, *exc) -> None:
        self.stop()

    def begin(self) -> None:
        """The loop is ready for frames: from now on ``paced`` rules, and a frame it had no time for is dropped
        (a live source's frames replaced while it started are ``skipped_at_start``)."""
        with self._lock:
            self._begun = True
            self.counts["skipped_at_start"], self.counts["dropped"] = self.counts["dropped"], 0
            self._lock.notify_all()

    def stop(self) -> None:
        self._stop.set()
        with self._lock:
            self._lock.notify_all()
        self._thread.join(timeout=5)
        self.source.close()

    @property
    def ended(self) -> bool:
        """The source has no more frames (and the last one was taken)."""
        with self._lock:
            return self._done and self._taken

    def _run(self) -> None:
        t_next = time.monotonic()
        try:
            for i, (img, t_arrived) in enumerate(self._frames, start=self._first):
                if self._stop.is_set():
                    break
                if self.paced and self.source.fps and not self._live:  # a live source is its own clock
                    t_next += self._period
                    delay = t_next - time.monotonic()
                    if delay > 0:
                        self._stop.wait(delay)
                with self._lock:
                    if not self.paced and (self._begun or not self._live):  # every frame: wait for it to be taken
                        while not self._taken and not self._stop.is_set():
                            self._lock.wait(0.1)
                    if not self._taken:
                        self.counts["dropped"] += 1
                    if img is None:
                        self.counts["broken"] += 1
                    elif self.shape is not None and img.shape != self.shape:
                        self.counts["wrong_size"] += 1
                    t = t_arrived if self._live else time.monotonic()
                    stamp = t if self._live or not self.source.fps else i / self.source.fps
                    self._latest = Frame(i, t, img, stamp)
                    self._taken = False
                    self.counts["captured"] += 1
                    self._lock.notify_all()
        finally:
            with self._lock:
                self._done = True
                self._lock.notify_all()

    def get(self, timeout: float = 1.0) -> Frame | None:
        """The newest untaken frame (waiting up to ``timeout`` s), or ``None`` (source ended or nothing new).

        Stale frames are counted and skipped; broken ones (``image is None``) are returned so
        that the loop can log them. Broken frames, and frames not of ``shape`` when given, are
        counted as they arrive (also those the loop never takes).
        """
        deadline = time.monotonic() + timeout
        with self._lock:
            while True:
                if not self._taken:
                    frame = self._latest
                    self._taken = True
                    self._lock.notify_all()
                    if frame.image is None:
                        return frame
                    if self.paced and time.monotonic() - frame.t > self.max_age_s:
                        self.counts["stale"] += 1
                        continue
                    return frame
                if self._done:
                    return None
                left = deadline - time.monotonic()
                if left <= 0:
                    return None
                self._lock.wait(left)

    def images(self) -> Iterator[np.ndarray | None]:
        """Each new frame's image as it is taken (``None``: a broken one), until the source ends: what the
        background is learnt from while a live source is drained."""
        while not self.ended:
            frame = self.get(timeout=0.5)
            if frame is not None:
                yield frame.image


class SyntheticSource(Source):
    """Frames of a synthetic world (:func:`omnijax.build_world`), rendered as they are read.

    The truth of each rendered frame is kept in :attr:`truth` (frame index -> numpy
    :class:`omnijax.Truth`) until the scorer takes it with :meth:`take_truth`.
    """

    def __init__(self, world, n_frames: int | None = None):
        self.world = world
        self.n_frames = world.n_frames if n_frames is None else min(n_frames, world.n_frames)
        self.fps = float(world.scenario.fps)
        self.name = f"synthetic scenario '{world.scenario.name}'"
        self.truth: dict[int, object] = {}
        self._lock = threading.Lock()

    def frames(self):
        import jax

        for t in range(self.n_frames):
            frame = jax.device_get(self.world.frame(t))
            with self._lock:
                self.truth[t] = frame.truth
            yield np.asarray(frame.image)

    def take_truth(self, index: int):
        """The truth of frame ``index``, forgetting it and every earlier frame's."""
        with self._lock:
            truth = self.truth.get(index)
            for k in [k for k in self.truth if k <= index]:
                del self.truth[k]
        return truth


class FaultySource(Source):
    """Wraps a source and injects the frame faults of a :class:`runtime.faults.FaultPlan`:
    broken frames (``None``), frames of the wrong size (half size), and an early end."""

    def __init__(self, source: Source, plan):
        self.source, self.plan = source, plan
        self.fps, self.name, self.live = source.fps, source.name, source.live

    def frames(self):
        for img, _ in self.stamped():
            yield img

    def stamped(self):
        for i, (img, t) in enumerate(self.source.stamped()):
            if self.plan.end is not None and i >= self.plan.end:
                return
            if i in self.plan.broken:
                yield None, t
            elif i in self.plan.wrong_size and img is not None:
                yield np.ascontiguousarray(img[::2, ::2]), t
            else:
                yield img, t

    def close(self):
        self.source.close()


class LatestImage:
    """A second video shown beside the loop, e.g. the PTZ camera's own stream (``run --ptz-video``): a
    :class:`Capture` runs it, and each call (the operator's view's ``foveal``, on the drawing thread)
    returns its newest image (the last one while nothing new came) and ``label``."""

    def __init__(self, source: Source, label: str = "PTZ camera"):
        self.capture = Capture(source, paced=True, max_age_s=float("inf"))
        self.label, self.image = label, None

    def __enter__(self) -> LatestImage:
        self.capture.__enter__()
        return self

    def __exit__(self, *exc) -> None:
        self.capture.stop()

    def __call__(self, frame=None, loop=None) -> tuple[np.ndarray | None, str]:
        got = self.capture.get(timeout=0.0)
        if got is not None and got.image is not None:
            self.image = got.image
        return self.image, self.label
