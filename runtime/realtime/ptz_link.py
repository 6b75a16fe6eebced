"""One PTZ as the real-time loop drives it: its driver and device profile, the last command sent, when
the PTZ should be there, and the frame-to-wire latency of its commands.

The loop holds one :class:`PtzLink` per PTZ of the rig, in the rig's order. Arrival is estimated on
the frames' own clock (the command's slot, below, plus the profile's command latency and slew time), never
the wall clock, so that a run that processes every frame (``--pace all``) makes the same choices
every time.

The device takes at most one target per ``link.min_interval_s`` (the profile's rate limit; the driver
enforces it on the wall clock, the latest target winning). The link keeps, on the frames' clock, the slot
at which its last command leaves (its frame's stamp, or the end of the interval after the one before,
or the one before's own slot if it had not left yet: the latest target replaces it there);
a command handed sooner waits for its slot, so the head is predicted to the slot (:meth:`PtzLink.slew`)
and the PTZ is expected there its slew time after it. ``--rate-wait-ms MS`` instead hands a command
only on a frame whose command would wait at most MS (:meth:`PtzLink.ready`; the next frame's, fresher,
goes instead, ``counts.rate_held``): the frame -> bytes latency then stays the loop's own, at the cost
of fewer commands, and the pointing measured worse for it (docs/runtime.md, "The rate limit and the
latency").
"""

from __future__ import annotations

import time

import jax
import numpy as np

from runtime.realtime.control import Slew, pan_tilt_slew_s

_slew_s = jax.jit(pan_tilt_slew_s)


