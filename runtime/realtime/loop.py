"""The real-time loop: frame -> detection -> tracks -> target -> predicted head -> pan/tilt/zoom -> PTZ.

The control thread does only this, per frame (each stage timed):

1. ``capture``: the newest frame from the :class:`~runtime.sources.Capture` (stale frames are
   rejected there, broken and wrong-size frames are counted here and skipped);
2. ``control``: one compiled call (:func:`runtime.realtime.control.control_step`): the detector,
   the detections' floor positions, the tracker's arithmetic, and the aim pipeline for every PTZ at
   every confirmed track's head predicted to when that PTZ will get there (tracking and latency
   uncertainty included): pan/tilt, their covariance and the zoom of both rules;
3. ``track``: the tracker's bookkeeping (ids, hits, misses);
4. ``aim``: the target chosen, with one PTZ by the :class:`~runtime.realtime.targeting.TargetSelector`,
   with several by the exact assignment of :class:`~runtime.realtime.assignment.CameraAssigner` (only
   trusted tracks a PTZ can frame at ``p_contain``: else the loop holds and counts why,
   ``held_untrusted`` or ``held_unframeable``), each target's aim taken from the call's result, the
   dead-zone test;
5. ``send``: each PTZ's command through its driver (:class:`~runtime.realtime.ptz_link.PtzLink`),
   unless it falls in the dead-zone;
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
from runtime.realtime.assignment import CameraAssigner, PairValues
from runtime.realtime.config import LoopConfig
from runtime.realtime.control import control_step, perceive
from runtime.realtime.drawing import OffPath
from runtime.realtime.operator import Operator, OperatorState
from runtime.realtime.perception import BackgroundKeeper
from runtime.realtime.ptz_link import PtzLink
from runtime.realtime.sources import Capture, Frame
from runtime.realtime.targeting import TargetSelector, can_frame, outside_dead_zone, trust_rule
from runtime.realtime.tracker import Tracker
from runtime.realtime.zones import priority_test

#: Timed stages: the control thread's, then the drawing thread's (``draw``: the hooks; ``log``).
STAGES = ("capture", "control", "track", "aim", "send", "adapt", "draw", "log")
__all__ = ["STAGES", "Command", "RealTimeLoop", "Samples", "Timings", "perceive"]


@dataclass
class Command:
    """What was (or would have been) sent for a frame (``track`` ``None``: the operator's manual pointing;
    ``xy``: the track's filtered floor position (m) when the command was made)."""

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
    floor_sd: np.ndarray | None = None  # sd of the floor position the aim used (X, Y), m (control.Control)
    xy: np.ndarray | None = None


class Samples:
    """The latest ``capacity`` values of a measurement in a preallocated ring buffer (memory stays
    flat however long the loop runs); statistics are over those."""

    def __init__(self, capacity: int = 65536):
        self._buf = np.full(capacity, np.nan)  # touched now, so resident memory does not creep up
        self.count = 0

    def append(self, v: float) -> None:
        self._buf[self.count % self._buf.size] = v
        self.count += 1

    def extend(self, values) -> None:
        for v in values:
            self.append(v)

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
    latency: Samples = field(default_factory=Samples)  # frame arrived -> PTZ bytes written (driver's stamps)
    compute: Samples = field(default_factory=Samples)  # frame arrived -> command handed to the driver
    frame: Samples = field(default_factory=Samples)
    #: every processed frame: arrived -> its PTZ bytes written, or (nothing written for it) -> its step's end
    age: Samples = field(default_factory=Samples)

    @staticmethod
    def stats(samples: Samples) -> dict:
        a = samples.values()
        if not a.size:
            return {"p50": None, "p99": None, "n": 0}
        return {"p50": float(np.median(a)), "p90": float(np.percentile(a, 90)),
                "p99": float(np.percentile(a, 99)), "max": float(a.max()), "n": int(samples.count)}


class RealTimeLoop:
    """Runs detection, tracking and PTZ control over a :class:`Capture` (see the module docstring).

    Hooks: ``on_frame(record, frame, dets, z, tracks, commands, status)`` for each processed frame,
    called on the drawing thread, with ``dets`` the detections (NumPy), ``z`` the valid detections'
    floor positions (K, 2) m (the demo scores there and the annotated view is drawn there),
    ``tracks`` the tracks confirmed at that frame (copies), ``commands`` each PTZ's :class:`Command`
    (``None``: no target), in the rig's order, ``status`` the loop's counters then (:meth:`status`)
    and ``status["arrived"]`` per PTZ the :class:`Command` it holds, arrived, on its target of this
    frame at the frame's time (sent before it; ``None`` if there is none); it returns extra log fields.
    ``on_control(record, frame)``: called on the control thread after the send (fault injection
    that must happen at its frame), returning extra log fields; keep it cheap.
    ``links``: one :class:`~runtime.realtime.ptz_link.PtzLink` per PTZ of the rig, in its order (a link
    without a driver: commands are computed and logged only). ``operator``: the console's requests
    (:class:`~runtime.realtime.operator.Operator`), read once a frame; ``None``: none.
    """

    def __init__(self, rig: Rig, detector: Detector, background, capture: Capture, links: list[PtzLink],
                 config: LoopConfig, log_path: Path, on_frame: Callable | None = None,
                 on_control: Callable | None = None, operator: Operator | None = None,
                 learning_frames: int | None = None):
        if len(links) != rig.ptz_count:
            raise ValueError(f"one PTZ link per PTZ of the rig ({rig.ptz_count}), got {len(links)}")
        self.rig, self.detector, self.capture = rig, detector, capture
        self.operator = operator
        self.zones, self.zones_version = rig.zones, 0
        self.links, self.cfg = list(links), config
        self.tracker = Tracker(config.tracker)
        if self.tracker.confirm < 2:
            raise ValueError("the fused control step aims at tracks matched again this frame: confirm must be >= 2")
        #: tracker slots in the compiled step; beyond them the tracks missing longest are dropped (counted)
        self.n_slots = 4 * detector.max_people
        #: one PTZ: the round-robin selector; several: the exact assignment (its own trust and ghost sites)
        self.selector = TargetSelector(config.target, config.dwell_s, trust_rule(config))
        self.assigner = (CameraAssigner(len(links), config.dwell_s, trust_rule(config),
                                        float(rig.layout.face_target_px), capacity=self.n_slots)
                         if len(links) > 1 else None)
        #: how the background was learnt (frames, seconds, step, frame indices), for the summary
        self.learning: dict | None = None
        #: the background's life, stepped every ``adapt_every``-th frame after the send
        self.keeper = BackgroundKeeper(rig, detector, background, trust_rule(config), capture.source.fps,
                                       learning_frames or rig.detection.background_frames, config.adapt_every)
        self.selector.priority = priority_test(rig)
        if self.assigner is not None:
            self.assigner.priority = self.selector.priority
        self.timings = Timings()
        self.rate_wait_s = math.inf if config.rate_wait_ms is None else 1e-3 * config.rate_wait_ms
        self.on_frame, self.on_control = on_frame, on_control
        self.log_path = log_path
        self.counts = {"frames": 0, "broken": 0, "wrong_size": 0, "commands_sent": 0, "dead_zone": 0, "rate_held": 0,
                       "no_target": 0, "held_untrusted": 0, "held_unframeable": 0, "held_paused": 0,
                       "operator_frames": 0,
                       "invalid_geometry": 0, "deadline_overruns": 0, "tracks_over_slots": 0}
        #: per PTZ, frames on which it had a target, and its latest command
        self.target_frames = [0] * len(links)
        self._last: list[Command | None] = [None] * len(links)
        self._stop = threading.Event()
        #: set by a second Ctrl-C or SIGTERM (``hurried_by``): finish quickly, keeping what was recorded
        self.hurry = threading.Event()
        self.hurried_by: str | None = None
        self._old_handlers: dict = {}
        self.t_start = time.monotonic()
        self.stop_reason = "source ended"
        self.off_path: OffPath | None = None
        self._framable: set[int] = set()
        W, H = rig.omni.image_size
        self.shape = (H, W, 3)
        self.period = 1.0 / capture.source.fps if capture.source.fps else None

    @property
    def sent(self) -> tuple[float, float, float] | None:
        """The first PTZ's last command (pan, tilt rad, zoom)."""
        return self.links[0].sent

    # -- control --------------------------------------------------------------------------

    def stop(self, reason: str) -> None:
        self.stop_reason = reason
        self._stop.set()

    def install_signal_handlers(self) -> None:
        """Ctrl-C and SIGTERM end the loop cleanly (PTZ home, summary written); a second one while the outputs are
        written sets :attr:`hurry`: what is left is cut short (no more drawing, no wait for the PTZ to get home)
        and what was recorded is kept. Until :meth:`restore_signal_handlers`."""
        for sig in (signal.SIGINT, signal.SIGTERM):
            self._old_handlers[sig] = signal.signal(sig, self._on_signal)

    def _on_signal(self, signum: int, _frame) -> None:
        name = signal.Signals(signum).name
        if not self._stop.is_set():
            self.stop(name)
        elif not self.hurry.is_set():
            self.hurried_by = name
            self.hurry.set()

    def restore_signal_handlers(self) -> None:
        """Put back the handlers :meth:`install_signal_handlers` replaced."""
        for sig, handler in self._old_handlers.items():
            signal.signal(sig, handler)
        self._old_handlers.clear()

    def _control(self, image, t: float):
        """The compiled per-frame call on ``image`` at time ``t`` with the tracker's current slots."""
        slew = jax.tree.map(lambda *a: np.stack(a), *[link.slew(t) for link in self.links])
        tr = self.tracker
        return control_step(self.detector, self.rig, image, self.keeper.lines, tr.slots(self.n_slots),
                            np.asarray(t, float), tr.accel_sd, tr.nearest_gate_m, slew, mode=tr.mode,
                            confirm=tr.confirm, prev=self.keeper.life.prev)

    def warm_up(self):
        """Compile the jitted stages on a frame of the right size before timing anything; returns
        the (empty) detections of the blank frame."""
        blank = jnp.zeros(self.shape, jnp.uint8)
        out = jax.block_until_ready(self._control(blank, 0.0))
        dets = out.dets
        self.keeper.warm_up(blank, dets, out.trace)
        for link in self.links:
            link.warm_up()
        if self.assigner is not None:
            self.assigner.warm_up()
        return dets

    # -- the loop -------------------------------------------------------------------------

    def run(self) -> None:
        self.t_start = t_start = time.monotonic()
        last_status = t_start
        self.off_path = OffPath(self.log_path, self.on_frame, self._describe, self._record,
                                block=not getattr(self.capture, "paced", True), hurry=self.hurry)
        self.capture.begin()
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
        record["wait_ms"] = round(1e3 * (t - frame.t), 3)  # how old it was when taken: a backlog shows here
        op = None
        if self.operator is not None:
            swap = self.operator.take_zones()
            if swap is not None:  # rebuilt off this thread; same shapes, nothing recompiles
                self.detector, self.selector.priority = swap.detector, swap.priority
                if self.assigner is not None:
                    self.assigner.priority = swap.priority
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
        c = _to_host(out)
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
        if self.assigner is None:
            commands = [self._manual(frame, pointing, self.links[0]) if pointing is not None
                        else self._aim(frame, confirmed, c, aim_of, op)]
            held = self.selector.held
        else:
            commands, held = self._assign(frame, confirmed, c, aim_of, op, pointing)
        if op is not None and (pointing is not None or op.paused or op.target is not None):
            record["operator"] = "point" if pointing is not None else "paused" if op.paused else "target"
            self.counts["operator_frames"] += 1
        for k, command in enumerate(commands):
            if command is not None and command.track is not None:
                self.target_frames[k] += 1
        t = self._record("aim", t)
        # what each PTZ holds at the frame's time, before this frame's sends
        arrived = [link.arrived(command, frame.stamp) for link, command in zip(self.links, commands)]
        sent = [k for k, command in enumerate(commands) if command is not None and command.sent]
        for k in sent:
            self.links[k].send(commands[k], frame.stamp, frame.t)
            self.counts["commands_sent"] += 1
        t_sent = time.monotonic()
        self._record("send", t)
        record["age_ms"] = round(1e3 * (t_sent - frame.t), 3)
        for k in sent:
            self.timings.compute.append(1e3 * (t_sent - frame.t))
            if self.links[k].driver is None:
                self.timings.latency.append(1e3 * (t_sent - frame.t))
        wired = [k for k in sent if self.links[k].driver is not None]
        for k in wired:
            self.links[k].step_ended(t_sent)
        if not wired:  # the frame's age ends with its step (no command went to a PTZ)
            self.timings.age.append(1e3 * (t_sent - frame.t))
        self._collect_writes()
        if self.on_control is not None:
            record.update(self.on_control(record, frame) or {})
        t = t_sent
        if all(command is None for command in commands) and held is not None:
            record["held"] = held
        if self.counts["frames"] % self.cfg.adapt_every == 0:  # dispatched, not waited for
            where = np.nonzero(valid)[0]
            slot_of = {tr.id: int(where[tr.detection]) for tr in tracker.tracks if tr.detection is not None}
            self.keeper.update(x, out.dets, out.trace, self.keeper.trusted(tracker.tracks, slot_of, valid.shape[0]))
        self._record("adapt", t)
        status = self.status()
        status["arrived"] = arrived
        if any(held is not None for held in arrived):
            record["ptz_arrived"] = [held is not None for held in arrived] if len(arrived) > 1 else True
        self.off_path.submit({"record": record, "frame": frame, "dets": c.dets, "z": z,
                              "tracks": [copy.copy(tr) for tr in confirmed], "commands": commands,
                              "status": status})
        elapsed = time.monotonic() - frame.t
        self.timings.frame.append(1e3 * elapsed)
        if self.period and elapsed > self.period:
            self.counts["deadline_overruns"] += 1

    @property
    def captures(self) -> int:
        """Faces captured so far (the selector's or the assignment's)."""
        return self.selector.captures if self.assigner is None else self.assigner.captures

    def status(self) -> dict:
        """A snapshot of the loop's counters for the drawing thread (taken on the control thread): the first
        PTZ's ``sent`` and ``driver``, and ``cameras``: each PTZ's (``sent``, ``driver``, ``held``)."""
        held = [self.selector.held] if self.assigner is None else list(self.assigner.held)
        cameras = [{"sent": link.sent, "driver": link.link_status(), "held": h} for link, h in zip(self.links, held)]
        return {"frames": self.counts["frames"], "elapsed": time.monotonic() - self.t_start,
                "counts": dict(self.counts), "capture": dict(self.capture.counts), "captures": self.captures,
                "driver": cameras[0]["driver"], "held": next((h for h in held if h is not None), None),
                "framable": sorted(self._framable), "sent": self.sent,
                "operator": self.operator.state if self.operator is not None else None,
                "zones_version": self.zones_version, "cameras": cameras}

    def _manual(self, frame: Frame, pointing: tuple[float, float, float], link: PtzLink) -> Command:
        """The operator's manual pointing as this frame's command for ``link``'s PTZ (sent when it changes)."""
        pan, tilt, zoom = pointing
        send = (link.sent != pointing or link.sent_track is not None) and link.ready(frame.stamp, self.rate_wait_s)
        return Command(track=None, pan=pan, tilt=tilt, zoom=zoom, zooms=dict.fromkeys(ZOOM_RULES, zoom), sd_pan=0.0,
                       sd_tilt=0.0, sent=send, t_predicted=frame.stamp)

    def _aim(self, frame: Frame, tracks, c, aim_of: dict[int, int], op: OperatorState | None = None) -> Command | None:
        aims: dict[int, tuple[int, Aim]] = {}
        self._framable = set()

        def framable(track) -> bool:
            if track.id in aims:
                return track.id in self._framable
            j = aim_of.get(track.id)
            if j is None:  # not aimed at in the control step (not matched this frame)
                return False
            aims[track.id] = (j, _entry(c.aims, 0, j))
            if not bool(aims[track.id][1].pointing.valid):
                self.counts["invalid_geometry"] += 1
            ok = can_frame(aims[track.id][1], self.cfg.zoom_rule)
            if ok:
                self._framable.add(track.id)
            return ok

        if op is not None:  # the console shows which tracks the operator can pick
            for tr in tracks:
                framable(tr)
        link = self.links[0]
        target = self.selector.choose(frame.stamp, tracks, link.settled(frame.stamp), framable,
                                      manual=op.target if op is not None else None,
                                      paused=op is not None and op.paused)
        if target is None:
            self.counts["no_target"] += 1
            if self.selector.held is not None:
                self.counts[f"held_{self.selector.held}"] += 1
            return None
        j, aimed = aims[target.id]
        return self._command(frame, c, 0, j, target, aimed)

    def _command(self, frame: Frame, c, k: int, j: int, target, aimed: Aim) -> Command:
        """PTZ ``k``'s command at track ``target`` (its aim ``aimed``, entry ``j`` of the control call's), sent
        unless it is the track the PTZ was sent to last and within the dead zone, or the device's rate limit
        would hold it (:meth:`PtzLink.ready`: the next frame's goes instead)."""
        link, track = self.links[k], target.id
        zooms = {rule: float(aimed.zooms[rule].zoom) for rule in ZOOM_RULES}
        pan, tilt, zoom = float(aimed.pointing.pan), float(aimed.pointing.tilt), zooms[self.cfg.zoom_rule]
        cov = aimed.covariance.cov
        sd_pan, sd_tilt = math.sqrt(cov[0, 0]), math.sqrt(cov[1, 1])
        new_target = track != link.sent_track
        send = new_target or outside_dead_zone((pan, tilt, zoom), link.sent, sd_pan, sd_tilt, self.cfg.dead_zone_sd)
        if not send:
            self.counts["dead_zone"] += 1
        elif not link.ready(frame.stamp, self.rate_wait_s):
            send = False
            self.counts["rate_held"] += 1
        return Command(track=track, pan=pan, tilt=tilt, zoom=zoom, zooms=zooms, sd_pan=sd_pan,
                       sd_tilt=sd_tilt, sent=send, t_predicted=frame.stamp + float(c.lead[k, j]), aimed=aimed,
                       floor_sd=c.floor_sd[k, j], xy=np.array(target.position, float))

    def _assign(self, frame: Frame, tracks, c, aim_of: dict[int, int], op: OperatorState | None,
                pointing: tuple[float, float, float] | None) -> tuple[list[Command | None], str | None]:
        """Several PTZs: each one's command from the exact assignment (:class:`CameraAssigner`); the PTZ the
        operator points by hand gets the pointing. Also why no PTZ has a target, if none has."""
        K, rule = len(self.links), self.cfg.zoom_rule
        manual_k = op.point_camera if pointing is not None else None
        pz, pf, pp = c.aims.pointing.valid, c.aims.zooms[rule].feasible, c.aims.zooms[rule].probability
        self._framable = set()

        def pairs(cands) -> PairValues:
            js = [aim_of.get(tr.id) for tr in cands]
            aimed = np.array([j is not None for j in js])
            idx = np.array([j if j is not None else 0 for j in js], int)
            framable = (pz[:, idx] & pf[:, idx]) & aimed[None, :]
            self.counts["invalid_geometry"] += int((~pz[:, idx] & aimed[None, :]).sum())
            self._framable = {tr.id for tr, ok in zip(cands, framable.any(0)) if ok}
            return PairValues(framable=framable, probability=pp[:, idx], face_px=c.face_px[rule][:, idx],
                              slew_s=c.lead[:, idx])

        targets = self.assigner.choose(frame.stamp, tracks, [link.settled(frame.stamp) for link in self.links],
                                       pairs, manual=op.target if op is not None else None,
                                       paused=op is not None and op.paused,
                                       free=[k != manual_k for k in range(K)], alive=self.tracker.tracks)
        commands: list[Command | None] = []
        for k, target in enumerate(targets):
            last = self._last[k]
            if k == manual_k:
                commands.append(self._manual(frame, pointing, self.links[k]))
            elif target is None:
                commands.append(None)
            elif self.assigner.holding[k]:  # its person's detection missed this frame: the PTZ stays where it is
                commands.append(dataclasses.replace(last, sent=False, t_predicted=frame.stamp)
                                if last is not None and last.track == target.id else None)
            else:
                j = aim_of[target.id]
                commands.append(self._command(frame, c, k, j, target, _entry(c.aims, k, j)))
        self._last = commands
        held = next((h for h in self.assigner.held if h is not None), None)
        if all(command is None for command in commands):
            self.counts["no_target"] += 1
            if held is not None:
                self.counts[f"held_{held}"] += 1
        return commands, held

    def _collect_writes(self) -> None:
        """Frame-to-wire latency and frame age of the targets the drivers have written (superseded ones never
        are: their frames aged until their step ended)."""
        for link in self.links:
            latencies, ages = link.take_writes()
            self.timings.latency.extend(latencies)
            self.timings.age.extend(ages)

    def home(self, wait_s: float = 3.0) -> bool:
        """Send every PTZ home (end of run); whether all reported being there within ``wait_s`` (not waited
        for once :attr:`hurry` is set)."""
        drivers = [link.driver for link in self.links if link.driver is not None]
        for driver in drivers:  # all at once; then wait for each
            driver.set_target(*self.cfg.home)
        reached = all([driver.wait_reached(wait_s, cancel=self.hurry) for driver in drivers])
        self._collect_writes()
        return reached

    # -- reporting ------------------------------------------------------------------------

    @staticmethod
    def _describe(item: dict) -> dict:
        """The log fields of a processed frame (on the drawing thread; everything in it is NumPy): ``ptz``
        the command of a rig's one PTZ, ``ptzs`` each PTZ's of several (``null`` where it has no target)."""
        dets, commands = item["dets"], item["commands"]
        people = [{"r_f": round(float(dets.r_f[k]), 3), "theta_f": round(float(dets.theta_f[k]), 5),
                   "sigma_r_f": round(float(dets.sigma_r_f[k]), 3),
                   "sigma_theta_f": round(float(dets.sigma_theta_f[k]), 5),
                   "contrast": round(float(dets.contrast[k]), 2)} for k in np.nonzero(dets.valid)[0]]
        out = {"detections": people,
               "tracks": [{"id": tr.id, "xy": [round(float(v), 3) for v in tr.position],
                           "v": [round(float(v), 3) for v in tr.x[2:]], "captured": tr.captured}
                          for tr in item["tracks"]]}
        described = [None if command is None else _describe_command(command) for command in commands]
        if len(described) > 1:
            out["ptzs"] = described
        elif described[0] is not None:
            out["ptz"] = described[0]
        return out

    def _status(self, elapsed: float) -> None:
        n = self.counts["frames"]
        lat = self.timings.latency.recent(50)
        ptz, errors = [], ""
        for link in self.links:
            sent = link.sent
            if sent is not None:
                ptz.append(f"{math.degrees(sent[0]):6.1f}/{math.degrees(sent[1]):5.1f} deg x{sent[2]:4.1f}")
            d = link.driver
            if d is not None:
                c = d.counters
                errors += f" err {c['errors']} reconn {c['reconnects']}" + ("" if d.connected else " [PTZ down]")
        ptz = ("PTZ " if len(ptz) == 1 else "PTZs ") + ", ".join(ptz) if ptz else ""
        sys.stderr.write(
            f"\r{n:6d} frames {n / max(elapsed, 1e-9):5.1f} fps | latency "
            f"{np.median(lat) if lat.size else float('nan'):5.2f} ms | tracks {len(self.tracker.confirmed()):2d} | "
            f"{ptz}{errors} | dropped {self.capture.counts['dropped']} stale {self.capture.counts['stale']}   ")
        sys.stderr.flush()

    def summary(self) -> dict:
        """The ``summary.json`` object (docs/design.md section 7.3), without the demo's scores."""
        frames = self.counts["frames"]
        drivers = [link.driver.stats() if link.driver is not None else None for link in self.links]
        ptz = {"commands": self.counts["commands_sent"], "errors": 0, "reconnects": 0}
        if any(drivers):
            ptz = {key: sum(st[key] for st in drivers if st) for key in ("commands", "errors", "reconnects")}
            ptz["commands_requested"] = self.counts["commands_sent"]
            if len(drivers) == 1:
                ptz["driver"] = drivers[0]
        assigned = self.assigner.summary() if self.assigner is not None else [
            {"id": 0, "handoffs": 0, "handed_over": 0, "held": {f"{h}": self.counts[f"held_{h}"] for h in
                                                                ("untrusted", "unframeable", "paused")}}]
        cameras = [{**a, "target_frames": self.target_frames[k], "commands_requested": self.links[k].commands,
                    "driver": drivers[k]} for k, a in enumerate(assigned)]
        return {
            "frames": frames,
            "fps": frames / self.elapsed if getattr(self, "elapsed", 0) else 0.0,
            "seconds": getattr(self, "elapsed", 0.0),
            "stop_reason": self.stop_reason,
            "latency_ms": Timings.stats(self.timings.latency),
            "frame_age_ms": Timings.stats(self.timings.age),
            "compute_latency_ms": Timings.stats(self.timings.compute),
            "frame_ms": Timings.stats(self.timings.frame),
            "stages_ms": {k: Timings.stats(v) for k, v in self.timings.stages.items()},
            "ptz": ptz,
            "faults": {"broken_frames": self.capture.counts["broken"],
                       "wrong_size_frames": self.capture.counts["wrong_size"],
                       "stale_frames": self.capture.counts["stale"], "dropped_frames": self.capture.counts["dropped"],
                       "skipped_at_start": self.capture.counts["skipped_at_start"],
                       "deadline_overruns": self.counts["deadline_overruns"],
                       "source_ended": self.stop_reason == "source ended"},
            "off_path": self.off_path.summary() if self.off_path is not None else None,
            "counts": self.counts,
            "background": self.keeper.summary(),
            "captures": self.captures,
            "cameras": cameras,
            "assignment": None if self.assigner is None else {
                "hysteresis": self.assigner.hysteresis, "face_target_px": self.assigner.face_target_px,
                "doubled_while_waiting": self.assigner.doubled_while_waiting},
            "config": {"zoom_rule": self.cfg.zoom_rule, "tracker": self.cfg.tracker, "target": self.cfg.target,
                       "dwell_s": self.cfg.dwell_s, "dead_zone_sd": self.cfg.dead_zone_sd,
                       "trust": dataclasses.asdict(self.selector.trust),
                       "inputs": list(INPUT_NAMES), "ptz_count": len(self.links)},
        }


def _to_host(tree):
    """``tree``'s arrays as NumPy arrays once computed: on the CPU each a view of its buffer, where
    :func:`jax.device_get` first starts a copy of every leaf (about 0.3 ms a frame for the control
    call's 48)."""
    return jax.tree.map(np.asarray, tree)


def _entry(aims: Aim, k: int, j: int) -> Aim:
    """PTZ ``k``'s aim at the control call's track entry ``j``."""
    return jax.tree.map(lambda a: a[k, j], aims)


def _describe_command(command: Command) -> dict:
    """A command's log fields."""
    return {"track": command.track, "pan_deg": round(math.degrees(command.pan), 3),
            "tilt_deg": round(math.degrees(command.tilt), 3), "zoom": round(command.zoom, 3),
            "zooms": {k: round(v, 3) for k, v in command.zooms.items()},
            "sd_pan_deg": round(math.degrees(command.sd_pan), 4),
            "sd_tilt_deg": round(math.degrees(command.sd_tilt), 4), "sent": command.sent,
            "t_predicted": round(command.t_predicted, 4),
            "floor_sd_m": (None if command.floor_sd is None else [round(float(v), 4) for v in command.floor_sd])}
