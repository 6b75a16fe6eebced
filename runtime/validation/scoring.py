"""Scoring the real-time loop against the synthetic world's ground truth (``omnijax demo``).

Per processed frame (an ``on_frame`` hook of :class:`~runtime.loop.RealTimeLoop`):

- detection: detections and the people whose foot is inside the image are matched one to one
  (:func:`runtime.validation.perception.match_feet`: Hungarian on the floor distance among the pairs
  within ``gate_m``). A *miss* is a person whose foot end is
  visible (not hidden by furniture or another person) and who got no detection; a *false
  alarm* is a detection matching nobody. ``miss_rate`` = misses / visible person-frames;
  ``false_alarm_rate`` = false alarms / detections (also given per frame). ``foot_error_m``:
  floor distance between each matched detection (eq 1 with the configured rig) and the true
  foot.
- containment: each frame with a target gives one trial per zoom rule (with several PTZs, one per
  PTZ with a target): the commanded pan and tilt with that rule's zoom, against the targeted
  person's true head at the time the command was predicted for (interpolated between frames), in
  the world's *true* rig of that PTZ (:func:`omnijax._foveal.head_in_view`: the whole head sphere
  inside the frame). The target is the true person nearest the target track (within ``gate_m``;
  otherwise the trial fails; the track's position is the one the command was made at: a PTZ holding on
  through a missed detection keeps its command).
  ``face_px``: the head's width in the foveal image at that zoom and the true distance. Each
  rule also reports the mean containment probability it predicted, and the rate over the
  trials where it could reach p_contain at all (its widest zoom sufficed).
- what a user of the PTZ sees: ``rate`` is over *all* target-frames; ``no_person_share`` the
  share of target-frames aimed at a track matching no person; ``rate_person_frames`` the frames
  with a head framed (``framed_frames``: by some PTZ) over all frames with someone in the image
  (frames where the loop held, no target, count as not framed; ``held`` counts them by the loop's
  reason: ``untrusted``,
  ``unframeable``, or ``no_track``); ``face_coverage``: per person, the share of their frames in
  the image in which some PTZ framed their head (each rule's zoom at the commanded pan/tilt; a
  frame counts once however many PTZs framed them).
- per PTZ (``cameras``): its target-frames, the share of them with the head framed
  (``framed_rate``, the driving rule's; ``rules`` has both), those aimed at no person, the median face.

- the loop's own pointing (``pointing``): every frame on which the PTZ has arrived at the command
  it holds on the frame's target (``status["arrived"]`` of :class:`~runtime.realtime.loop.RealTimeLoop`)
  is one trial: the NEES of the held pan/tilt against the true head direction of the targeted person
  (the true person nearest the target track, within ``gate_m``) at the frame's time, under the
  held aim's covariance (:mod:`runtime.validation.pointing`), and whether the head is in the frame
  at the zoom each rule chooses from that covariance for p_contain 0.9, 0.95, 0.99 (``curve``).
  Frames arrived on a track matching no person are counted (``no_person``), not scored.

Trials are scored in batches of :data:`BATCH` and only counts, sums and histograms are kept, so the
memory stays flat however long the demo runs.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from omnijax.world import head_in_view
from omnijax.zoom import ZOOM_RULES as RULES
from runtime.validation.perception import match_feet
from runtime.validation.pointing import (
    NEES_95_2DOF,
    P_CONTAIN,
    containment_at,
    head_direction,
    nees_summary,
    pointing_errors,
)

#: Trials scored at once (one compiled shape); face widths are histogrammed in 1 px bins up to FACE_MAX.
BATCH, FACE_MAX = 256, 4096


@eqx.filter_jit
def _trials(true_rig, pan, tilt, zoom, head, R_h):  # true_rig: one PTZ's
    """head_in_view over trials (n,) and rules (n, r): inside (n, r), face_px (n, r)."""
    def one(p, t, z, h, r):
        v = jax.vmap(lambda zz: head_in_view(true_rig, p, t, zz, h, r))(z)
        return v.inside, v.face_px
    return jax.vmap(one)(pan, tilt, zoom, head, R_h)


@eqx.filter_jit
def _pointing_trials(rig, true_rig, pan, tilt, cov4, distance, slant, foot, H_p, R_h):
    """Per arrived frame (n,): NEES, each axis's squared error over its variance, and containment (n, p, rule)."""
    pan_true, tilt_true = head_direction(true_rig, foot, H_p, R_h)
    errors = pointing_errors(pan, tilt, cov4[:, :2, :2], pan_true, tilt_true)
    head = jnp.concatenate([foot, (H_p - R_h)[:, None]], -1)
    inside = jax.vmap(lambda *a: containment_at(rig, true_rig, *a, jnp.asarray(P_CONTAIN)))(
        pan, tilt, cov4, distance, slant, head, R_h)
    return (*errors, inside)


