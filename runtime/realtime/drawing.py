"""Everything off the control path, on its own thread: the frame hooks (the annotated view with the
foveal inset and its video encoding, the demo's scoring, recording), and the log.

The control thread hands each processed frame (and each fault record) to :class:`OffPath` through
a bounded queue and never waits for it (except with ``--pace all``, where no frame is late and
every one is drawn): when the queue is full the item is skipped and counted,
and the summary lists which frames the video and the log lack (``off_path`` in ``summary.json``,
docs/runtime.md). The log is line-buffered: every line is in the file as soon as it is written (the
staging folder keeps it whatever happens to the process). Told to hurry (a second Ctrl-C while the
outputs are written), it writes the log lines of what is still queued without drawing them
(``undrawn``). What the hooks see is a snapshot taken on the control thread (the tracks
confirmed at that frame, the counters then), so that drawing never reads state the control
thread is changing.
"""

from __future__ import annotations

import json
import queue
import threading
import time
from collections.abc import Callable
from pathlib import Path

#: Frames (and fault records) waiting for the drawing thread at most: 2 s at 25 fps.
QUEUE_SIZE = 50
#: Skipped frames listed by index in the summary at most (all are counted).
LISTED = 1000


class OffPath:
    """The drawing and logging thread (see the module docstring).

    ``hooks(record, frame, dets, z, tracks, commands, status)`` returns extra log fields;
    ``describe(item) -> dict`` the log fields of a processed frame; ``timings`` gets the ``draw``
    and ``log`` stage times (ms).
    """

    def __init__(self, log_path: Path, hooks: Callable | None, describe: Callable, record_time: Callable,
                 size: int = QUEUE_SIZE, block: bool = False, hurry: threading.Event | None = None):
        self.hooks, self.describe, self.record_time, self.block = hooks, describe, record_time, block
        self.hurry = hurry
        self.queue: queue.Queue = queue.Queue(maxsize=size)
        self.size = size
        self.done = self.skipped = self.max_waiting = self.undrawn = 0
        self.skipped_frames: list[int] = []
        self.error: BaseException | None = None
        self._log = log_path.open("w", buffering=1)  # line-buffered: every line is in the file as it is written
        self._thread = threading.Thread(target=self._run, name="omnijax-off-path", daemon=True)
        self._thread.start()

    def submit(self, item: dict) -> bool:
        """Queue ``item`` (``record``, and for a processed frame ``frame``, ``dets``, ``z``, ``tracks``,
        ``commands``, ``status``) without waiting; ``False`` (and counted) when the queue is full.
        With ``block`` (frames not paced: ``--pace all``, nothing is late) it waits for room instead."""
        try:
            if self.block:
                while self.error is None:
                    try:
                        self.queue.put(item, timeout=0.5)
                        break
                    except queue.Full:
                        continue
            else:
                self.queue.put_nowait(item)
        except queue.Full:
            self.skipped += 1
            if len(self.skipped_frames) < LISTED:
                self.skipped_frames.append(item["record"]["frame"])
            return False
        self.max_waiting = max(self.max_waiting, self.queue.qsize())
        return True

    def close(self, timeout: float = 30.0) -> None:
        """Let the thread finish what is queued (at most ``timeout`` s), then close the log."""
        self.queue.put(None, timeout=timeout)
        self._thread.join(timeout)
        self._log.close()
        if self.error is not None:
            raise RuntimeError(f"the drawing thread failed: {self.error!r}") from self.error

    def summary(self) -> dict:
        return {"queue_size": self.size, "done": self.done, "skipped": self.skipped,
                "skipped_frames": self.skipped_frames, "max_waiting": self.max_waiting, "undrawn": self.undrawn}

    def _run(self) -> None:
        while True:
            item = self.queue.get()
            if item is None:
                return
            if self.error is not None:  # after a failure: drain, so that the control thread is never held up
                continue
            try:
                self._handle(item)
            except BaseException as exc:  # reported by close(); the control loop keeps running meanwhile
                self.error = exc

    def _handle(self, item: dict) -> None:
        record = item["record"]
        if "frame" in item:
            t = time.monotonic()
            if self.hurry is not None and self.hurry.is_set():  # told to finish quickly: the log line only
                self.undrawn += 1
            elif self.hooks is not None:
                record.update(self.hooks(record, item["frame"], item["dets"], item["z"], item["tracks"],
                                         item["commands"], item["status"]) or {})
            t = self.record_time("draw", t)
            record.update(self.describe(item))
            self._log.write(json.dumps(record) + "\n")
            self.record_time("log", t)
        else:
            self._log.write(json.dumps(record) + "\n")
        self.done += 1
