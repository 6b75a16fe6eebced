"""Perception scored against the synthetic world's truth: misses, false alarms and their causes, NEES.

What ``benchmarks/perception_sweep.py`` reports for every (scene, seed), from the lines ``omnijax
render`` writes (``truth.jsonl``, ``world.json``) and the lines ``omnijax detect`` writes
(``detections.jsonl``), or the same objects made in one process.

Per frame, detections and the people whose foot is in the image are matched one to one (Hungarian
on the floor distance between the detection's foot, eq 1 in the configured rig, and the true foot,
gated at :data:`GATE_M`; the rule of the demo's scorer, :func:`match_feet`). A *miss* is a person
whose foot end is visible and who got no detection; a *false alarm* a detection matching nobody.
People whose foot stands inside the rig's blind disc under the camera (``[detection]
min_floor_radius``: the detector places no foot there by design) are neither: they are not
counted as missed, and a detection matching one is not a false alarm (``blind`` counts them).

Each false alarm and miss gets one cause, the first that applies (the classifier knows the truth,
not the detector's state, so it is approximate; docs/detection.md, "Per-cause figures"):

false alarms
  ``fragment``         a person matched by another detection stands within :data:`FRAGMENT_M` (a
                       second detection of one person: the body beyond the model, a shadow)
  ``ghost_learning``   a person's foot was within :data:`SITE_M` in at least a fifth of the frames the
                       background was learnt from
  ``ghost_pause``      a person stood still within :data:`SITE_M` for :data:`PAUSE_S` or more
                       earlier and has gone
  ``moved_object``     within :data:`SITE_M` of a piece of furniture that moved (either place)
  ``shadow``           within :data:`SHADOW_M` of a visible person's shadow on the floor from a lamp
                       whose spectrum is not the ambient light's (a coloured shadow: a change of
                       chromaticity, which eq 5-7 count; a shadow under one spectrum changes only the
                       brightness): the segment from the foot away from the lamp, as long as the
                       person's height casts it (every lamp taken as on; up a wall, the shadow's foot
                       is where the segment meets the wall)
  ``far_field``        beyond :data:`FAR_M` from the camera axis
  ``other``
misses
  ``never_seen_free`` the person has stood on their spot since before the first frame the background was
                       learnt from and has not moved yet: no learning frame saw the floor under them, so
                       no change detector can see them until they move (standing_start: a first pause
                       longer than the learning)
  ``floor_coloured``   the person is dressed close to the floor's colour (the chromaticity measure sees
                       their skin and hair at most; before ``merged``: a person nobody can see is not
                       missed for the company they keep)
  ``merged``           the run of lines of a detection matched to another person covers the person's
                       azimuth (within :data:`SECTOR_MARGIN_RAD`): two people, one detection
  ``ghost_sector``     a false alarm's run covers the person's azimuth (merged with a ghost)
  ``absorbed_standing`` the person has stood still for :data:`PAUSE_S` or more
  ``far_field``        the foot beyond :data:`FAR_M`
  ``other``

Two figures of the background's life: ``ghost_gone_s``, the longest a ghost lasted after its person had
walked :data:`LEFT_M` away (from the first processed frame on, for a person who left during the
learning). A ghost is an episode: ghost false alarms (``ghost_learning``, ``ghost_pause``) within
:data:`SITE_M` of each other and none more than :data:`GHOST_GAP_S` apart; it lasted until its last false
alarm, whose age is the seconds since the last frame anyone stood within LEFT_M of it, plus one frame.
An episode that began more than GHOST_GAP_S after everyone had left its place was not there when they
left (the place was clear in between): it is a false alarm at an old place, not a ghost that lasted, and
is counted apart (``ghost_returns``, episodes; ``ghost_age_max_s``, the largest age of any ghost false
alarm, which was ``ghost_gone_s`` before 2026-11-28: a one-frame false alarm beside a walker at a place
left 6.5 s before counted as a ghost of 6.5 s); and ``standing``, how many frames a visible person had stood still for
:data:`PAUSE_S` or more and in how many of them they were detected (``standing_detected_rate``), and the
same without the frames of people standing on their spot since before the learning's first frame
(``standing_detected_rate_seen``: no change detector sees them until they move; standing_start's people).

NEES per matched detection and coordinate: ``(error / sigma)^2`` with the sigma rule's sigma
(chi-square(1): mean 1, P(> 6.63) = 0.01), overall and per band of the true foot's floor radius
(:data:`RANGE_BANDS`).
"""

