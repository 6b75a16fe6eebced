"""One run of the real-time loop with its outputs: what ``omnijax run`` and ``omnijax demo`` share.

:func:`run_session` learns the background from the source's first frames, builds the detector,
starts the capture thread, runs :class:`~runtime.loop.RealTimeLoop` until the source ends, a limit
is reached or Ctrl-C/SIGTERM arrives, sends the PTZ home, and writes into the output folder
(staged: nothing half-written) ``summary.json``, ``log.jsonl``, ``events.jsonl`` (with ``faces/``) and
``annotated.mp4`` (or ``.avi`` where OpenCV has no MP4 encoder). :class:`Annotator` draws the operator's
view (the paper's figure 1) for each processed frame; with a console (``--serve``) the view is drawn
whatever ``video`` says, and the console's snapshot is taken after it on the drawing thread.
"""

from __future__ import annotations

import gc
import json
import math
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import jax
import numpy as np

from omnijax import Rig, build_detector
from omnijax.detection import polar_range
from runtime.errors import Interrupted, UsageError, interrupted_during
from runtime.events import EventLog
from runtime.frames import Source
from runtime.output import dumps, staged_output
from runtime.realtime.config import LoopConfig
from runtime.realtime.loop import RealTimeLoop
from runtime.realtime.overlay import (
    GREEN,
    GREY,
    ORANGE,
    RED,
    WHITE,
    YELLOW,
    compose_view,
    draw_detections,
    draw_tracks,
    track_pixels,
)
from runtime.realtime.perception import learn_from_frames, learning_step
from runtime.realtime.ptz_link import PtzLink
from runtime.realtime.sources import Capture


class VideoOut:
    """An OpenCV video writer: ``stem``.mp4 (mp4v) where the build can, else Motion-JPEG ``stem``.avi
    (``replay``: only the AVI, each frame a JPEG of quality 95, for re-reading with ``omnijax run``)."""

    def __init__(self, folder: Path, fps: float, size: tuple[int, int], stem: str = "annotated",
                 replay: bool = False):
        self.writer = None
        options = [(f"{stem}.avi", "MJPG")] if replay else [(f"{stem}.mp4", "mp4v"), (f"{stem}.avi", "MJPG")]
        for name, codec in options:
            w = cv2.VideoWriter(str(folder / name), cv2.VideoWriter_fourcc(*codec), fps, size)
            if w.isOpened():
                if replay:
                    w.set(cv2.VIDEOWRITER_PROP_QUALITY, 95)
                self.writer, self.name = w, name
                break
            (folder / name).unlink(missing_ok=True)
        if self.writer is None:
            raise RuntimeError("OpenCV can write neither MP4 nor Motion-JPEG AVI video here")
        self.frames = 0

    def write(self, rgb: np.ndarray) -> None:
        self.writer.write(cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR))
        self.frames += 1

    def close(self) -> None:
        self.writer.release()


