"""What the operator asks of the loop (the console's controls), as state the control thread reads once a frame.

:class:`Operator` is written by other threads (the console's server) and read by the control thread
with one attribute read (:attr:`Operator.state`, an immutable :class:`OperatorState` replaced whole
under a lock), so that the control thread never waits for anyone:

- ``target``: the track the operator chose; the selector keeps it while it is there and can be framed,
  then goes back to its own choice (:class:`~runtime.realtime.targeting.TargetSelector`, ``manual``;
  with several PTZs the assignment keeps it on the PTZ best placed for it);
- ``paused``: automatic targeting paused: no target, no command (the PTZs stay where they are);
- ``point``: a manual pan, tilt (rad) and zoom for PTZ ``point_camera`` (the rig's order; 0 with one
  PTZ), sent instead of any target's until ``point_until`` (``time.monotonic()``) or until released: a
  click on the floor, the home button, the calibration assistant's keys. The other PTZs go on.

Zones are swapped in the same way (:meth:`Operator.offer_zones`: a detector rebuilt off the control
thread and the priority test, taken by the control thread at the start of its next frame).
"""

from __future__ import annotations

import dataclasses
import math
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass

#: How long a manual pointing lasts unless released or given another length (s).
POINT_S = 30.0


@dataclass(frozen=True)
class OperatorState:
    """One consistent view of the operator's requests (see the module docstring); ``version`` counts changes."""

    target: int | None = None
    paused: bool = False
    point: tuple[float, float, float] | None = None
    point_until: float = 0.0
    point_camera: int = 0
    version: int = 0

    def pointing(self, now: float) -> tuple[float, float, float] | None:
        """The manual pan, tilt, zoom in force at ``now`` (``time.monotonic()``), if any."""
        return self.point if self.point is not None and now < self.point_until else None


@dataclass(frozen=True)
class ZoneSwap:
    """Zones to take in at the next frame: the detector with their ignore mask, the priority test
    (``priority(xy) -> bool`` for a floor point, m, or ``None``) and the zones themselves (``version``: which)."""

    detector: object
    priority: Callable | None
    zones: tuple
    version: int


class Operator:
    """The operator's requests (see the module docstring). Thread-safe; the control thread only reads
    :attr:`state` and calls :meth:`take_zones`."""

    def __init__(self):
        self._lock = threading.Lock()
        self.state = OperatorState()
        self._zones: ZoneSwap | None = None

    def _update(self, **changes) -> OperatorState:
        with self._lock:
            self.state = dataclasses.replace(self.state, version=self.state.version + 1, **changes)
            return self.state

    def choose(self, track: int | None) -> OperatorState:
        """Make track ``track`` the target (``None``: back to the automatic choice); ends a manual pointing."""
        return self._update(target=track, point=None, point_until=0.0)

    def pause(self, paused: bool) -> OperatorState:
        """Pause (or resume) the automatic targeting."""
        return self._update(paused=bool(paused))

    def point(self, pan: float, tilt: float, zoom: float, seconds: float = POINT_S, camera: int = 0) -> OperatorState:
        """Send PTZ ``camera`` to ``pan``, ``tilt`` (rad), ``zoom`` for ``seconds`` (or until :meth:`release`)."""
        if not all(math.isfinite(v) for v in (pan, tilt, zoom, seconds)) or seconds <= 0 or zoom <= 0:
            raise ValueError(f"a manual pointing needs finite pan, tilt, a zoom > 0 and seconds > 0, got "
                             f"{pan}, {tilt}, {zoom}, {seconds}")
        return self._update(point=(float(pan), float(tilt), float(zoom)), point_until=time.monotonic() + seconds,
                            point_camera=int(camera))

    def release(self) -> OperatorState:
        """End a manual pointing now."""
        return self._update(point=None, point_until=0.0)

    def offer_zones(self, swap: ZoneSwap) -> None:
        """Hand zones to the control thread (it takes them at its next frame; a newer offer replaces an older)."""
        with self._lock:
            self._zones = swap

    def take_zones(self) -> ZoneSwap | None:
        """The zones offered since the last call (control thread, once a frame), or ``None``."""
        if self._zones is None:
            return None
        with self._lock:
            swap, self._zones = self._zones, None
        return swap