class DemoScorer:
    """Scores a run of :class:`~runtime.sources.SyntheticSource` (see the module docstring)."""

    def __init__(self, world, source, gate_m: float = 0.5):
        self.world, self.source, self.gate_m = world, source, gate_m
        self.true_rigs = [world.true_rig.ptz(k) for k in range(world.true_rig.ptz_count)]
        K = len(self.true_rigs)
        self.fps = float(world.scenario.fps)
        self.positions = np.asarray(world.paths.position)  # (t, p, 2)
        self.head_z = np.asarray(world.people.head_z)
        self.R_h = np.asarray(world.people.R_h)
        self.visible = self.misses = self.detections = self.false_alarms = self.frames = 0
        self.foot_sq_sum, self.matched = 0.0, 0
        self.batch: list[tuple] = []
        self.trials = self.no_person = 0
        nr = len(RULES)
        self.contained, self.feasible, self.feasible_contained = np.zeros(nr, int), np.zeros(nr, int), np.zeros(nr, int)
        self.prob_sum, self.zoom_sum = np.zeros(nr), np.zeros(nr)
        self.face_hist, self.face_hist_in = np.zeros((nr, FACE_MAX + 1), int), np.zeros((nr, FACE_MAX + 1), int)
        self.p_contain = float(world.rig.p_contain)
        n_people = self.positions.shape[1]
        self.in_view = np.zeros(n_people, int)  # frames each person's foot is in the image
        self.framed = np.zeros((nr, n_people), int)  # frames each person's head was framed (by some PTZ), per rule
        self.last_framed = np.full((nr, n_people), -1)  # the last frame counted there
        self.framed_frames, self.last_framed_frame = np.zeros(nr, int), np.full(nr, -1)  # frames with a head framed
        # per PTZ: target-frames, those on no person, framed per rule, face widths
        self.cam_trials, self.cam_no_person = np.zeros(K, int), np.zeros(K, int)
        self.cam_contained, self.cam_feasible = np.zeros((K, nr), int), np.zeros((K, nr), int)
        self.cam_feasible_contained = np.zeros((K, nr), int)
        self.cam_face_hist = np.zeros((K, nr, FACE_MAX + 1), int)
        self.person_frames = 0  # frames with someone in the image
        self.held = {"untrusted": 0, "unframeable": 0, "no_track": 0}  # of those, frames without a target
        self.last_target_error: float | None = None
        self.H_p = np.asarray(world.people.H_p)
        self.rigs = [world.rig.ptz(k) for k in range(K)]
        self.arrived: list[list[tuple]] = [[] for _ in range(K)]  # per PTZ, arrived frames waiting to be scored
        self.arrived_people: list[list[int]] = [[] for _ in range(K)]  # the person of each of those frames
        # per person: frames, NEES, pan's and tilt's squared error over variance (pointing()["people"])
        self.person_nees = np.zeros((len(self.H_p), 4))
        self.arrived_no_person = 0
        self.nees_sums = np.zeros(5)  # frames, NEES, NEES^2, pan's and tilt's squared error over variance
        self.nees_over = 0
        self.arrived_inside = np.zeros((len(P_CONTAIN), len(RULES)), int)

    def warm_up(self) -> None:
        """Compile the batch scorers (:func:`_trials`, :func:`_pointing_trials`, one shape each) for every
        PTZ before the loop starts: the first full batch comes hundreds of frames in, on the drawing thread,
        and tracing and compiling them there held it 1.1-1.4 s (3.7 s on a cold compilation cache, when the
        drawing queue filled and 42 frames went undrawn and unscored; docs/runtime.md)."""
        n, nr = BATCH, len(RULES)
        a = lambda *shape, v=1.0: jnp.asarray(np.full(shape, v))  # staged from the host as the batches are
        for rig, true_rig in zip(self.rigs, self.true_rigs):
            _trials(true_rig, a(n), a(n, v=-0.3), a(n, nr), a(n, 3), a(n, v=0.1))
            _pointing_trials(rig, true_rig, a(n), a(n, v=-0.3), jnp.asarray(np.tile(1e-4 * np.eye(4), (n, 1, 1))),
                             a(n, v=3.0), a(n, v=3.0), a(n, 2), a(n, v=1.75), a(n, v=0.1))

    def __call__(self, record, frame, dets, z, tracks, commands, status=None, *_) -> dict:
        truth = self.source.take_truth(frame.index)
        if truth is None:
            return {}
        self.frames += 1
        foot = np.asarray(truth.foot)
        inside = np.nonzero(np.asarray(truth.in_image))[0]
        visible = np.asarray(truth.foot_visible)
        z = np.asarray(z).reshape(-1, 2)
        matched = set()
        for _r, c, dist in match_feet(z, foot[inside], self.gate_m):
            matched.add(int(inside[c]))
            self.foot_sq_sum += dist**2
            self.matched += 1
        n_vis = int(visible[inside].sum())
        missed = sum(1 for j in inside if visible[j] and j not in matched)
        fa = len(z) - len(matched)
        self.visible += n_vis
        self.misses += missed
        self.detections += len(z)
        self.false_alarms += fa
        out = {"truth": {"visible": n_vis, "missed": missed, "false_alarms": fa}}
        self.in_view[inside] += 1
        self.person_frames += bool(len(inside))
        if record.get("operator") in ("point", "paused"):  # the operator had the PTZ: not the loop's choice
            return out
        if all(command is None for command in commands) and len(inside):
            self.held[record.get("held") or "no_track"] += 1
        people = [None if command is None else self._add_trial(frame.index, k, command, tracks)
                  for k, command in enumerate(commands)]
        if len(commands) == 1 and commands[0] is not None:
            out["truth"]["target_person"] = people[0]
            out["truth"]["target_error_m"] = self.last_target_error
        elif len(commands) > 1:
            out["truth"]["target_people"] = people
        for k, held in enumerate((status or {}).get("arrived") or ()):
            if held is not None and held.aimed is not None:
                self._add_arrived(frame.index, k, held, tracks)
        return out

    def _add_arrived(self, index: int, camera: int, held, tracks) -> None:
        """One frame on which PTZ ``camera`` holds ``held`` on its target: queued for :meth:`_score_arrived`."""
        xy = next((tr.position for tr in tracks if tr.id == held.track), None)
        pos = self.positions[min(index, len(self.positions) - 1)]
        d = np.linalg.norm(pos - xy, axis=-1) if xy is not None else np.zeros(0)
        if not d.size or d.min() > self.gate_m:
            self.arrived_no_person += 1
            return
        k = int(np.argmin(d))
        a = held.aimed
        queue = self.arrived[camera]
        queue.append((held.pan, held.tilt, np.asarray(a.covariance.cov), float(a.pointing.distance),
                      float(a.pointing.slant), pos[k], self.H_p[k], self.R_h[k]))
        self.arrived_people[camera].append(k)
        if len(queue) == BATCH:
            self._score_arrived(camera)

    def _score_arrived(self, camera: int) -> None:
        queue = self.arrived[camera]
        n = len(queue)
        if not n:
            return
        pad = queue + [queue[-1]] * (BATCH - n)
        cols = [jnp.asarray(np.array(v, float)) for v in zip(*pad)]
        out = [np.asarray(a)[:n] for a in _pointing_trials(self.rigs[camera], self.true_rigs[camera], *cols)]
        v, pan_sq, tilt_sq, inside = out
        self.nees_sums += [n, v.sum(), (v * v).sum(), pan_sq.sum(), tilt_sq.sum()]
        self.nees_over += int((v > NEES_95_2DOF).sum())
        self.arrived_inside += inside.sum(0)
        np.add.at(self.person_nees, np.asarray(self.arrived_people[camera], int),
                  np.stack([np.ones(n), v, pan_sq, tilt_sq], 1))
        queue.clear()
        self.arrived_people[camera].clear()

    def pointing(self) -> dict:
        """``summary.json``'s ``pointing``: the NEES of the held pointing on the arrived frames of every PTZ
        (see the module docstring), and the containment ``curve`` there."""
        for camera in range(len(self.arrived)):
            self._score_arrived(camera)
        n, s1, s2, sp, st = self.nees_sums
        n = int(n)
        out = nees_summary(np.zeros(0))
        if n:
            out.update(nees_mean=s1 / n / 2, nees_over_5_99=self.nees_over / n, pan_nees_mean=sp / n,
                       tilt_nees_mean=st / n)
            if n > 1:
                out["nees_mean_se"] = float(np.sqrt(max(s2 - s1 * s1 / n, 0.0) / (n - 1) / n) / 2)
        people = [{"person": i, "H_p_m": round(float(self.H_p[i]), 4), "frames": int(m),
                   "nees_mean": v / m / 2 if m else None, "pan_nees_mean": pan / m if m else None,
                   "tilt_nees_mean": tilt / m if m else None}
                  for i, (m, v, pan, tilt) in enumerate(self.person_nees)]
        out.update(frames=n, no_person=self.arrived_no_person, people=people,
                   curve=[{"rule": rule, "p_contain": p, "rate": self.arrived_inside[i, j] / n if n else None,
                           "trials": n} for j, rule in enumerate(RULES) for i, p in enumerate(P_CONTAIN)],
                   meaning="frames on which a PTZ had arrived at the command it held on its target: the held "
                           "pan/tilt against the true head direction at the frame's time, under the held aim's "
                           "covariance; nees_mean per degree of freedom (1 when the covariance is right), "
                           "nees_over_5_99 the share above chi-square(2)'s 95 % point (0.05 when right); curve: "
                           "the head in the frame at each rule's zoom for each p_contain from that covariance; "
                           "people: the same per person of the world (their true height H_p_m): a person far "
                           "from the height prior shows here")
        return out

    def _add_trial(self, index: int, camera: int, command, tracks) -> int | None:
        xy = command.xy if command.xy is not None else next((tr.position for tr in tracks if tr.id == command.track),
                                                             None)
        pos_now = self.positions[min(index, len(self.positions) - 1)]
        person = None
        if xy is not None:
            d = np.linalg.norm(pos_now - xy, axis=-1)
            self.last_target_error = float(d.min()) if d.size else None
            if d.size and d.min() <= self.gate_m:
                person = int(np.argmin(d))
        if person is None:
            self.no_person += 1
            self.cam_no_person[camera] += 1
            head, R_h = np.array([0.0, 0.0, -100.0]), 0.1  # below the floor: never in view
        else:
            k = min(max(command.t_predicted * self.fps, 0.0), len(self.positions) - 1.0)
            k0 = int(np.floor(k))
            k1 = min(k0 + 1, len(self.positions) - 1)
            w = k - k0
            p = (1 - w) * self.positions[k0, person] + w * self.positions[k1, person]
            head, R_h = np.r_[p, self.head_z[person]], float(self.R_h[person])
        aimed = command.aimed
        prob = (np.array([float(aimed.zooms[r].probability) for r in RULES]) if aimed is not None
                else np.full(len(RULES), np.nan))
        self.batch.append((command.pan, command.tilt, [command.zooms[r] for r in RULES], head, R_h, prob,
                           -1 if person is None else person, camera, index))
        if len(self.batch) == BATCH:
            self._score_batch()
        return person

    def _score_batch(self) -> None:
        """Score the trials kept (each PTZ's with its true rig, padded to one compiled shape)."""
        if not self.batch:
            return
        inside = np.zeros((len(self.batch), len(RULES)), bool)
        for k in range(len(self.true_rigs)):
            mine = [m for m, b in enumerate(self.batch) if b[7] == k]
            if mine:
                inside[mine] = self._score(k, [self.batch[m] for m in mine])
        # face coverage: the batch is in frame order; a person framed by several PTZs in one frame counts once
        person = np.array([b[6] for b in self.batch], int)
        frame = np.array([b[8] for b in self.batch], int)
        for i in range(len(RULES)):
            hit = inside[:, i] & (person >= 0)
            for p, f in zip(person[hit], frame[hit]):
                if self.last_framed[i, p] != f:
                    self.framed[i, p] += 1
                    self.last_framed[i, p] = f
                if self.last_framed_frame[i] != f:
                    self.framed_frames[i] += 1
                    self.last_framed_frame[i] = f
        self.batch.clear()

    def _score(self, camera: int, batch: list[tuple]) -> np.ndarray:
        """Score PTZ ``camera``'s trials ``batch``; whether each framed the head (n, rules)."""
        n = len(batch)
        pad = batch + [batch[-1]] * (BATCH - n)
        pan, tilt, zoom, head, R_h, prob, *_ = (np.array(v, float) for v in zip(*pad))
        inside, px = (np.asarray(a)[:n] for a in _trials(self.true_rigs[camera], jnp.asarray(pan),
                                                           jnp.asarray(tilt), jnp.asarray(zoom), jnp.asarray(head),
                                                           jnp.asarray(R_h)))
        zoom, prob = zoom[:n], prob[:n]
        bins = np.clip(np.round(px), 0, FACE_MAX).astype(int)
        feasible = prob >= self.p_contain - 1e-9
        self.trials += n
        self.contained += inside.sum(0)
        self.feasible += feasible.sum(0)
        self.feasible_contained += (feasible & inside).sum(0)
        self.prob_sum += np.nan_to_num(prob).sum(0)
        self.zoom_sum += zoom.sum(0)
        self.cam_trials[camera] += n
        self.cam_contained[camera] += inside.sum(0)
        self.cam_feasible[camera] += feasible.sum(0)
        self.cam_feasible_contained[camera] += (feasible & inside).sum(0)
        for i in range(len(RULES)):
            self.face_hist[i] += np.bincount(bins[:, i], minlength=FACE_MAX + 1)
            self.face_hist_in[i] += np.bincount(bins[inside[:, i], i], minlength=FACE_MAX + 1)
            self.cam_face_hist[camera, i] += np.bincount(bins[:, i], minlength=FACE_MAX + 1)
        return inside

    def summary(self, p_contain: float, rule: str) -> dict:
        """The demo's scores for ``summary.json``; ``rate`` and ``median`` at the top are those of
        ``rule`` (the one the PTZ was driven with), ``rules`` has both."""
        det = {"miss_rate": self.misses / self.visible if self.visible else None,
               "false_alarm_rate": self.false_alarms / self.detections if self.detections else None,
               "false_alarms_per_frame": self.false_alarms / self.frames if self.frames else None,
               "visible_person_frames": self.visible, "misses": self.misses,
               "detections": self.detections, "false_alarms": self.false_alarms, "gate_m": self.gate_m}
        foot = {"rms": float(np.sqrt(self.foot_sq_sum / self.matched)) if self.matched else None,
                "matched": self.matched}
        self._score_batch()
        n = self.trials
        cont = {"p_contain": p_contain, "rule": rule, "rate": None, "trials": n, "no_person": self.no_person,
                "no_person_share": self.no_person / n if n else None, "person_frames": self.person_frames,
                "held": dict(self.held), "rules": {}}
        face = {"rule": rule, "median": None, "rules": {}}
        for i, r in enumerate(RULES):
            if not n:
                break
            cont["rules"][r] = {
                "rate": self.contained[i] / n, "contained": int(self.contained[i]), "trials": n,
                "predicted_mean": self.prob_sum[i] / n, "zoom_mean": self.zoom_sum[i] / n,
                "feasible_trials": int(self.feasible[i]),
                "rate_feasible": self.feasible_contained[i] / self.feasible[i] if self.feasible[i] else None,
                "framed_frames": int(self.framed_frames[i]),
                "rate_person_frames": self.framed_frames[i] / self.person_frames if self.person_frames else None}
            face["rules"][r] = {"median": _hist_median(self.face_hist[i]),
                                "median_contained": _hist_median(self.face_hist_in[i])}
        if n:
            cont["rate"] = cont["rules"][rule]["rate"]
            cont["rate_person_frames"] = cont["rules"][rule]["rate_person_frames"]
            face["median"] = face["rules"][rule]["median"]
        return {"detection": det, "foot_error_m": foot, "containment": cont, "face_px": face,
                "face_coverage": self._coverage(rule), "cameras": self._cameras(rule), "pointing": self.pointing()}

    def _cameras(self, rule: str) -> list[dict]:
        """Per PTZ: ``id``, ``target_frames``, ``framed_rate`` (``rule``'s, over its target-frames), ``rules``
        (each rule's ``rate``, ``contained``, ``rate_feasible``), ``no_person``, ``face_px_median``."""
        out = []
        i = RULES.index(rule)
        for k, n in enumerate(self.cam_trials):
            contained, feasible = self.cam_contained[k], self.cam_feasible[k]
            rules = {r: {"rate": contained[j] / n if n else None, "contained": int(contained[j]),
                         "rate_feasible": self.cam_feasible_contained[k, j] / feasible[j] if feasible[j] else None}
                     for j, r in enumerate(RULES)}
            out.append({"id": k, "rule": rule, "target_frames": int(n), "framed_rate": rules[rule]["rate"],
                        "rules": rules, "no_person": int(self.cam_no_person[k]),
                        "face_px_median": _hist_median(self.cam_face_hist[k, i])})
        return out

    def _coverage(self, rule: str) -> dict:
        """Per person (seen in the image at all), the share of their frames in the image with their head
        framed, per rule; ``mean`` and ``min`` over them for ``rule``."""
        people = []
        for p in np.nonzero(self.in_view)[0]:
            people.append({"person": int(p), "frames_in_view": int(self.in_view[p]),
                           "rules": {r: self.framed[i, p] / self.in_view[p] for i, r in enumerate(RULES)}})
        shares = [q["rules"][rule] for q in people]
        return {"rule": rule, "mean": float(np.mean(shares)) if shares else None,
                "min": float(np.min(shares)) if shares else None, "people": people}


def _hist_median(hist: np.ndarray) -> float | None:
    """Median of values histogrammed in 1-unit bins (to the bin)."""
    total = hist.sum()
    if not total:
        return None
    return float(np.searchsorted(np.cumsum(hist), (total + 1) / 2))