@dataclass
class Annotator:
    """Draws the operator's view of each processed frame and hands it to ``sinks``.

    ``fovea``: per PTZ (the rig's order), ``foveal(frame, loop) -> (image | None, label)`` supplies its
    inset (the demo renders it from the synthetic world at the emulated PTZ's actual position), or
    ``None``: the commanded PTZ state only.
    """

    rig: Rig
    title: str
    fovea: list = field(default_factory=list)
    sinks: list = field(default_factory=list)
    loop: RealTimeLoop | None = None
    last: np.ndarray | None = None
    #: the latest frame's annotated omni image and each PTZ's inset (with its label), apart (the console shows them)
    omni_view: np.ndarray | None = None
    insets: list[tuple[np.ndarray | None, str]] = field(default_factory=list)

    def __post_init__(self):
        self.r_range = polar_range(self.rig)
        self.fovea = list(self.fovea) + [None] * (self.rig.ptz_count - len(self.fovea))
        self.insets = [(None, _ptz_name(k, self.rig.ptz_count)) for k in range(self.rig.ptz_count)]

    @property
    def inset(self) -> tuple[np.ndarray | None, str]:
        """The first PTZ's inset and label."""
        return self.insets[0]

    def warm_up(self, blank: np.ndarray, dets) -> None:
        """Compile the drawing's jitted parts (and the insets') before the loop starts."""
        draw_detections(blank, self.rig, dets, self.r_range)
        track_pixels(self.rig, np.array([1.0, 0.5, 0.1, 0.0]), 0.01 * np.eye(4))
        for foveal in self.fovea:
            if hasattr(foveal, "warm_up"):
                foveal.warm_up()

    def __call__(self, record, frame, dets, z, tracks, commands, status) -> dict:
        """Draw the view of a processed frame (on the loop's drawing thread): ``tracks`` are the tracks
        confirmed then, ``commands`` each PTZ's, ``status`` the loop's counters then
        (:meth:`RealTimeLoop.status`)."""
        loop, K = self.loop, len(commands)
        img = draw_detections(frame.image, self.rig, dets, self.r_range)
        targets: dict[int, str] = {}
        for k, command in enumerate(commands):
            if command is not None and command.track is not None:
                targets[command.track] = "TARGET" if K == 1 else f"{targets.get(command.track, 'PTZ')} {k}"
        draw_tracks(img, self.rig, tracks, targets)
        self.insets = [foveal(frame, loop) if foveal is not None else (None, _ptz_name(k, K))
                       for k, foveal in enumerate(self.fovea)]
        n, elapsed = status["frames"], max(status["elapsed"], 1e-9)
        lat = loop.timings.latency.recent(50) if len(loop.timings.latency) else loop.timings.compute.recent(50)
        lines = [(f"{n / elapsed:5.1f} fps   latency {np.median(lat) if lat.size else float('nan'):5.2f} ms", WHITE),
                 (f"tracks {len(tracks)}   faces captured {status['captures']}", WHITE)]
        for k, (command, camera) in enumerate(zip(commands, status["cameras"])):
            lines.extend(_command_lines(command, loop.cfg.zoom_rule, float(self.rig.p_contain)) if K == 1
                         else [_camera_line(k, command)])
            c = camera["driver"]
            if c is not None:
                up = c["connected"]
                lines.append((f"{_ptz_name(k, K)} {'online' if up else 'OFFLINE'}  cmds {c['commands']}  "
                              f"err {c['errors']}  reconn {c['reconnects']}", GREEN if up else RED))
        counts = status["counts"]
        faults = counts["broken"] + counts["wrong_size"]
        lines.append((f"faults: broken {counts['broken']}  size {counts['wrong_size']}  "
                      f"stale {status['capture']['stale']}", RED if faults else GREY))
        clock = f"frame {frame.index:6d}   t {frame.stamp:8.2f} s"
        self.omni_view = img
        self.last = compose_view(img, self.insets, self.title, clock, lines)
        for sink in self.sinks:
            sink(self.last)
        return {}


def _ptz_name(k: int, count: int) -> str:
    return "PTZ" if count == 1 else f"PTZ {k}"


def _command_lines(command, zoom_rule: str, p_contain: float) -> list[tuple[str, tuple[int, int, int]]]:
    """The status panel's lines of a rig's one PTZ."""
    if command is None:
        return [("no target", GREY)]
    who = "manual" if command.track is None else f"target #{command.track}"
    return [(f"{who}  pan {math.degrees(command.pan):6.1f}  tilt {math.degrees(command.tilt):5.1f}", ORANGE),
            (f"zoom x{command.zoom:4.1f} ({zoom_rule}, p={p_contain:.2f})", ORANGE),
            (f"sd pan {math.degrees(command.sd_pan):.2f}  tilt {math.degrees(command.sd_tilt):.2f} deg", YELLOW)]