class PtzLink:
    """PTZ ``index`` of the rig: ``driver`` (``None``: commands are computed and logged only) and its
    device ``profile`` (``None``: unknown, no slew-time prediction)."""

    def __init__(self, index: int, driver, profile):
        self.index, self.driver, self.profile = index, driver, profile
        #: the slew rates of the moves the driver commands (the speed code it sends), deg/s
        self.rates = profile.move_rates_deg_s() if profile is not None else (1.0, 1.0)
        #: the last command sent (pan, tilt rad, zoom), when (``time.monotonic()``) and for which track
        self.sent: tuple[float, float, float] | None = None
        self.sent_at: float | None = None
        #: when (frame clock, s) the last command sent leaves for the device (:meth:`_slot_for`)
        self.slot: float | None = None
        #: the device's rate limit: at most one target per this many seconds (0: none known)
        self.min_interval_s = profile.link.min_interval_s if profile is not None else 0.0
        self.sent_track: int | None = None
        self.sent_command = None  # the last Command sent
        #: the frame stamp (s) by which the PTZ should have reached :attr:`sent`
        self.arrive_at = 0.0
        self.commands = 0
        #: driver sequence number -> (frame available, its loop step ended), ``time.monotonic()``
        self._pending: dict[int, tuple[float, float]] = {}

    def slew(self, stamp: float = 0.0) -> Slew:
        """What the control call's head prediction needs of this PTZ on the frame stamped ``stamp`` (NumPy
        scalars, the loop stacks them: no JAX operation runs on the control thread outside its compiled call):
        the latency is the profile's command latency and the wait for the command's slot (:meth:`wait`)."""
        sent, profile = self.sent, self.profile
        latency = profile.link.command_latency_s + self.wait(stamp) if profile is not None else 0.0
        return Slew(known=np.asarray(sent is not None and profile is not None),
                    pan=np.asarray(sent[0] if sent else 0.0), tilt=np.asarray(sent[1] if sent else 0.0),
                    pan_deg_s=np.asarray(self.rates[0]), tilt_deg_s=np.asarray(self.rates[1]),
                    latency_s=np.asarray(latency))

    def wait(self, stamp: float) -> float:
        """Seconds a command handed on the frame stamped ``stamp`` waits for its slot (the device's rate limit
        after the last command's slot, on the frames' clock)."""
        return max(0.0, self._slot_for(stamp) - stamp)

    def _slot_for(self, stamp: float) -> float:
        """When a command handed on the frame stamped ``stamp`` leaves: the driver sends the latest target, so
        one handed before the last command's slot replaces it there; after it, it leaves the rate limit's
        interval after that slot, or at once if that has passed."""
        if self.slot is None:
            return stamp
        return self.slot if stamp < self.slot else max(stamp, self.slot + self.min_interval_s)

    def warm_up(self) -> None:
        """Compile the slew-time estimate."""
        _slew_s(0.0, 0.0, 0.0, 0.0, *self.rates).block_until_ready()

    def settled(self, stamp: float) -> bool:
        """Whether the PTZ should have reached the last command by the frame stamped ``stamp``."""
        if self.sent_at is None or self.sent is None:
            return False
        return stamp >= self.arrive_at

    def arrived(self, command, stamp: float):
        """The command this PTZ holds at the frame stamped ``stamp`` (the last one sent before it), if it has
        arrived there by then (:meth:`settled`) and it aims at ``command``'s target, this frame's (the loop's
        own pointing, as the demo scores it); ``None`` otherwise (no target, the operator's pointing, a new
        target or still slewing)."""
        sent = self.sent_command
        if (command is None or command.track is None or sent is None or sent.track != command.track
                or not self.settled(stamp)):
            return None
        return sent

    def ready(self, stamp: float, wait_s: float = 0.0) -> bool:
        """Whether a command handed on the frame stamped ``stamp`` would leave for the device within ``wait_s``:
        the device's rate limit (``min_interval_s``) after the last command's slot, on the frames' clock."""
        return self.wait(stamp) <= wait_s + 1e-9  # frame-clock rounding

    def slew_time(self, target: tuple[float, float, float]) -> float:
        """Seconds the PTZ needs from the last command to ``target``: the device profile's command latency,
        then its slew rates and zoom speed."""
        if self.profile is None or self.sent is None:
            return 0.0
        pan_tilt = float(_slew_s(target[0], target[1], self.sent[0], self.sent[1], *self.rates))
        zp = self.profile.zoom
        z_span = max(zp.position) - min(zp.position)
        d_zoom = abs(self.profile.zoom_position(target[2]) - self.profile.zoom_position(self.sent[2])) / z_span
        return self.profile.link.command_latency_s + max(pan_tilt, d_zoom * zp.seconds_full_range)

    def send(self, cmd, stamp: float, frame_t: float | None = None) -> None:
        """Hand ``cmd`` (a :class:`~runtime.realtime.loop.Command`) to the driver; the PTZ is expected there
        its slew time after the command's slot (the frame ``stamp``, or the rate limit's end if later).
        ``frame_t``: when the frame became available
        (``time.monotonic()``), for the latency to the bytes written."""
        if self.driver is not None:
            self.driver.set_target(cmd.pan, cmd.tilt, cmd.zoom)
            time.sleep(0)  # hand the GIL to the driver's worker now, so that the bytes go out at once
            if frame_t is not None:
                self._pending[self.driver.sequence] = (frame_t, frame_t)
        self.slot = self._slot_for(stamp)
        self.arrive_at = self.slot + self.slew_time((cmd.pan, cmd.tilt, cmd.zoom))
        self.sent = (cmd.pan, cmd.tilt, cmd.zoom)
        self.sent_at = time.monotonic()
        self.sent_track = cmd.track
        self.sent_command = cmd
        self.commands += 1

    def step_ended(self, t: float) -> None:
        """The loop step that sent the last command ended at ``t`` (for a command superseded before the wire)."""
        if self.driver is not None and self.driver.sequence in self._pending:
            self._pending[self.driver.sequence] = (self._pending[self.driver.sequence][0], t)

    def take_writes(self) -> tuple[list[float], list[float]]:
        """Frame-to-wire latencies (ms) of the targets the driver has written since the last call, and the
        frame ages (ms) they settle: a written target's frame aged until the write, a superseded one's
        (never written) until its loop step ended."""
        latencies: list[float] = []
        ages: list[float] = []
        if self.driver is None:
            return latencies, ages
        for seq, t_write in self.driver.take_writes():
            pending = self._pending.pop(seq, None)
            if pending is not None:
                latencies.append(1e3 * (t_write - pending[0]))
                ages.append(1e3 * (t_write - pending[0]))
            for k in [k for k in self._pending if k < seq]:
                t_frame, t_step = self._pending.pop(k)
                ages.append(1e3 * (t_step - t_frame))
        return latencies, ages

    def link_status(self) -> dict | None:
        """The driver's link state and counters (``None``: no driver)."""
        if self.driver is None:
            return None
        return {"connected": self.driver.connected, **self.driver.counters}
