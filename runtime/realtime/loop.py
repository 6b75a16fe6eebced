"""The real-time loop: frame -> detection -> tracks -> target -> predicted head -> pan/tilt/zoom -> PTZ.

The control thread does only this, per frame (each stage timed):

1. ``capture``: the newest frame from the :class:`~runtime.sources.Capture` (stale frames are
   rejected there, broken and wrong-size frames are counted here and skipped);
2. ``control``: one compiled call (:func:`runtime.realtime.control.control_step`): the detector,
   the detections' floor positions, the tracker's arithmetic, and the aim pipeline at every
   confirmed track's head predicted to when the PTZ will get there (tracking and latency
   uncertainty included): pan/tilt, their covariance and the zoom of both rules;
3. ``track``: the tracker's bookkeeping (ids, hits, misses);
4. ``aim``: the target chosen (:class:`~runtime.realtime.targeting.TargetSelector`; only trusted
   tracks the PTZ can frame at ``p_contain``: else the loop holds and counts why, ``held_untrusted``
   or ``held_unframeable``) and its aim taken from the call's result, the dead-zone test;
5. ``send``: the PTZ command through the driver, unless it falls in the dead-zone;
6. ``adapt``: the background's life dispatched (:class:`~runtime.realtime.perception.BackgroundKeeper`:
   ghost repair, absorption, drift, fed by the tracker's trusted people; it runs while the loop waits
   for the next frame).

The operator's requests (the console: a chosen target, a pause, a manual pointing, new zones) are read
once a frame from :class:`~runtime.realtime.operator.Operator` without waiting (``operator``).

Everything else runs on another thread fed by a bounded queue that never holds up this one
(:class:`~runtime.realtime.drawing.OffPath`): the hooks (``draw``: the annotated frame with the
foveal inset and its encoding, the demo's scoring) and the log line; what it had to skip is
counted (``off_path`` in the summary).

The loop keeps going through faults (the source ends, a broken frame, a frame of the wrong
size, the PTZ port vanishing and returning) and counts each; on Ctrl-C or SIGTERM it sends
the PTZ home, writes the summary and closes the outputs.
"""

from __future__ import annotations

import copy
import dataclasses
import math
import signal
import sys
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from omnijax import INPUT_NAMES, Aim, Detector, Rig
from omnijax.zoom import ZOOM_RULES
from runtime.realtime.config import LoopConfig
from runtime.realtime.control import Slew, control_step, pan_tilt_slew_s, perceive
from runtime.realtime.drawing import OffPath
from runtime.realtime.operator import Operator, OperatorState
from runtime.realtime.perception import BackgroundKeeper
from runtime.realtime.sources import Capture, Frame
from runtime.realtime.targeting import TargetSelector, can_frame, outside_dead_zone, trust_rule
from runtime.realtime.tracker import Tracker
from runtime.realtime.zones import priority_test

#: Timed stages: the control thread's, then the drawing thread's (``draw``: the hooks; ``log``).
STAGES = ("capture", "control", "track", "aim", "send", "adapt", "draw", "log")
_slew_s = jax.jit(pan_tilt_slew_s)
__all__ = ["STAGES", "Command", "RealTimeLoop", "Samples", "Timings", "perceive"]


@dataclass
class Command:
    """What was (or would have been) sent for a frame (``track`` ``None``: the operator's manual pointing)."""

    track: int | None
    pan: float
    tilt: float
    zoom: float
    zooms: dict[str, float]
    sd_pan: float
    sd_tilt: float
    sent: bool
    t_predicted: float
    aimed: Aim | None = None
    floor_sd: np.ndarray | None = None  # sd of the predicted floor position (X, Y), m


