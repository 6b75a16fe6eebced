"""The event log: a person appeared, left, or had their face captured, one JSON object a line.

:class:`EventLog` is a frame hook of the loop's drawing thread (never the control thread): it compares
the tracks confirmed at each frame with the ones before and writes an event when

- ``person_appeared``: a track is trusted as a person for the first time
  (:func:`runtime.realtime.targeting.is_trusted`: it walked in; blobs that never move make no events);
- ``face_captured``: a PTZ has dwelt on the person (the target selector, or with several PTZs the
  assignment, marks the face captured); that PTZ's image then (the demo's rendered view, or the
  camera's own stream) is saved as
  ``faces/track<ID>_frame<N>.jpg`` beside the log and named in the event (``face``);
- ``person_left``: an appeared person's track has not been confirmed for ``leave_s`` seconds of frames.

Every event has ``event``, ``track``, ``xy`` (floor, m), ``frame``, ``t`` (the frame's stamp, s) and
``time`` (UTC, ISO 8601). Each is also handed to ``sinks`` (the MQTT publisher, the console).
"""

from __future__ import annotations

import datetime
import json
from collections import deque
from collections.abc import Callable
from pathlib import Path

import cv2
import numpy as np

#: The events, in the order a person goes through them.
EVENTS: tuple[str, ...] = ("person_appeared", "face_captured", "person_left")
#: Seconds of frames a person's track may be missing before they have left.
LEAVE_S = 1.0
#: Faces the log keeps in memory for the console (the files stay).
RECENT_FACES = 8


class EventLog:
    """Writes ``events.jsonl`` (and ``faces/``) into ``folder``; see the module docstring.

    ``face_image(track) -> RGB array | None``: the current image of the PTZ that captured ``track``'s face;
    ``sinks``: callables taking each event.
    """

    def __init__(self, folder: Path, face_image: Callable[..., np.ndarray | None] | None = None,
                 sinks: tuple[Callable[[dict], None], ...] = (), leave_s: float = LEAVE_S):
        self.folder, self.face_image, self.sinks, self.leave_s = Path(folder), face_image, list(sinks), leave_s
        self.path = self.folder / "events.jsonl"
        self._file = self.path.open("w")
        self.present: dict[int, tuple[float, list[float]]] = {}  # appeared track -> (last seen, xy)
        self.captured: set[int] = set()
        self.counts = dict.fromkeys(EVENTS, 0)
        self.faces: deque[tuple[dict, bytes]] = deque(maxlen=RECENT_FACES)  # (event, JPEG)

    def __call__(self, record, frame, dets, z, tracks, commands, status) -> dict:
        t = float(frame.stamp)
        for tr in tracks:
            xy = [round(float(v), 3) for v in tr.position]
            if tr.id in self.present:
                self.present[tr.id] = (t, xy)
            elif tr.trusted:
                self.present[tr.id] = (t, xy)
                self._emit("person_appeared", tr.id, xy, frame)
            if tr.captured and tr.id not in self.captured:
                self.captured.add(tr.id)
                self._face(tr, xy, frame)
        for track, (seen, xy) in list(self.present.items()):
            if t - seen > self.leave_s:
                del self.present[track]
                self._emit("person_left", track, xy, frame)
        return {}

    def _face(self, tr, xy: list[float], frame) -> None:
        track = tr.id
        image = self.face_image(tr) if self.face_image is not None else None
        extra, jpeg = {"face": None}, None
        if image is not None:
            ok, buf = cv2.imencode(".jpg", cv2.cvtColor(np.asarray(image), cv2.COLOR_RGB2BGR),
                                   [cv2.IMWRITE_JPEG_QUALITY, 90])
            if ok:
                jpeg = buf.tobytes()
                name = f"faces/track{track}_frame{frame.index}.jpg"
                (self.folder / "faces").mkdir(exist_ok=True)
                (self.folder / name).write_bytes(jpeg)
                extra["face"] = name
        event = self._emit("face_captured", track, xy, frame, extra)
        if jpeg is not None:
            self.faces.append((event, jpeg))

    def _emit(self, kind: str, track: int, xy: list[float], frame, extra: dict | None = None) -> dict:
        event = {"event": kind, "track": int(track), "xy": xy, "frame": int(frame.index),
                 "t": round(float(frame.stamp), 4),
                 "time": datetime.datetime.now(datetime.UTC).isoformat(timespec="milliseconds"), **(extra or {})}
        self._file.write(json.dumps(event) + "\n")
        self._file.flush()
        self.counts[kind] += 1
        for sink in self.sinks:
            sink(event)
        return event

    def close(self) -> None:
        self._file.close()

    def summary(self) -> dict:
        return {"file": self.path.name, **self.counts}