from __future__ import annotations

import math
from collections import Counter
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import linear_sum_assignment

#: Matching gate on the floor (m), as the demo's scorer.
GATE_M = 0.5
#: Cause classifier: a second detection of one person within FRAGMENT_M (m); a person's place
#: within SITE_M (m); a pause of PAUSE_S (s) or more; a detection's run of lines covers a person's
#: azimuth within SECTOR_MARGIN_RAD (rad) of its ends; the far field starts FAR_M (m) from the camera
#: axis.
FRAGMENT_M, SITE_M, PAUSE_S, SECTOR_MARGIN_RAD, FAR_M = 0.7, 0.6, 1.0, 0.05, 2.7
#: A ghost's clock starts when its person is LEFT_M (m) away.
LEFT_M = 1.0
#: A ghost's false alarms are one episode while none is more than GHOST_GAP_S (s) after the last.
GHOST_GAP_S = 0.5
#: A person counts as standing at a place in the learning frames when there in this share of them.
LEARNING_SHARE = 0.2
#: A false alarm this near (m) to a coloured shadow's axis on the floor lies in it (a body's half width
#: and the detection's error); a lamp's spectrum is another colour than the ambient light's when their
#: chromaticities differ by more than SPECTRUM_CHROMA.
SHADOW_M, SPECTRUM_CHROMA = 0.4, 0.01
#: Bands of the true foot's floor radius (m) for the NEES.
RANGE_BANDS = (0.0, 1.5, 2.5, 3.5, math.inf)
#: The chi-square(1) 99 % point: a Gaussian coordinate's NEES exceeds it with probability 0.01.
NEES_99 = 6.63
FA_CAUSES = ("fragment", "ghost_learning", "ghost_pause", "moved_object", "shadow", "far_field", "other")
MISS_CAUSES = ("never_seen_free", "floor_coloured", "merged", "ghost_sector", "absorbed_standing", "far_field", "other")


def match_feet(z: np.ndarray, foot: np.ndarray, gate_m: float = GATE_M) -> list[tuple[int, int, float]]:
    """One-to-one matches (detection, person, distance m) of detections at floor points ``z`` (K, 2) to
    true feet ``foot`` (P, 2): the Hungarian assignment on the floor distance among the pairs within
    ``gate_m`` (gated first: an assignment of least total distance over all pairs may pair a detection
    with a far person and leave the near one)."""
    z, foot = np.asarray(z, float).reshape(-1, 2), np.asarray(foot, float).reshape(-1, 2)
    if not len(z) or not len(foot):
        return []
    d = np.linalg.norm(z[:, None] - foot[None], axis=-1)
    rows, cols = linear_sum_assignment(np.where(d <= gate_m, d, 1e6))
    return [(int(r), int(c), float(d[r, c])) for r, c in zip(rows, cols) if d[r, c] <= gate_m]


def wrap_pi(a):
    return (np.asarray(a) + np.pi) % (2 * np.pi) - np.pi