def _camera_line(k: int, command) -> tuple[str, tuple[int, int, int]]:
    """One status line of PTZ ``k`` of several."""
    if command is None:
        return (f"PTZ {k}: no target", GREY)
    who = "manual" if command.track is None else f"#{command.track}"
    return (f"PTZ {k}: {who}  pan {math.degrees(command.pan):6.1f}  tilt {math.degrees(command.tilt):5.1f}  "
            f"x{command.zoom:4.1f}", ORANGE)


def chain_hooks(*hooks) -> Callable:
    """One ``on_frame`` hook calling each of ``hooks`` in turn and merging their log fields."""
    def on_frame(*args):
        out = {}
        for h in hooks:
            if h is not None:
                out.update(h(*args) or {})
        return out
    return on_frame


def run_session(rig: Rig, source: Source, out: Path, *, links: list[PtzLink], config: LoopConfig,
                paced: bool = True, background_frames: int | None = None, background_seconds: float | None = None,
                video: bool = True, record: bool = False,
                title: str = "omnijax", fovea: tuple = (), hooks: tuple = (), control_hooks: tuple = (),
                finish: Callable | None = None, extra: dict | None = None, screenshot_at: int | None = None,
                console=None, mqtt=None) -> dict:
    """Run the loop on ``source`` and write the outputs to ``out`` (see the module docstring).

    ``links``: one :class:`~runtime.realtime.ptz_link.PtzLink` per PTZ of ``rig`` (its driver, or none, and
    its device profile); ``fovea``: per PTZ, its view for the operator's view (:class:`Annotator`).

    ``hooks`` are extra ``on_frame`` hooks (the demo's scorer), run on the drawing thread;
    ``control_hooks`` run on the control thread at their frame (fault injection); ``record`` writes
    the processed omni frames as they came (``omni.avi``, to replay with ``omnijax run``); ``finish(summary)``
    may add to the summary before it is written; ``screenshot_at`` saves that processed frame's
    view as ``view.png``; ``console`` (:class:`~runtime.console.Console`) is attached to the loop once it is
    built, ``mqtt`` (:class:`~runtime.events.MqttPublisher`) gets the events. Returns the summary.
    """
    # the PTZ driver's and the capture's threads get the interpreter within 1 ms (default 5 ms) of a wake-up
    sys.setswitchinterval(0.001)
    n_bg = background_frames or rig.detection.background_frames
    t0 = time.monotonic()
    with staged_output(out) as stage, interrupted_during("while writing the outputs"):
        with interrupted_during("during start-up"):
            loop, annot, writer, recorder, first = _start(
                rig, source, stage, links=links, config=config, paced=paced, n_bg=n_bg,
                background_seconds=background_seconds, video=video, record=record, title=title, fovea=fovea,
                hooks=hooks, control_hooks=control_hooks, screenshot_at=screenshot_at, console=console, mqtt=mqtt)
        setup_s = time.monotonic() - t0
        loop.install_signal_handlers()  # until the outputs are staged: a second signal hurries, never discards
        # what start-up built (JAX, the compiled programs, the world) lives as long as the run: out of the
        # collector's sight, a full collection scans only what the loop makes (it scanned all of it, 0.1-0.35 s
        # with every thread held, collecting nothing: the frames dropped mid-run, docs/runtime.md)
        gc.collect()
        gc.freeze()
        watch = CollectorWatch()
        gc.callbacks.append(watch)
        try:
            summary = _finish(loop, stage, writer, recorder, source, setup_s, n_bg, first, console,
                              mqtt, extra, finish, watch)
        finally:
            gc.callbacks.remove(watch)
            gc.unfreeze()
            loop.restore_signal_handlers()
    if loop.hurried_by is not None:  # the outputs are in place; say that they were cut short
        exc = Interrupted(loop.hurried_by)
        exc.during, exc.kept = "while writing the outputs", str(out)
        raise exc
    return summary


