"""Perception with a background that lives: one learning rule, the detector, the tracker, and the
decisions of the background's life. What ``omnijax detect``, ``run``, ``demo`` and the perception
sweep (benchmarks/perception_sweep.py) share.

- **Learning** (:func:`learning_step`, :func:`learn_from_frames`): ``[detection] background_frames``
  frames spread over ``background_seconds`` (every ``step``-th frame), robustly averaged around their
  temporal median (:func:`omnijax.learn_background`): a person standing for less than half of the
  window is not learnt. The frames after the window are processed.
- **The background's life** (:class:`BackgroundKeeper`): every processed frame the kernel
  :func:`omnijax.detection.live_step` measures each detection's ghost evidence (an object's edge in
  the current image at the sector's sides, or none) and re-learns the detections this keeper marks:
  a detection whose track has stood still (:data:`STATIC_M` over :data:`STATIC_S`) and shown no
  object edge for ``ghost_s`` is a ghost (someone the background holds who has gone, an object moved
  away, a lamp of another colour) and is re-learnt; an object that stands still with no trusted track
  (a moved chair; :func:`runtime.realtime.targeting.is_trusted`) is absorbed after ``absorb_s``. A
  person who stops keeps an object's edge and is never re-learnt; a person trusted (walked in) is
  never absorbed.
- :class:`Perception` and :func:`detect_frames`: learning, then per frame the detector, the floor
  positions, the tracker and the keeper: ``omnijax detect``'s pipeline. The real-time loop runs the
  same detector and tracker inside its fused control call and the same keeper after it.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field

import jax
import jax.numpy as jnp
import numpy as np

from omnijax import Rig, build_detector, detection_sigmas, learn_background, line_background
from omnijax.detection import BackgroundLife, learned_share, live_step, pixel_polar, start_life
from runtime.errors import UsageError
from runtime.realtime.control import perceive
from runtime.realtime.targeting import TrustRule, is_trusted
from runtime.realtime.tracker import Track, Tracker

#: A track stands still when its filtered position stayed within STATIC_M (m) of where it is now over
#: the last STATIC_S (s).
STATIC_M, STATIC_S = 0.2, 0.3
#: Frames per second assumed for a source that does not say (an image folder).
DEFAULT_FPS = 25.0


def learning_step(fps: float | None, samples: int, seconds: float) -> int:
    """Every how many frames a learning frame is taken: ``samples`` frames over ``seconds`` at ``fps``."""
    return max(1, int(round(seconds * (fps or DEFAULT_FPS) / samples)))


def learn_from_frames(frames_iter: Iterable, n: int, step: int, what: str):
    """The background from ``n`` readable frames of ``frames_iter``, every ``step``-th (broken ones,
    ``None``, skipped). Returns it, the indices of the frames it was learnt from and the number of
    frames read."""
    got, used, read = [], [], 0
    for img in frames_iter:
        read += 1
        if img is not None and (read - 1) % step == 0:
            got.append(img)
            used.append(read - 1)
        if len(got) == n:
            break
    if len(got) < n:
        raise UsageError(f"{what}: only {len(got)} readable frames, expected at least {n} to learn the background "
                         f"(--background-frames, every {step}th frame)")
    first = np.asarray(got[0])
    if any(np.shape(g) != first.shape for g in got):
        raise UsageError(f"{what}: the frames change size while the background is learnt")
    return learn_background(np.stack(got)), used, read


@dataclass
class LifeCounts:
    """What the keeper did: detections re-learnt as ghosts, objects absorbed, frames decided."""

    ghosts: int = 0
    absorbed: int = 0
    frames: int = 0
    ghost_times: list = field(default_factory=list)  # (t, x, y) of each ghost repair

    def as_dict(self) -> dict:
        return {"ghost_repairs": self.ghosts, "absorbed": self.absorbed, "frames": self.frames}


class BackgroundKeeper:
    """The background's life on the host: holds the :class:`~omnijax.detection.BackgroundLife` and its
    polar lines, decides which detections are re-learnt (see the module docstring) and dispatches
    :func:`~omnijax.detection.live_step`. ``update`` is called once per processed frame, after the
    tracker's bookkeeping; its kernel runs while the caller waits for the next frame."""

    def __init__(self, rig: Rig, detector, bg, trust: TrustRule, fps: float | None, every: int = 1):
        self.rig, self.detector, self.trust = rig, detector, trust
        self.life: BackgroundLife = start_life(bg)
        self.lines = line_background(detector, bg)
        self.pixels = pixel_polar(rig.omni)
        d = rig.detection
        dt = every / (fps or DEFAULT_FPS)
        self.recent_rate = 1.0 - math.exp(-dt / d.recent_s)
        self.adapt_rate = float(d.adapt_rate) * every
        self.ghost_s, self.edge, self.absorb_s = d.ghost_s, d.ghost_edge, d.absorb_s
        self.counts = LifeCounts()
        self._pending: tuple | None = None  # (evidence (K,), {slot: track id}) of the last update
        self.learned_share = float(learned_share(detector, bg))

    @property
    def bg(self):
        return self.life.bg

    def warm_up(self, blank, dets) -> None:
        """Compile the life's kernel on a blank frame before anything is timed."""
        out = live_step(self.detector, self.life, blank, self.lines, dets, np.zeros(dets.valid.shape, bool),
                        self.pixels, self.recent_rate, self.adapt_rate)
        jax.block_until_ready(out)

    def update(self, image, dets, slot_of: dict[int, int], t: float, tracks: list[Track]) -> np.ndarray:
        """Decide and dispatch one frame of the background's life. ``dets`` are the frame's detections
        (device arrays, K slots), ``slot_of`` maps a track id to the slot of the detection it took this
        frame, ``tracks`` all tracks after the bookkeeping. Returns the slots re-learnt."""
        self._take_evidence(t, tracks)
        K = dets.valid.shape[0]
        repair = np.zeros(K, bool)
        for tr in tracks:
            k = slot_of.get(tr.id)
            if k is None:
                continue
            static_for = self._static_for(tr, t)
            ghost_for = t - tr.extra["ghost_since"] if tr.extra.get("ghost_since") is not None else -1.0
            trusted = is_trusted(tr, self.trust)
            if static_for >= STATIC_S and ghost_for >= self.ghost_s:
                repair[k] = True
                self.counts.ghosts += 1
                self.counts.ghost_times.append((t, *map(float, tr.position)))
                tr.extra["ghost_since"] = None
            elif static_for >= self.absorb_s and not trusted:
                repair[k] = True
                self.counts.absorbed += 1
        self.counts.frames += 1
        self.life, lines, evidence = live_step(self.detector, self.life, image, self.lines, dets, repair,
                                               self.pixels, self.recent_rate, self.adapt_rate)
        self.lines = lines
        self._pending = (evidence, {k: tid for tid, k in slot_of.items()}, t)
        return repair

    def _take_evidence(self, t: float, tracks: list[Track]) -> None:
        """The ghost evidence of the last update's detections, onto the tracks that took them."""
        if self._pending is None:
            return
        evidence, track_of, t_ev = self._pending
        self._pending = None
        ev = np.asarray(evidence)
        by_id = {tr.id: tr for tr in tracks}
        for k, tid in track_of.items():
            tr = by_id.get(tid)
            if tr is None:
                continue
            if ev[k] < self.edge:
                if tr.extra.get("ghost_since") is None:
                    tr.extra["ghost_since"] = t_ev
            else:
                tr.extra["ghost_since"] = None

    @staticmethod
    def _static_for(tr: Track, t: float) -> float:
        """Seconds ``tr`` has stood still (0 while it moves), from its recent positions."""
        hist = tr.extra.setdefault("history", deque())
        hist.append((t, float(tr.position[0]), float(tr.position[1])))
        while len(hist) > 2 and t - hist[1][0] >= STATIC_S:
            hist.popleft()
        ts, xy = hist[0][0], np.array([[h[1], h[2]] for h in hist])
        still = t - ts >= STATIC_S and np.max(np.hypot(*(xy - xy[-1]).T)) <= STATIC_M
        if not still:
            tr.extra["still_since"] = None
            return 0.0
        if tr.extra.get("still_since") is None:
            tr.extra["still_since"] = ts
        return t - tr.extra["still_since"]