@dataclass
class History:
    """What the cause classifier knows of the world: every frame's feet (t, p, 2), who moves (t, p),
    who is dressed like the floor (p,), the frames the background was learnt from, the fps, the
    furniture that moved (footprint centres, m, both places), the people's heights (p,, m) and the
    lamps of another colour than the ambient light (positions (L, 3), m)."""

    feet: np.ndarray
    moving: np.ndarray
    floor_like: np.ndarray
    learning_frames: np.ndarray
    fps: float
    moved_furniture: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    heights: np.ndarray = field(default_factory=lambda: np.zeros(0))
    coloured_lamps: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))

    @classmethod
    def from_truth_lines(cls, lines: list[dict], world: dict, learning_frames, moved_furniture=()) -> History:
        n = max(t["frame"] for t in lines) + 1
        p = len(world["people"])
        feet, moving = np.full((n, p, 2), np.nan), np.zeros((n, p), bool)
        for t in lines:
            for q in t["persons"]:
                feet[t["frame"], q["id"]] = q["foot_m"]
                moving[t["frame"], q["id"]] = q["moving"]
        return cls(feet=feet, moving=moving, floor_like=np.array([q["floor_like"] for q in world["people"]], bool),
                   learning_frames=np.asarray(learning_frames, int), fps=float(world["fps"]),
                   moved_furniture=np.asarray(moved_furniture, float).reshape(-1, 2),
                   heights=np.array([q["H_p_m"] for q in world["people"]], float),
                   coloured_lamps=_coloured_lamps(world))

    def in_coloured_shadow(self, frame: int, xy) -> bool:
        """``xy`` lies within :data:`SHADOW_M` of a visible person's shadow on the floor from a lamp of
        another colour (the segment from their foot away from the lamp, ``h / (z - h)`` times the
        lamp's floor distance long)."""
        if not len(self.coloured_lamps) or not len(self.heights):
            return False
        x = np.asarray(xy, float)
        for foot, h in zip(self.feet[frame], self.heights):
            if np.isnan(foot).any():
                continue
            for lamp in self.coloured_lamps:
                away = foot - lamp[:2]
                tip = foot + away * h / max(lamp[2] - h, 0.05)
                if _segment_distance(x, foot, tip) <= SHADOW_M:
                    return True
        return False

    def ghost_age(self, frame: int, xy) -> float:
        """Seconds up to ``frame`` (inclusive) since everybody was :data:`LEFT_M` or more from ``xy``,
        counted from the first processed frame; 0 while somebody is nearer."""
        start = int(self.learning_frames.max()) + 1 if self.learning_frames.size else 0
        d = np.linalg.norm(self.feet[: frame + 1] - np.asarray(xy)[None, None], axis=-1)
        near = np.nonzero(np.any(d < LEFT_M, axis=1))[0]
        if near.size and near[-1] == frame:
            return 0.0
        left = near[-1] + 1 if near.size else 0
        return (frame - max(left, start) + 1) / self.fps

    def still_for(self, frame: int, person: int) -> float:
        """Seconds person has stood still up to ``frame`` (0 if moving at it)."""
        if getattr(self, "_still_run", None) is None:  # frames still up to each frame, once per history
            run = np.zeros(self.moving.shape, int)
            for t in range(len(run)):
                run[t] = np.where(self.moving[t], 0, (run[t - 1] if t else 0) + 1)
            self._still_run = run
        return self._still_run[frame, person] / self.fps

    def never_seen_free(self, frame: int, person: int) -> bool:
        """The person has stood still at ``frame`` since before the first learning frame."""
        if not self.learning_frames.size:
            return False
        self.still_for(frame, person)
        return bool(self._still_run[frame, person] > frame - int(self.learning_frames.min()))

    def learnt_here(self, xy) -> bool:
        f = self.learning_frames
        if not f.size:
            return False
        d = np.linalg.norm(self.feet[f] - np.asarray(xy)[None, None], axis=-1)  # (n, p)
        return bool(np.any(np.mean(d <= SITE_M, axis=0) >= LEARNING_SHARE))

    def paused_here_before(self, frame: int, xy) -> bool:
        """Someone stood still within SITE_M of ``xy`` for PAUSE_S or more before ``frame`` and is gone now."""
        start = int(self.learning_frames.max()) + 1 if self.learning_frames.size else 0
        seg = slice(start, frame)
        near = np.linalg.norm(self.feet[seg] - np.asarray(xy)[None, None], axis=-1) <= SITE_M
        still = near & ~self.moving[seg]
        need = int(round(PAUSE_S * self.fps))
        for p in range(still.shape[1]):
            now_away = np.linalg.norm(self.feet[frame, p] - xy) > SITE_M
            if now_away and _longest_run(still[:, p]) >= need:
                return True
        return False


