"""Perception with a background that lives: one learning rule, the detector, the tracker and the
background's life, as ``omnijax detect``, ``run``, ``demo`` and the perception sweep
(benchmarks/perception_sweep.py) all use them.

- **Learning** (:func:`learning_step`, :func:`learn_from_frames`): ``[detection] background_frames``
  frames spread over ``background_seconds`` (every ``step``-th frame), robustly averaged around their
  median colour (:func:`omnijax.learn_background`): a person standing through less than half of
  the window is not learnt, and what the window could not settle is learnt later, as it is seen
  free (:mod:`omnijax.detection._life`). Someone who stood through more than half of it is learnt,
  then settled from the learning's minority when the keeper starts
  (:func:`omnijax.detection.settle_learning`: the floor they hid continues the floor around it). The
  frames after the window are processed.
- **The background's life** (:class:`BackgroundKeeper`): after each frame's detection, the kernel
  :func:`omnijax.detection.live_step` repairs ghosts (detections with no object edge in the current
  image), absorbs what stays changed and still for ``absorb_s`` outside every trusted person, lets
  the rest drift. The tracker feeds it: a detection whose track is trusted (a person who walked in,
  :func:`runtime.realtime.targeting.is_trusted`) is a ghost only on both signs of one (no edge now,
  an edge in the background), and its region is never absorbed, so a person who stops stays.
- :class:`Perception` and :func:`detect_frames`: learning, then per frame the detector, the floor
  positions, the tracker and the keeper: ``omnijax detect``'s pipeline. The real-time loop runs the
  same detector and tracker inside its fused control call and the same keeper after it.
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator
from dataclasses import dataclass

import jax
import jax.numpy as jnp
import numpy as np

from omnijax import Rig, build_detector, detection_sigmas, learn_background, line_background
from omnijax.detection import LifeRates, learned_share, live_step, settle_learning, start_life
from runtime.errors import UsageError
from runtime.realtime.control import perceive
from runtime.realtime.targeting import GhostSites, TrustRule, is_trusted
from runtime.realtime.tracker import Track, Tracker

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
                         f"(--background-frames {n}, one every {step} frames: --background-seconds spreads "
                         f"them; lower it for a short clip, 0 takes consecutive frames)")
    first = np.asarray(got[0])
    if any(np.shape(g) != first.shape for g in got):
        raise UsageError(f"{what}: the frames change size while the background is learnt")
    return learn_background(np.stack(got)), used, read


def life_rates(rig: Rig, fps: float | None, learning_frames: int, every: int = 1) -> LifeRates:
    """The rig's ``[detection]`` time constants as frames of a source at ``fps`` whose life is stepped
    every ``every``-th frame."""
    d = rig.detection
    per_s = (fps or DEFAULT_FPS) / every
    f = lambda s: jnp.asarray(max(1.0, s * per_s))
    return LifeRates(adapt_rate=jnp.asarray(float(d.adapt_rate) * every), edge=jnp.asarray(float(d.ghost_edge)),
                     still_frames=f(d.still_s), ghost_frames=f(d.ghost_s), absorb_frames=f(d.absorb_s),
                     learn_frames=jnp.asarray(float(learning_frames)), floor_shows_frames=f(d.floor_shows_s))


@dataclass
class LifeCounts:
    """What the keeper did: frames stepped, detections judged ghosts (summed over frames), the trusted
    ones among them."""

    frames: int = 0
    ghost_detections: int = 0
    trusted_ghosts: int = 0

    def as_dict(self) -> dict:
        return {"frames": self.frames, "ghost_detections": self.ghost_detections,
                "trusted_ghosts": self.trusted_ghosts}


#: A track whose detection has shown a person's edge (the life's person verdict,
#: :func:`omnijax.detection.verdicts`) in this many seconds of frames is a person to the background's
#: life, trusted by the tracker or not: someone standing since before the tracker started was never
#: seen walking in, and a passer-by in front of them hides the sides the ghost evidence reads
#: (stops_a_minute 9064: two frames of a ghost's verdict re-learnt a stander seen for 12 s, for good).
#: A ghost shows no person's edge; a ghost merged with its person walking off it shows one for the
#: second or so they take to part.
PERSON_SEEN_S = 2.0


class BackgroundKeeper:
    """The background's life on the host: holds the :class:`~omnijax.detection.Life`, says which
    detections are trusted people (from the tracker) and dispatches
    :func:`~omnijax.detection.live_step`. :meth:`update` is called once per processed frame, after the
    tracker's bookkeeping; its kernel runs while the caller waits for the next frame, and the counts
    of a frame are read at the next update (no wait)."""

    def __init__(self, rig: Rig, detector, bg, trust: TrustRule, fps: float | None, learning_frames: int,
                 every: int = 1):
        self.rig, self.detector, self.trust = rig, detector, trust
        lines = line_background(detector, bg)
        #: share of the floor's samples whose learnt colour was someone who stood there, settled to the
        #: learning's minority (:func:`omnijax.detection.settle_learning`)
        self.settled_share = 0.0
        if bg.minority is not None:
            lines, took = settle_learning(detector, lines, bg, jnp.asarray(float(rig.detection.ghost_edge)),
                                          jnp.asarray(float(learning_frames)))
            self.settled_share = float(jnp.sum(took) / jnp.maximum(jnp.sum(detector.polar.line_ok), 1))
        self.life = start_life(lines)
        self.rates = life_rates(rig, fps, learning_frames, every)
        self.learning_frames = learning_frames
        self.counts = LifeCounts()
        self.learned_at_start = float(learned_share(detector, self.life, float(learning_frames)))
        self._pending = None
        #: frames in which each track's detection showed a person's edge (track id -> frames)
        self.person_frames: dict[int, int] = {}
        self.person_needed = max(1.0, PERSON_SEEN_S * (fps or DEFAULT_FPS) / every)
        self._slots: dict[int, int] = {}

    @property
    def lines(self):
        return self.life.lines

    def warm_up(self, blank, dets, trace) -> None:
        """Compile the life's kernel on a blank frame (its detections and their trace) before anything is timed."""
        out = live_step(self.detector, self.life, blank, dets, trace.d2, np.zeros(dets.valid.shape, bool), self.rates,
                        trace)
        jax.block_until_ready(out)

    def trusted(self, tracks: list[Track], slot_of: dict[int, int], K: int) -> np.ndarray:
        """Which of the ``K`` detection slots a track the life takes for a person took (``slot_of``: track
        id -> slot): trusted (:func:`~runtime.realtime.targeting.is_trusted`), or seen with a person's edge
        in :data:`PERSON_SEEN_S` of frames."""
        out = np.zeros(K, bool)
        self._slots = {}
        alive = {tr.id for tr in tracks}  # the tracker never reuses an id: the counts of gone tracks go
        self.person_frames = {t: n for t, n in self.person_frames.items() if t in alive}
        for tr in tracks:
            k = slot_of.get(tr.id)
            if k is None:
                continue
            self._slots[k] = tr.id
            if is_trusted(tr, self.trust) or self.person_frames.get(tr.id, 0) >= self.person_needed:
                out[k] = True
        return out

    def update(self, image, dets, trace, trusted: np.ndarray) -> None:
        """Dispatch one frame of the life for the frame ``image`` whose detections ``dets`` (device
        arrays) were found against :attr:`lines` with ``trace`` (:class:`~omnijax.detection.DetectionTrace`:
        their change, the frame at the polar samples, their ghost evidence if judged already);
        ``trusted`` per slot."""
        self._collect()
        self.life, _, ghostly, person = live_step(self.detector, self.life, image, dets, trace.d2, trusted,
                                                  self.rates, trace)
        self._pending = (ghostly, trusted, person, self._slots)
        self.counts.frames += 1

    def _collect(self) -> None:
        if self._pending is None:
            return
        ghostly, trusted, person, slots = self._pending
        g, person = np.asarray(ghostly), np.asarray(person)
        self.counts.ghost_detections += int(g.sum())
        self.counts.trusted_ghosts += int((g & trusted).sum())
        for k, track in slots.items():
            if person[k]:
                self.person_frames[track] = self.person_frames.get(track, 0) + 1
        self._pending = None

    def learned_share(self) -> float:
        """Share of the floor's samples the background is sure of now."""
        return float(learned_share(self.detector, self.life, float(self.learning_frames)))

    def summary(self) -> dict:
        self._collect()
        return {**self.counts.as_dict(), "settled_share": self.settled_share,
                "learned_share_start": self.learned_at_start,
                "learned_share_end": self.learned_share()}