class Samples:
    """The latest ``capacity`` values of a measurement in a preallocated ring buffer (memory stays
    flat however long the loop runs); statistics are over those."""

    def __init__(self, capacity: int = 65536):
        self._buf = np.full(capacity, np.nan)  # touched now, so resident memory does not creep up
        self.count = 0

    def append(self, v: float) -> None:
        self._buf[self.count % self._buf.size] = v
        self.count += 1

    def values(self) -> np.ndarray:
        return self._buf[: min(self.count, self._buf.size)]

    def recent(self, n: int) -> np.ndarray:
        """The last ``n`` values (fewer at the start)."""
        idx = np.arange(max(self.count - min(n, self._buf.size), 0), self.count) % self._buf.size
        return self._buf[idx]

    def __len__(self) -> int:
        return self.count


@dataclass
class Timings:
    """Per-stage and end-to-end times (ms)."""

    stages: dict[str, Samples] = field(default_factory=lambda: {s: Samples() for s in STAGES})
    latency: Samples = field(default_factory=Samples)  # frame available -> PTZ bytes written (driver's stamps)
    compute: Samples = field(default_factory=Samples)  # frame available -> command handed to the driver
    frame: Samples = field(default_factory=Samples)

    @staticmethod
    def stats(samples: Samples) -> dict:
        a = samples.values()
        if not a.size:
            return {"p50": None, "p99": None, "n": 0}
        return {"p50": float(np.median(a)), "p90": float(np.percentile(a, 90)),
                "p99": float(np.percentile(a, 99)), "max": float(a.max()), "n": int(samples.count)}