def _coloured_lamps(world: dict) -> np.ndarray:
    """Positions (L, 3) of ``world.json``'s lamps whose spectrum's chromaticity differs from the ambient
    light's by more than :data:`SPECTRUM_CHROMA`."""
    lamps = world.get("lamps", [])
    ambient = np.asarray(world.get("ambient_spectrum", [1.0, 1.0, 1.0]), float)
    chroma = lambda s: np.asarray(s, float)[:2] / max(float(np.sum(s)), 1e-9)
    out = [q["position_m"] for q in lamps
           if np.abs(chroma(q["spectrum"]) - chroma(ambient)).max() > SPECTRUM_CHROMA]
    return np.asarray(out, float).reshape(-1, 3)


def _covers(detection: dict, theta: float) -> bool:
    """Whether ``detection``'s run of lines (``theta_l`` .. ``theta_r``, about ``theta_f``) covers the
    azimuth ``theta`` within :data:`SECTOR_MARGIN_RAD`."""
    half = 0.5 * abs(float(wrap_pi(detection["theta_r"] - detection["theta_l"]))) + SECTOR_MARGIN_RAD
    return bool(abs(wrap_pi(detection["theta_f"] - theta)) <= half)


def _segment_distance(x: np.ndarray, a: np.ndarray, b: np.ndarray) -> float:
    """Distance from point ``x`` to the segment ``a``-``b`` (2-D)."""
    ab = b - a
    t = np.clip((x - a) @ ab / max(float(ab @ ab), 1e-12), 0.0, 1.0)
    return float(np.linalg.norm(x - (a + t * ab)))


def _longest_run(b: np.ndarray) -> int:
    best = run = 0
    for v in b:
        run = run + 1 if v else 0
        best = max(best, run)
    return best