@dataclass
class FrameResult:
    """One processed frame of :func:`detect_frames`: its index, time, the image, the detections
    (NumPy, K slots), the valid ones' floor points and the ``people`` lines ``omnijax detect``
    writes, the tracks."""

    index: int
    t: float
    image: np.ndarray
    dets: object
    z: np.ndarray
    people: list[dict]
    tracks: list[Track]


class Perception:
    """Learning done, per frame: detector, floor positions, tracker, background's life (see the module
    docstring). The tracker has the real-time loop's defaults, and so do the ghost sites that take the
    trust of a track on a place where an untrusted track stood (:class:`~runtime.realtime.targeting.GhostSites`,
    in the loop its target selector's): the keeper is told the same trust as in ``run`` (without them a
    trusted track that took over a moved chair's detection from a passer-by kept it protected from
    absorption for good: chair_moved 9031, detected all of its 104 s)."""

    def __init__(self, rig: Rig, bg, fps: float | None, learning_frames: int, trust: TrustRule | None = None,
                 detector=None):
        self.rig = rig
        self.detector = build_detector(rig) if detector is None else detector
        self.tracker = Tracker()
        self.keeper = BackgroundKeeper(rig, self.detector, bg, trust or TrustRule(), fps, learning_frames)
        self.ghost_sites = GhostSites(self.keeper.trust)

    def step(self, image: np.ndarray, t: float):
        x = jnp.asarray(image)
        dets_d, trace, z_d, R_d = perceive(self.detector, self.rig, x, self.keeper.lines, self.keeper.life.prev)
        dets, z, R = jax.device_get((dets_d, z_d, R_d))
        valid = np.nonzero(np.asarray(dets.valid))[0]
        tracks = self.tracker.step(t, np.asarray(z)[valid], np.asarray(R)[valid])
        self.ghost_sites.update(t, tracks)
        slot_of = {tr.id: int(valid[tr.detection]) for tr in tracks if tr.detection is not None}
        self.keeper.update(x, dets_d, trace, self.keeper.trusted(tracks, slot_of, len(dets.valid)))
        return dets, np.asarray(z)[valid], valid, tracks