class CollectorWatch:
    """Python's garbage collections while the loop runs (a ``gc.callbacks`` entry): per generation, how
    many and the longest (ms); with what start-up left frozen out of their sight (``gc.freeze``). A full
    collection holds every thread; before the freeze they scanned all that start-up built and grew to
    0.35 s mid-run (docs/runtime.md). ``summary()`` is summary.json's ``gc``."""

    def __init__(self):
        self.frozen = gc.get_freeze_count()
        self.count, self.max_ms, self._t0 = [0, 0, 0], [0.0, 0.0, 0.0], 0.0

    def __call__(self, phase: str, info: dict) -> None:
        if phase == "start":
            self._t0 = time.perf_counter()
            return
        g = info["generation"]
        self.count[g] += 1
        self.max_ms[g] = max(self.max_ms[g], 1e3 * (time.perf_counter() - self._t0))

    def summary(self) -> dict:
        return {"frozen_objects": self.frozen, "collections": list(self.count),
                "max_ms": [round(v, 3) for v in self.max_ms]}


def _finish(loop: RealTimeLoop, stage: Path, writer, recorder, source: Source, setup_s: float, n_bg: int, first: int,
            console, mqtt, extra: dict | None, finish: Callable | None, watch: CollectorWatch) -> dict:
    """Run the loop until it stops, send the PTZ home, close the writers and write ``summary.json`` into
    ``stage``; returns the summary. A second Ctrl-C or SIGTERM meanwhile (:attr:`RealTimeLoop.hurry`) cuts the
    drawing and the wait for the PTZ short; what was recorded is written all the same."""
    try:
        with loop.capture:
            loop.run()
    finally:
        homed = loop.home()
        for w in (writer, recorder):
            if w is not None:
                w.close()
        loop.events.close()
    summary = loop.summary()
    summary["events"] = loop.events.summary()
    if mqtt is not None:
        summary["events"]["mqtt"] = mqtt.summary()
    if console is not None:
        summary["console"] = {"url": console.url, "operator": loop.counts["operator_frames"]}
    view = stage / "view.png"
    summary.update({"source": source.name, "setup_s": setup_s, "background_frames": n_bg,
                    "learning": loop.learning, "first_frame": first, "ptz_homed": homed,
                    "finish_cut_short": loop.hurried_by,
                    "outputs": {"log": "log.jsonl", "events": "events.jsonl",
                                **({"video": writer.name} if writer else {}),
                                **({"record": recorder.name} if recorder else {}),
                                **({"view": view.name} if view.is_file() else {})}})
    video_counters = _source_counters(source)  # a network stream: reconnects, drops, outage
    if video_counters is not None:
        summary["stream"] = video_counters
    summary["gc"] = watch.summary()
    summary.update(extra or {})
    if finish is not None:
        finish(summary)
    (stage / "summary.json").write_text(dumps(summary) + "\n")
    return summary


def home_warning(summary: dict) -> str | None:
    """The last line a command prints when the PTZ did not report its home position at the end (``ptz_homed``
    false in ``summary.json``), ``None`` when it did (or there was no PTZ)."""
    if summary.get("ptz_homed", True):
        return None
    return ("warning: the PTZ did not report its home position at the end (summary.json ptz_homed: false); "
            "it may still point where the run left it")


def _source_counters(source) -> dict | None:
    """A network source's ``counters`` (reconnects, drops, ...), through any wrapper."""
    while source is not None:
        if isinstance(getattr(source, "counters", None), dict):
            return dict(source.counters)
        source = getattr(source, "source", None)
    return None


def _start(rig: Rig, source: Source, stage: Path, *, links: list[PtzLink], config: LoopConfig, paced: bool, n_bg: int,
           background_seconds: float | None, video: bool, record: bool, title: str, fovea: tuple, hooks: tuple,
           control_hooks: tuple, screenshot_at: int | None, console=None, mqtt=None):
    """Start-up of :func:`run_session`: the background, the detector, the writers, the loop, compiled.

    A live source's capture starts first and drains the source throughout (the background is learnt from
    it), so that the loop starts on the newest frame, not on what piled up while it compiled."""
    W, H = rig.omni.image_size
    capture = Capture(source, paced=paced, shape=(H, W, 3)).start() if source.live else None
    try:
        return _start_on(capture, rig, source, stage, links=links, config=config, paced=paced,
                         n_bg=n_bg, background_seconds=background_seconds, video=video, record=record, title=title,
                         fovea=fovea, hooks=hooks, control_hooks=control_hooks, screenshot_at=screenshot_at,
                         console=console, mqtt=mqtt)
    except BaseException:
        if capture is not None:
            capture.stop()
        raise


