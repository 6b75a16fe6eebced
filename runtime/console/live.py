"""What the console shows, taken on the loop's drawing thread: :class:`LiveView` is a frame hook there
(after the operator's view is drawn) that keeps the latest snapshot, replaced whole, for the server's
thread to read. The console never reads the control thread's state.
"""

from __future__ import annotations

import math
import threading
import time
from collections import deque
from dataclasses import dataclass

import jax.numpy as jnp
import numpy as np

from runtime.realtime.overlay import floor_to_pixels

#: Tracks the console lists at most (their pixels are computed in one call of this size).
MAX_TRACKS = 32
#: Events the console keeps for the page.
RECENT_EVENTS = 50


@dataclass(frozen=True)
class Snapshot:
    """One processed frame as the console shows it: the ``status`` JSON object, the annotated omni image
    and each PTZ's image (RGB; ``None`` before the first or without a PTZ view) with its label, in the
    rig's order (``views``); ``ptz``, ``ptz_label``: the first PTZ's."""

    status: dict
    omni: np.ndarray | None
    views: tuple[tuple[np.ndarray | None, str], ...]
    index: int

    @property
    def ptz(self) -> np.ndarray | None:
        return self.views[0][0]

    @property
    def ptz_label(self) -> str:
        return self.views[0][1]


def _deg(v: float | None, nd: int = 3) -> float | None:
    return None if v is None else round(math.degrees(v), nd)


class LiveView:
    """The drawing thread's hook keeping :attr:`snapshot` (see the module docstring).

    ``annotator`` is the session's :class:`~runtime.realtime.session.Annotator` (its images of this
    frame), ``loop`` the :class:`~runtime.realtime.loop.RealTimeLoop` (its configuration and latency
    samples, as the annotator reads them).
    """

    def __init__(self, rig, annotator=None, loop=None):
        self.rig, self.annotator, self.loop = rig, annotator, loop
        self.snapshot: Snapshot | None = None
        self.events: deque[dict] = deque(maxlen=RECENT_EVENTS)
        self._lock = threading.Lock()
        self.started = time.monotonic()

    def event(self, event: dict) -> None:
        """A sink of the event log: the page lists the latest events."""
        with self._lock:
            self.events.append(event)

    def recent_events(self) -> list[dict]:
        with self._lock:
            return list(self.events)

    def _pixels(self, tracks) -> np.ndarray:
        xy = np.zeros((MAX_TRACKS, 2))
        for k, tr in enumerate(tracks[:MAX_TRACKS]):
            xy[k] = tr.position
        return np.asarray(floor_to_pixels(self.rig, jnp.asarray(xy), jnp.zeros(MAX_TRACKS)))

    def __call__(self, record, frame, dets, z, tracks, commands, status) -> dict:
        loop, annot = self.loop, self.annotator
        px = self._pixels(tracks)
        framable = set(status.get("framable") or ())
        n, elapsed = status["frames"], max(status["elapsed"], 1e-9)
        lat = loop.timings.latency.recent(100) if len(loop.timings.latency) else loop.timings.compute.recent(100)
        lat = lat[np.isfinite(lat)]
        op = status.get("operator")
        now = time.monotonic()
        views = ((None, "PTZ"),) * len(commands) if annot is None else tuple(annot.insets)
        cameras = [{"id": k, "target": None if command is None else command.track,
                    "manual": command is not None and command.track is None, "held": camera["held"],
                    "view": views[k][1], **self._ptz(camera, command)}
                   for k, (command, camera) in enumerate(zip(commands, status["cameras"]))]
        command = commands[0]
        counts = status["counts"]
        out = {
            "frames": n, "frame": int(frame.index), "t": round(float(frame.stamp), 3),
            "fps": round(n / elapsed, 2),
            "latency_ms": {"p50": round(float(np.median(lat)), 2) if lat.size else None,
                           "p99": round(float(np.percentile(lat, 99)), 2) if lat.size else None},
            "tracks": [{"id": tr.id, "xy": [round(float(v), 3) for v in tr.position],
                        "px": [round(float(v), 1) for v in px[k]], "trusted": bool(tr.trusted),
                        "captured": bool(tr.captured), "framable": tr.id in framable}
                       for k, tr in enumerate(tracks[:MAX_TRACKS])],
            "target": None if command is None else command.track,
            "manual": command is not None and command.track is None,
            "held": status.get("held"),
            "ptz": self._ptz(status["cameras"][0], command),
            "cameras": cameras,
            "operator": None if op is None else {
                "target": op.target, "paused": op.paused,
                "point": None if op.pointing(now) is None else {
                    "pan_deg": _deg(op.point[0]), "tilt_deg": _deg(op.point[1]), "zoom": round(op.point[2], 3),
                    "remaining_s": round(op.point_until - now, 1), "camera": op.point_camera}},
            "faces_captured": status["captures"],
            "faults": {"broken": counts["broken"], "wrong_size": counts["wrong_size"],
                       "stale": status["capture"]["stale"], "dropped": status["capture"]["dropped"],
                       "ptz_offline": any(c["driver"] is not None and not c["driver"]["connected"]
                                          for c in status["cameras"])},
            "zones_version": status.get("zones_version", 0),
        }
        omni = None if annot is None else annot.omni_view
        self.snapshot = Snapshot(status=out, omni=omni, views=views, index=int(frame.index))
        return {}

    def _ptz(self, camera: dict, command) -> dict:
        """A PTZ's part of the status: where it was sent last, its link, and this frame's command's sigmas,
        zooms and predicted containment."""
        sent, rule = camera["sent"], self.loop.cfg.zoom_rule
        ptz = {"pan_deg": _deg(sent[0]) if sent else None, "tilt_deg": _deg(sent[1]) if sent else None,
               "zoom": round(sent[2], 3) if sent else None, "zoom_rule": rule,
               "p_contain": float(self.rig.p_contain), "link": camera["driver"]}
        if command is not None:
            ptz.update({"sd_pan_deg": _deg(command.sd_pan, 4), "sd_tilt_deg": _deg(command.sd_tilt, 4),
                        "zooms": {k: round(v, 3) for k, v in command.zooms.items()},
                        "probability": (None if command.aimed is None else
                                        round(float(command.aimed.zooms[rule].probability), 4))})
        return ptz