def people_lines(rig: Rig, dets, valid: np.ndarray) -> list[dict]:
    """The per-person objects of ``detections.jsonl`` (r_f, theta_f, the sigma rule's sigmas and the
    detector's own, how the foot from the head moves with the height and whether the head placed it,
    contrast, run edges, radial extent)."""
    s_r, s_t = (np.asarray(a) for a in detection_sigmas(rig, dets.sigma_r_f, dets.sigma_theta_f, dets.bound_r_f,
                                                        dets.bound_theta_f, dets.r_f))
    return [{"r_f": float(dets.r_f[k]), "theta_f": float(dets.theta_f[k]), "sigma_r_f": float(s_r[k]),
             "sigma_theta_f": float(s_t[k]), "detector_sigma_r_f": float(dets.sigma_r_f[k]),
             "detector_sigma_theta_f": float(dets.sigma_theta_f[k]), "detector_bound_r_f": float(dets.bound_r_f[k]),
             "detector_bound_theta_f": float(dets.bound_theta_f[k]),
             "detector_height_r_f": float(dets.height_r_f[k]), "detector_from_head": bool(dets.from_head[k]),
             "contrast": float(dets.contrast[k]),
             "theta_l": float(dets.theta_l[k]), "theta_r": float(dets.theta_r[k]),
             "r_in": float(dets.r_in[k]), "r_out": float(dets.r_out[k])} for k in valid]


class DetectRun:
    """:func:`detect_frames`'s result: iterate for the :class:`FrameResult` of each processed frame;
    ``learning_frames`` (their indices), ``step_frames`` and ``perception`` (with the keeper) once
    started."""

    def __init__(self, rig: Rig, frames: Iterable, fps: float | None, samples: int | None, seconds: float | None,
                 what: str, detector=None):
        d = rig.detection
        self.samples = samples or d.background_frames
        self.step_frames = learning_step(fps, self.samples, d.background_seconds if seconds is None else seconds)
        self.fps = fps or DEFAULT_FPS
        self._frames = iter(frames)
        bg, self.learning_frames, self.read = learn_from_frames(self._frames, self.samples, self.step_frames, what)
        self.perception = Perception(rig, bg, fps, self.samples, detector=detector)

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


__all__ = ["DEFAULT_FPS", "BackgroundKeeper", "DetectRun", "FrameResult", "LifeCounts", "Perception",
           "detect_frames", "learn_from_frames", "learning_step", "life_rates", "people_lines"]