def _start_on(capture: Capture | None, rig: Rig, source: Source, stage: Path, *, links: list[PtzLink],
              config: LoopConfig, paced: bool, n_bg: int, background_seconds: float | None, video: bool, record: bool,
              title: str, fovea: tuple, hooks: tuple, control_hooks: tuple, screenshot_at: int | None, console=None,
              mqtt=None):
    W, H = rig.omni.image_size
    frames = source.stamped() if capture is None else None
    seconds = rig.detection.background_seconds if background_seconds is None else background_seconds
    step = learning_step(source.fps, n_bg, seconds)
    images = capture.images() if capture is not None else (img for img, _ in frames)
    bg, used, first = learn_from_frames(images, n_bg, step, source.name)
    if bg.mean.shape[:2] != (H, W):
        raise UsageError(f"{source.name}: frames are {bg.mean.shape[1]}x{bg.mean.shape[0]}, "
                         f"expected {W}x{H} (omni.image_size of the rig)")
    detector = build_detector(rig)
    writer = VideoOut(stage, source.fps or 25.0, (W + W // 2, H)) if video else None
    annot = Annotator(rig, title, list(fovea), [writer.write] if writer else [])
    if capture is None:
        capture = Capture(source, paced=paced, frames=frames, first_index=first, shape=(H, W, 3))
    drawn = video or screenshot_at is not None or console is not None
    loop = RealTimeLoop(rig, detector, bg, capture, links, config, stage / "log.jsonl",
                        on_frame=chain_hooks(*hooks, annot if drawn else None),
                        on_control=chain_hooks(*control_hooks) if control_hooks else None,
                        operator=console.operator if console is not None else None, learning_frames=n_bg)
    annot.loop = loop
    loop.learning = {"frames": n_bg, "seconds": seconds, "step": step, "frame_indices": used}
    live = console.attach(loop, rig, annot, stage, links[0].driver, links[0].profile) if console is not None else None
    sinks = tuple(s for s in (live.event if live is not None else None, mqtt) if s is not None)
    # a face is saved from the PTZ that dwelt on the person (the first one's where the track does not say)
    loop.events = EventLog(stage, face_image=lambda tr: annot.insets[tr.extra.get("captured_by", 0)][0],
                           sinks=sinks)
    if console is not None:
        console.events = loop.events

    def shoot(record, frame, dets, z, tracks, commands, status):
        if screenshot_at is not None and status["frames"] == screenshot_at and annot.last is not None:
            cv2.imwrite(str(stage / "view.png"), cv2.cvtColor(annot.last, cv2.COLOR_RGB2BGR))
        return {}

    recorder = VideoOut(stage, source.fps or 25.0, (W, H), "omni", replay=True) if record else None

    def rec(record_, frame, *_):
        if recorder is not None:
            recorder.write(frame.image)
        return {}

    loop.on_frame = chain_hooks(loop.on_frame, loop.events, live, shoot, rec)
    blank_dets = jax.device_get(loop.warm_up())
    if drawn:
        annot.warm_up(np.zeros((H, W, 3), np.uint8), blank_dets)
    for hook in hooks:  # what runs on the drawing thread compiles now, not mid-run (the demo's scorer)
        if hasattr(hook, "warm_up"):
            hook.warm_up()
    return loop, annot, writer, recorder, first


def read_state(path: Path) -> dict | None:
    """The emulator's ``--state-file`` object, or ``None`` while it is being replaced or absent."""
    try:
        return json.loads(Path(path).read_text())
    except (OSError, ValueError):
        return None