@dataclass
class FrameResult:
    """One processed frame of :func:`detect_frames`: its index, time, the image, the detections
    (NumPy, K slots), their floor points and the ``people`` lines ``omnijax detect`` writes, the tracks."""

    index: int
    t: float
    image: np.ndarray
    dets: object
    z: np.ndarray
    people: list[dict]
    tracks: list[Track]


class Perception:
    """Learning done, per frame: detector, floor positions, tracker, background's life (see the module
    docstring). The tracker has the real-time loop's defaults."""

    def __init__(self, rig: Rig, bg, fps: float | None, trust: TrustRule | None = None, detector=None):
        self.rig = rig
        self.detector = build_detector(rig) if detector is None else detector
        self.tracker = Tracker()
        self.keeper = BackgroundKeeper(rig, self.detector, bg, trust or TrustRule(), fps)

    def step(self, image: np.ndarray, t: float):
        x = jnp.asarray(image)
        dets, _, z, R = jax.device_get(perceive(self.detector, self.rig, x, self.keeper.bg, self.keeper.lines))
        valid = np.nonzero(np.asarray(dets.valid))[0]
        tracks = self.tracker.step(t, np.asarray(z)[valid], np.asarray(R)[valid])
        slot_of = {tr.id: int(valid[tr.detection]) for tr in tracks if tr.detection is not None}
        self.keeper.update(x, dets, slot_of, t, tracks)
        return dets, np.asarray(z)[valid], valid, tracks