class RealTimeLoop:
    """Runs detection, tracking and PTZ control over a :class:`Capture` (see the module docstring).

    Hooks: ``on_frame(record, frame, dets, z, tracks, command, status)`` for each processed frame,
    called on the drawing thread, with ``dets`` the detections (NumPy), ``z`` the valid detections'
    floor positions (K, 2) m (the demo scores there and the annotated view is drawn there),
    ``tracks`` the tracks confirmed at that frame (copies), ``status`` the loop's counters then
    (:meth:`status`) and ``status["arrived"]`` the :class:`Command` the PTZ holds, arrived, on this
    frame's target at the frame's time (sent before it; ``None`` if there is none); it returns extra
    log fields.
    ``on_control(record, frame)``: called on the control thread after the send (fault injection
    that must happen at its frame), returning extra log fields; keep it cheap.
    ``driver`` may be ``None`` (no PTZ: commands are computed and logged only). ``operator``: the
    console's requests (:class:`~runtime.realtime.operator.Operator`), read once a frame; ``None``: none.
    """

    def __init__(self, rig: Rig, detector: Detector, background, capture: Capture, driver, profile,
                 config: LoopConfig, log_path: Path, on_frame: Callable | None = None,
                 on_control: Callable | None = None, operator: Operator | None = None,
                 learning_frames: int | None = None):
        self.rig, self.detector, self.capture = rig, detector, capture
        self.operator = operator
        self.zones, self.zones_version = rig.zones, 0
        self.driver, self.profile, self.cfg = driver, profile, config
        self.tracker = Tracker(config.tracker)
        if self.tracker.confirm < 2:
            raise ValueError("the fused control step aims at tracks matched again this frame: confirm must be >= 2")
        #: tracker slots in the compiled step; beyond them the tracks missing longest are dropped (counted)
        self.n_slots = 4 * detector.max_people
        self.selector = TargetSelector(config.target, config.dwell_s, trust_rule(config))
        #: how the background was learnt (frames, seconds, step, frame indices), for the summary
        self.learning: dict | None = None
        #: the background's life, stepped every ``adapt_every``-th frame after the send
        self.keeper = BackgroundKeeper(rig, detector, background, trust_rule(config), capture.source.fps,
                                       learning_frames or rig.detection.background_frames, config.adapt_every)
        self.selector.priority = priority_test(rig)
        self.timings = Timings()
        self.on_frame, self.on_control = on_frame, on_control
        self.log_path = log_path
        self.counts = {"frames": 0, "broken": 0, "wrong_size": 0, "commands_sent": 0, "dead_zone": 0,
                       "no_target": 0, "held_untrusted": 0, "held_unframeable": 0, "held_paused": 0,
                       "operator_frames": 0,
                       "invalid_geometry": 0, "deadline_overruns": 0, "tracks_over_slots": 0}
        self.sent: tuple[float, float, float] | None = None
        self.sent_at: float | None = None
        self._arrive_at = 0.0
        self._sent_track: int | None = None
        self._sent_command: Command | None = None
        self._stop = threading.Event()
        self._old_handlers: dict = {}
        self.t_start = time.monotonic()
        self._pending: dict[int, float] = {}  # driver sequence number -> frame available time
        self.stop_reason = "source ended"
        self.off_path: OffPath | None = None
        self._framable: set[int] = set()
        W, H = rig.omni.image_size
        self.shape = (H, W, 3)
        self.period = 1.0 / capture.source.fps if capture.source.fps else None
        if profile is not None:
            self._rates = (float(profile.pan.slew_deg_s()), float(profile.tilt.slew_deg_s()))
        else:
            self._rates = (1.0, 1.0)

    # -- control --------------------------------------------------------------------------

    def stop(self, reason: str) -> None:
        self.stop_reason = reason
        self._stop.set()

    def install_signal_handlers(self) -> None:
        """Ctrl-C and SIGTERM end the loop cleanly (PTZ home, summary written); see :meth:`restore_signal_handlers`."""
        for sig in (signal.SIGINT, signal.SIGTERM):
            self._old_handlers[sig] = signal.signal(sig, lambda s, _f: self.stop(signal.Signals(s).name))

    def restore_signal_handlers(self) -> None:
        """Put back the handlers :meth:`install_signal_handlers` replaced."""
        for sig, handler in self._old_handlers.items():
            signal.signal(sig, handler)
        self._old_handlers.clear()

    def _control(self, image, t: float):
        """The compiled per-frame call on ``image`` at time ``t`` with the tracker's current slots."""
        slew = Slew(known=jnp.asarray(self.sent is not None and self.profile is not None),
                    pan=jnp.asarray(self.sent[0] if self.sent else 0.0),
                    tilt=jnp.asarray(self.sent[1] if self.sent else 0.0),
                    pan_deg_s=jnp.asarray(self._rates[0]), tilt_deg_s=jnp.asarray(self._rates[1]),
                    latency_s=jnp.asarray(self.profile.link.command_latency_s if self.profile is not None else 0.0))
        tr = self.tracker
        return control_step(self.detector, self.rig, image, self.keeper.lines, tr.slots(self.n_slots),
                            jnp.asarray(t, float), tr.accel_sd, tr.nearest_gate_m, slew, mode=tr.mode,
                            confirm=tr.confirm)

    def warm_up(self):
        """Compile the jitted stages on a frame of the right size before timing anything; returns
        the (empty) detections of the blank frame."""
        blank = jnp.zeros(self.shape, jnp.uint8)
        out = jax.block_until_ready(self._control(blank, 0.0))
        dets = out.dets
        self.keeper.warm_up(blank, dets, out.d2)
        _slew_s(0.0, 0.0, 0.0, 0.0, *self._rates).block_until_ready()
        return dets

    # -- the loop -------------------------------------------------------------------------

    def run(self) -> None:
        self.t_start = t_start = time.monotonic()
        last_status = t_start
        self.off_path = OffPath(self.log_path, self.on_frame, self._describe, self._record,
                                block=not getattr(self.capture, "paced", True))
        try:
            while not self._stop.is_set():
                if self.cfg.max_frames is not None and self.counts["frames"] >= self.cfg.max_frames:
                    self.stop_reason = "frame limit"
                    break
                if self.cfg.max_seconds is not None and time.monotonic() - t_start >= self.cfg.max_seconds:
                    self.stop_reason = "time limit"
                    break
                t0 = time.monotonic()
                frame = self.capture.get(timeout=0.5)
                if frame is None:
                    if self.capture.ended:
                        self.stop_reason = "source ended"
                        break
                    continue
                self._record("capture", t0)
                self._process(frame)
                if self.off_path.error is not None:
                    self.stop_reason = "the drawing thread failed"
                    break
                now = time.monotonic()
                if not self.cfg.quiet and now - last_status >= self.cfg.status_every_s:
                    self._status(now - t_start)
                    last_status = now
        finally:
            self.elapsed = time.monotonic() - t_start
            self.off_path.close()
        if not self.cfg.quiet:
            sys.stderr.write("\n")

    def _record(self, stage: str, t0: float) -> float:
        t1 = time.monotonic()
        self.timings.stages[stage].append(1e3 * (t1 - t0))
        return t1

    def _process(self, frame: Frame) -> None:
        record: dict = {"frame": frame.index, "t": round(frame.t, 6)}
        if frame.image is None:
            self.counts["broken"] += 1
            self.off_path.submit({"record": {**record, "fault": "broken frame"}})
            return
        if frame.image.shape != self.shape:
            self.counts["wrong_size"] += 1
            h, w = frame.image.shape[:2]
            fault = f"frame {w}x{h}, expected {self.shape[1]}x{self.shape[0]}"
            self.off_path.submit({"record": {**record, "fault": fault}})
            return
        self.counts["frames"] += 1
        t = time.monotonic()
        op = None
        if self.operator is not None:
            swap = self.operator.take_zones()
            if swap is not None:  # rebuilt off this thread; same shapes, nothing recompiles
                self.detector, self.selector.priority = swap.detector, swap.priority
                self.keeper.detector = swap.detector
                self.zones, self.zones_version = swap.zones, swap.version
            op = self.operator.state
        tracker = self.tracker
        if len(tracker.tracks) > self.n_slots:  # many false alarms: keep the tracks seen most recently
            self.counts["tracks_over_slots"] += len(tracker.tracks) - self.n_slots
            tracker.tracks = sorted(tracker.tracks, key=lambda tr: tr.misses)[: self.n_slots]
        slots = list(tracker.tracks)
        x = jnp.asarray(frame.image)
        out = self._control(x, frame.stamp)
        c = jax.device_get(out)
        t = self._record("control", t)
        valid = np.asarray(c.dets.valid)
        compact = np.cumsum(valid) - 1  # index among the valid detections
        assign = np.where(c.assign >= 0, compact[np.clip(c.assign, 0, None)], -1)[: len(slots)]
        z, R = c.z[valid], c.R[valid]
        tracker.apply(frame.stamp, z, R, assign, c.x, c.P)
        confirmed = tracker.confirmed()
        t = self._record("track", t)
        aim_of = {slots[int(i)].id: j for j, (i, ok) in enumerate(zip(c.aim_slot, c.aim_ok)) if ok}
        pointing = op.pointing(time.monotonic()) if op is not None else None
        if pointing is not None:
            command = self._manual(frame, pointing)
        else:
            command = self._aim(frame, confirmed, c, aim_of, op)
        if op is not None and (pointing is not None or op.paused or op.target is not None):
            record["operator"] = "point" if pointing is not None else "paused" if op.paused else "target"
            self.counts["operator_frames"] += 1
        t = self._record("aim", t)
        arrived = self._arrived(command, frame.stamp)  # what the PTZ holds at the frame's time, before this send
        if command is not None and command.sent:
            self._send(command, frame.stamp)
        t_sent = time.monotonic()
        self._record("send", t)
        if command is not None and command.sent:
            self.timings.compute.append(1e3 * (t_sent - frame.t))
            if self.driver is None:
                self.timings.latency.append(1e3 * (t_sent - frame.t))
            else:
                self._pending[self.driver.sequence] = frame.t
        self._collect_writes()
        if self.on_control is not None:
            record.update(self.on_control(record, frame) or {})
        t = t_sent
        if command is None and self.selector.held is not None:
            record["held"] = self.selector.held
        if self.counts["frames"] % self.cfg.adapt_every == 0:  # dispatched, not waited for
            where = np.nonzero(valid)[0]
            slot_of = {tr.id: int(where[tr.detection]) for tr in tracker.tracks if tr.detection is not None}
            self.keeper.update(x, out.dets, out.d2, self.keeper.trusted(tracker.tracks, slot_of, valid.shape[0]))
        self._record("adapt", t)
        status = self.status()
        status["arrived"] = arrived
        if arrived is not None:
            record["ptz_arrived"] = True
        self.off_path.submit({"record": record, "frame": frame, "dets": c.dets, "z": z,
                              "tracks": [copy.copy(tr) for tr in confirmed], "command": command,
                              "status": status})
        elapsed = time.monotonic() - frame.t
        self.timings.frame.append(1e3 * elapsed)
        if self.period and elapsed > self.period:
            self.counts["deadline_overruns"] += 1

    def status(self) -> dict:
        """A snapshot of the loop's counters for the drawing thread (taken on the control thread)."""
        st = {"frames": self.counts["frames"], "elapsed": time.monotonic() - self.t_start,
              "counts": dict(self.counts), "capture": dict(self.capture.counts), "captures": self.selector.captures,
              "driver": None, "held": self.selector.held, "framable": sorted(self._framable),
              "sent": self.sent, "operator": self.operator.state if self.operator is not None else None,
              "zones_version": self.zones_version}
        if self.driver is not None:
            st["driver"] = {"connected": self.driver.connected, **self.driver.counters}
        return st

    def _settled(self, stamp: float) -> bool:
        """Whether the PTZ should have reached the last command by the frame stamped ``stamp`` (slew-time
        estimate on the frames' clock, so that ``--pace all`` runs are repeatable)."""
        if self.sent_at is None or self.sent is None:
            return False
        return stamp >= self._arrive_at

    def _arrived(self, command: Command | None, stamp: float) -> Command | None:
        """The command the PTZ holds at the frame stamped ``stamp`` (the last one sent before it), if it
        has arrived there by then (:meth:`_settled`) and it aims at this frame's target (the loop's own
        pointing, as the demo scores it); ``None`` otherwise (no target, the operator's pointing, a new
        target or still slewing)."""
        sent = self._sent_command
        if (command is None or command.track is None or sent is None or sent.track != command.track
                or not self._settled(stamp)):
            return None
        return sent

    def _slew_time(self, target: tuple[float, float, float]) -> float:
        """Seconds the PTZ needs from the last command to ``target``: the device profile's command latency,
        then its slew rates and zoom speed."""
        if self.profile is None or self.sent is None:
            return 0.0
        pan_tilt = float(_slew_s(target[0], target[1], self.sent[0], self.sent[1], *self._rates))
        zp = self.profile.zoom
        z_span = max(zp.position) - min(zp.position)
        d_zoom = abs(self.profile.zoom_position(target[2]) - self.profile.zoom_position(self.sent[2])) / z_span
        return self.profile.link.command_latency_s + max(pan_tilt, d_zoom * zp.seconds_full_range)

    def _manual(self, frame: Frame, pointing: tuple[float, float, float]) -> Command:
        """The operator's manual pointing as this frame's command (sent when it changes)."""
        pan, tilt, zoom = pointing
        return Command(track=None, pan=pan, tilt=tilt, zoom=zoom, zooms=dict.fromkeys(ZOOM_RULES, zoom), sd_pan=0.0,
                       sd_tilt=0.0, sent=self.sent != pointing or self._sent_track is not None,
                       t_predicted=frame.stamp)

    def _aim(self, frame: Frame, tracks, c, aim_of: dict[int, int], op: OperatorState | None = None) -> Command | None:
        aims: dict[int, tuple[int, Aim]] = {}
        self._framable = set()

        def framable(track) -> bool:
            if track.id in aims:
                return track.id in self._framable
            j = aim_of.get(track.id)
            if j is None:  # not aimed at in the control step (not matched this frame)
                return False
            aims[track.id] = (j, jax.tree.map(lambda a: a[j], c.aims))
            if not bool(aims[track.id][1].pointing.valid):
                self.counts["invalid_geometry"] += 1
            ok = can_frame(aims[track.id][1], self.cfg.zoom_rule)
            if ok:
                self._framable.add(track.id)
            return ok

        if op is not None:  # the console shows which tracks the operator can pick
            for tr in tracks:
                framable(tr)
        target = self.selector.choose(frame.stamp, tracks, self._settled(frame.stamp), framable,
                                      manual=op.target if op is not None else None,
                                      paused=op is not None and op.paused)
        if target is None:
            self.counts["no_target"] += 1
            if self.selector.held is not None:
                self.counts[f"held_{self.selector.held}"] += 1
            return None
        j, aimed = aims[target.id]
        zooms = {rule: float(aimed.zooms[rule].zoom) for rule in ZOOM_RULES}
        pan, tilt, zoom = float(aimed.pointing.pan), float(aimed.pointing.tilt), zooms[self.cfg.zoom_rule]
        cov = aimed.covariance.cov
        sd_pan, sd_tilt = math.sqrt(cov[0, 0]), math.sqrt(cov[1, 1])
        new_target = self.selector.current != self._sent_track
        send = new_target or outside_dead_zone((pan, tilt, zoom), self.sent, sd_pan, sd_tilt, self.cfg.dead_zone_sd)
        if not send:
            self.counts["dead_zone"] += 1
        return Command(track=target.id, pan=pan, tilt=tilt, zoom=zoom, zooms=zooms, sd_pan=sd_pan,
                       sd_tilt=sd_tilt, sent=send, t_predicted=frame.stamp + float(c.lead[j]), aimed=aimed,
                       floor_sd=c.floor_sd[j])

    def _send(self, cmd: Command, stamp: float) -> None:
        """Hand ``cmd`` to the driver; the PTZ is expected there its slew time after the frame ``stamp``."""
        if self.driver is not None:
            self.driver.set_target(cmd.pan, cmd.tilt, cmd.zoom)
            time.sleep(0)  # hand the GIL to the driver's worker now, so that the bytes go out at once
        self._arrive_at = stamp + self._slew_time((cmd.pan, cmd.tilt, cmd.zoom))
        self.sent = (cmd.pan, cmd.tilt, cmd.zoom)
        self.sent_at = time.monotonic()
        self._sent_track = cmd.track
        self._sent_command = cmd
        self.counts["commands_sent"] += 1

    def _collect_writes(self) -> None:
        """Frame-to-wire latency of the targets the driver has written (superseded ones never are)."""
        if self.driver is None:
            return
        for seq, t_write in self.driver.take_writes():
            t_frame = self._pending.pop(seq, None)
            if t_frame is not None:
                self.timings.latency.append(1e3 * (t_write - t_frame))
            for k in [k for k in self._pending if k < seq]:
                del self._pending[k]

    def home(self, wait_s: float = 3.0) -> bool:
        """Send the PTZ home (end of run); whether it reported being there within ``wait_s``."""
        if self.driver is None:
            return True
        self.driver.set_target(*self.cfg.home)
        reached = self.driver.wait_reached(wait_s)
        self._collect_writes()
        return reached

    # -- reporting ------------------------------------------------------------------------

    @staticmethod
    def _describe(item: dict) -> dict:
        """The log fields of a processed frame (on the drawing thread; everything in it is NumPy)."""
        dets, command = item["dets"], item["command"]
        people = [{"r_f": round(float(dets.r_f[k]), 3), "theta_f": round(float(dets.theta_f[k]), 5),
                   "sigma_r_f": round(float(dets.sigma_r_f[k]), 3),
                   "sigma_theta_f": round(float(dets.sigma_theta_f[k]), 5),
                   "contrast": round(float(dets.contrast[k]), 2)} for k in np.nonzero(dets.valid)[0]]
        out = {"detections": people,
               "tracks": [{"id": tr.id, "xy": [round(float(v), 3) for v in tr.position],
                           "v": [round(float(v), 3) for v in tr.x[2:]], "captured": tr.captured}
                          for tr in item["tracks"]]}
        if command is not None:
            out["ptz"] = {"track": command.track, "pan_deg": round(math.degrees(command.pan), 3),
                          "tilt_deg": round(math.degrees(command.tilt), 3), "zoom": round(command.zoom, 3),
                          "zooms": {k: round(v, 3) for k, v in command.zooms.items()},
                          "sd_pan_deg": round(math.degrees(command.sd_pan), 4),
                          "sd_tilt_deg": round(math.degrees(command.sd_tilt), 4), "sent": command.sent,
                          "t_predicted": round(command.t_predicted, 4),
                          "floor_sd_m": (None if command.floor_sd is None
                                         else [round(float(v), 4) for v in command.floor_sd])}
        return out

    def _status(self, elapsed: float) -> None:
        n = self.counts["frames"]
        lat = self.timings.latency.recent(50)
        ptz = ""
        if self.sent is not None:
            ptz = f"PTZ {math.degrees(self.sent[0]):6.1f}/{math.degrees(self.sent[1]):5.1f} deg x{self.sent[2]:4.1f}"
        errors = ""
        if self.driver is not None:
            c = self.driver.counters
            errors = f" err {c['errors']} reconn {c['reconnects']}" + ("" if self.driver.connected else " [PTZ down]")
        sys.stderr.write(
            f"\r{n:6d} frames {n / max(elapsed, 1e-9):5.1f} fps | latency "
            f"{np.median(lat) if lat.size else float('nan'):5.2f} ms | tracks {len(self.tracker.confirmed()):2d} | "
            f"{ptz}{errors} | dropped {self.capture.counts['dropped']} stale {self.capture.counts['stale']}   ")
        sys.stderr.flush()

    def summary(self) -> dict:
        """The ``summary.json`` object (docs/design.md section 7.3), without the demo's scores."""
        frames = self.counts["frames"]
        ptz = {"commands": self.counts["commands_sent"], "errors": 0, "reconnects": 0}
        if self.driver is not None:
            st = self.driver.stats()
            ptz = {"commands": st["commands"], "errors": st["errors"], "reconnects": st["reconnects"],
                   "commands_requested": self.counts["commands_sent"], "driver": st}
        return {
            "frames": frames,
            "fps": frames / self.elapsed if getattr(self, "elapsed", 0) else 0.0,
            "seconds": getattr(self, "elapsed", 0.0),
            "stop_reason": self.stop_reason,
            "latency_ms": Timings.stats(self.timings.latency),
            "compute_latency_ms": Timings.stats(self.timings.compute),
            "frame_ms": Timings.stats(self.timings.frame),
            "stages_ms": {k: Timings.stats(v) for k, v in self.timings.stages.items()},
            "ptz": ptz,
            "faults": {"broken_frames": self.capture.counts["broken"],
                       "wrong_size_frames": self.capture.counts["wrong_size"],
                       "stale_frames": self.capture.counts["stale"], "dropped_frames": self.capture.counts["dropped"],
                       "deadline_overruns": self.counts["deadline_overruns"],
                       "source_ended": self.stop_reason == "source ended"},
            "off_path": self.off_path.summary() if self.off_path is not None else None,
            "counts": self.counts,
            "background": self.keeper.summary(),
            "captures": self.selector.captures,
            "config": {"zoom_rule": self.cfg.zoom_rule, "tracker": self.cfg.tracker, "target": self.cfg.target,
                       "dwell_s": self.cfg.dwell_s, "dead_zone_sd": self.cfg.dead_zone_sd,
                       "trust": dataclasses.asdict(self.selector.trust),
                       "inputs": list(INPUT_NAMES)},
        }