@dataclass
class PerceptionScore:
    """Counts, causes and NEES over the frames scored (see the module docstring)."""

    blind_radius_m: float = 0.0
    visible: int = 0
    misses: int = 0
    blind: int = 0
    detections: int = 0
    false_alarms: int = 0
    frames: int = 0
    #: ghost episodes: [age at the first false alarm (s), age at the last (s), last frame, place (2,)]
    ghosts: list = field(default_factory=list)
    standing_frames: int = 0
    standing_detected: int = 0
    #: the same without the frames of people the learning never saw off their spot (``never_seen_free``)
    standing_seen_frames: int = 0
    standing_seen_detected: int = 0
    fa_causes: Counter = field(default_factory=Counter)
    miss_causes: Counter = field(default_factory=Counter)
    nees: list = field(default_factory=list)  # (R_m, nees_r, nees_theta)
    #: per matched detection: the true foot's floor radius (m), the errors of r_f (px) and theta_f (rad)
    #: and the detector's own sigmas and bound parts (before the rule): what benchmarks/fit_detection_sigmas.py
    #: fits; then what may explain an error: the true r_f (px), the detection's contrast, run width (rad),
    #: r_in and r_out (px), whether the person was moving, the person's height (m), the detector's coupling of
    #: the foot to the height (px a metre: ``Detections.height_r_f``) and whether the head placed it
    records: list = field(default_factory=list)

    def add_frame(self, frame: int, truth: dict, people: list[dict], z: np.ndarray, sigmas: np.ndarray,
                  history: History | None) -> dict:
        """Score one frame: ``truth`` a truth line, ``people`` the detections (``r_f``, ``theta_f``,
        ``theta_l``, ``theta_r``), ``z`` their floor points (K, 2), ``sigmas`` their sigma-rule
        sigmas (K, 2: r_f px, theta_f rad). Returns the frame's misses and false alarms with causes."""
        self.frames += 1
        persons = [q for q in truth["persons"] if q["in_image"]]
        foot = np.array([q["foot_m"] for q in persons]).reshape(-1, 2)
        blind = {c for c, q in enumerate(persons) if math.hypot(*q["foot_m"]) < self.blind_radius_m}
        self.blind += len(blind)
        if blind:  # a detection on a person under the camera is neither right nor wrong: left out
            on_blind = {r for r, c, _ in match_feet(z, foot) if c in blind}
            people, z, sigmas = self._drop(people, z, sigmas, on_blind)
        seen = [c for c in range(len(persons)) if c not in blind]
        pairs = [(r, seen[c], d) for r, c, d in match_feet(z, foot[seen])]
        det_of = {c: r for r, c, _ in pairs}
        person_of = {r: c for r, c, _ in pairs}
        for r, c, _ in pairs:
            q = persons[c]
            e_r = people[r]["r_f"] - q["r_f"]
            e_t = float(wrap_pi(people[r]["theta_f"] - q["theta_f"]))
            R = float(np.hypot(*q["foot_m"]))
            self.nees.append((R, (e_r / sigmas[r, 0]) ** 2, (e_t / sigmas[r, 1]) ** 2))
            p = people[r]
            self.records.append((R, float(e_r), e_t, float(p.get("detector_sigma_r_f", sigmas[r, 0])),
                                 float(p.get("detector_sigma_theta_f", sigmas[r, 1])),
                                 float(p.get("detector_bound_r_f", 0.0)), float(p.get("detector_bound_theta_f", 0.0)),
                                 float(q["r_f"]), float(p.get("contrast", 0.0)),
                                 float(wrap_pi(p["theta_r"] - p["theta_l"])), float(p.get("r_in", 0.0)),
                                 float(p.get("r_out", 0.0)), float(q.get("moving", False)),
                                 float(q.get("H_p_m", math.nan)), float(p.get("detector_height_r_f", 0.0)),
                                 float(p.get("detector_from_head", False))))
        out = {"missed": [], "false": []}
        unmatched = [k for k in range(len(people)) if k not in person_of]
        for c, q in enumerate(persons):
            if not q["foot_visible"] or c in blind:
                continue
            self.visible += 1
            standing = bool(history is not None and history.still_for(frame, q["id"]) >= PAUSE_S)
            seen_standing = standing and not history.never_seen_free(frame, q["id"])
            self.standing_frames += standing
            self.standing_seen_frames += seen_standing
            if c in det_of:
                self.standing_detected += standing
                self.standing_seen_detected += seen_standing
                continue
            self.misses += 1
            cause = self._miss_cause(frame, q, persons, det_of, people, unmatched, history)
            self.miss_causes[cause] += 1
            out["missed"].append({"id": q["id"], "cause": cause})
        self.detections += len(people)
        for k in unmatched:
            self.false_alarms += 1
            cause = self._fa_cause(frame, z[k], z, person_of, foot, history)
            self.fa_causes[cause] += 1
            if cause in ("ghost_learning", "ghost_pause"):
                self._ghost_seen(frame, z[k], history.ghost_age(frame, z[k]), history.fps)
            out["false"].append({"xy": [round(float(v), 3) for v in z[k]], "cause": cause})
        return out

    @staticmethod
    def _drop(people, z, sigmas, which: set):
        """``people``, ``z``, ``sigmas`` without the detections ``which`` (those on a blind person)."""
        keep = [k for k in range(len(people)) if k not in which]
        return [people[k] for k in keep], np.asarray(z).reshape(-1, 2)[keep], np.asarray(sigmas).reshape(-1, 2)[keep]

    @staticmethod
    def _fa_cause(frame, xy, z, person_of, foot, history) -> str:
        for k, c in person_of.items():
            if np.linalg.norm(z[k] - xy) <= FRAGMENT_M and np.linalg.norm(foot[c] - xy) <= FRAGMENT_M:
                return "fragment"
        if history is not None:
            if history.learnt_here(xy):
                return "ghost_learning"
            if history.paused_here_before(frame, xy):
                return "ghost_pause"
            if len(history.moved_furniture) and np.min(np.linalg.norm(history.moved_furniture - xy, axis=-1)) <= 1.0:
                return "moved_object"
            if history.in_coloured_shadow(frame, xy):
                return "shadow"
        return "far_field" if np.hypot(*xy) > FAR_M else "other"

    @staticmethod
    def _miss_cause(frame, q, persons, det_of, people, unmatched, history) -> str:
        if history is not None and history.never_seen_free(frame, q["id"]):
            return "never_seen_free"
        if history is not None and history.floor_like[q["id"]]:
            return "floor_coloured"
        if any(_covers(people[r], q["theta_f"]) for c, r in det_of.items() if persons[c] is not q):
            return "merged"
        if any(_covers(people[k], q["theta_f"]) for k in unmatched):
            return "ghost_sector"
        if history is not None and history.still_for(frame, q["id"]) >= PAUSE_S:
            return "absorbed_standing"
        return "far_field" if np.hypot(*q["foot_m"]) > FAR_M else "other"

    def _ghost_seen(self, frame: int, xy, age: float, fps: float) -> None:
        """A ghost false alarm at ``xy``: it continues the episode at that place, or begins one."""
        for ep in self.ghosts:
            if frame - ep[2] <= GHOST_GAP_S * fps and np.linalg.norm(ep[3] - xy) <= SITE_M:
                ep[1:] = [age, frame, np.asarray(xy, float)]
                return
        self.ghosts.append([age, age, frame, np.asarray(xy, float)])

    def ghost_figures(self) -> dict:
        """``ghost_gone_s`` (the longest a ghost lasted after its person left), ``ghost_returns`` (episodes
        that began at a place left more than GHOST_GAP_S before) and ``ghost_age_max_s`` (module docstring)."""
        lasted = [ep[1] for ep in self.ghosts if ep[0] <= GHOST_GAP_S]
        return {"ghost_gone_s": float(max(lasted, default=0.0)),
                "ghost_returns": int(sum(ep[0] > GHOST_GAP_S for ep in self.ghosts)),
                "ghost_age_max_s": float(max((ep[1] for ep in self.ghosts), default=0.0))}

    def nees_figures(self) -> dict:
        """NEES mean and P(> 6.63) of r_f and theta_f, overall and per range band."""
        a = np.array(self.nees, float).reshape(-1, 3)
        out = {"all": _nees(a)}
        for lo, hi in zip(RANGE_BANDS, RANGE_BANDS[1:]):
            sel = (a[:, 0] >= lo) & (a[:, 0] < hi)
            out[f"{lo:g}-{hi:g} m"] = _nees(a[sel])
        return out

    def _miss_rate_seen(self) -> float | None:
        """The miss rate over the person-frames of people whose floor the learning saw (without the
        ``never_seen_free`` ones, which no change detector can see)."""
        n = self.miss_causes["never_seen_free"]
        return (self.misses - n) / (self.visible - n) if self.visible > n else None

    def summary(self) -> dict:
        return {"frames": self.frames, "visible": self.visible, "misses": self.misses, "blind": self.blind,
                "detections": self.detections, "false_alarms": self.false_alarms,
                "miss_rate": self.misses / self.visible if self.visible else None,
                "false_alarm_rate": self.false_alarms / self.detections if self.detections else None,
                "miss_rate_seen": self._miss_rate_seen(),
                "fa_causes": {c: self.fa_causes[c] for c in FA_CAUSES},
                "miss_causes": {c: self.miss_causes[c] for c in MISS_CAUSES},
                **self.ghost_figures(), "standing_frames": self.standing_frames,
                "standing_detected_rate": (self.standing_detected / self.standing_frames
                                           if self.standing_frames else None),
                "standing_seen_frames": self.standing_seen_frames,
                "standing_detected_rate_seen": (self.standing_seen_detected / self.standing_seen_frames
                                                if self.standing_seen_frames else None),
                "nees": self.nees_figures()}


def _nees(a: np.ndarray) -> dict:
    if not len(a):
        return {"n": 0}
    return {"n": int(len(a)), "r_f_mean": float(a[:, 1].mean()), "r_f_over_6_63": float(np.mean(a[:, 1] > NEES_99)),
            "theta_f_mean": float(a[:, 2].mean()), "theta_f_over_6_63": float(np.mean(a[:, 2] > NEES_99))}