def people_lines(rig: Rig, dets, valid: np.ndarray) -> list[dict]:
    """The per-person objects of ``detections.jsonl`` (r_f, theta_f, the sigma rule's sigmas and the
    detector's own, contrast, sector edges, radial extent)."""
    s_r, s_t = (np.asarray(a) for a in detection_sigmas(rig, dets.sigma_r_f, dets.sigma_theta_f))
    return [{"r_f": float(dets.r_f[k]), "theta_f": float(dets.theta_f[k]), "sigma_r_f": float(s_r[k]),
             "sigma_theta_f": float(s_t[k]), "detector_sigma_r_f": float(dets.sigma_r_f[k]),
             "detector_sigma_theta_f": float(dets.sigma_theta_f[k]), "contrast": float(dets.contrast[k]),
             "theta_l": float(dets.theta_l[k]), "theta_r": float(dets.theta_r[k]),
             "r_in": float(dets.r_in[k]), "r_out": float(dets.r_out[k])} for k in valid]


class DetectRun:
    """:func:`detect_frames`'s result: iterate for the :class:`FrameResult` of each processed frame;
    ``learning_frames``, ``learned_share`` and ``perception`` (with the keeper's counts) once started."""

    def __init__(self, rig: Rig, frames: Iterable, fps: float | None, samples: int | None, seconds: float | None,
                 what: str, detector=None):
        d = rig.detection
        self.samples = samples or d.background_frames
        self.step_frames = learning_step(fps, self.samples, d.background_seconds if seconds is None else seconds)
        self.fps = fps or DEFAULT_FPS
        self._frames = iter(frames)
        bg, self.learning_frames, self.read = learn_from_frames(self._frames, self.samples, self.step_frames, what)
        self.perception = Perception(rig, bg, fps, detector=detector)
        self.learned_share = self.perception.keeper.learned_share

    def __iter__(self) -> Iterator[FrameResult]:
        index = self.read
        for image in self._frames:
            t = index / self.fps
            dets, z, valid, tracks = self.perception.step(image, t)
            yield FrameResult(index=index, t=t, image=image, dets=dets, z=z,
                              people=people_lines(self.perception.rig, dets, valid), tracks=tracks)
            index += 1


def detect_frames(rig: Rig, frames: Iterable, fps: float | None = None, samples: int | None = None,
                  seconds: float | None = None, what: str = "source", detector=None) -> DetectRun:
    """``omnijax detect``'s pipeline on ``frames`` (RGB uint8 arrays): learning by the one rule, then the
    processed frames (see :class:`DetectRun`). ``samples`` and ``seconds`` override the rig's
    ``background_frames`` and ``background_seconds``."""
    return DetectRun(rig, frames, fps, samples, seconds, what, detector)
