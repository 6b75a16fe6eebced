"""Which person each of several PTZs looks at: an exact assignment every frame.

A rig with one PTZ keeps its :class:`~runtime.realtime.targeting.TargetSelector` (round-robin with a
dwell time). With several, :class:`CameraAssigner` assigns the trusted tracks that some PTZ can frame
(the same :class:`~runtime.realtime.targeting.TrustRule`, ghost sites and framability test) to the
PTZs every frame, so as to maximise what is captured. Per (PTZ c, track j), from the control call's
aims (:mod:`runtime.realtime.control`):

- the framing strength ``s = p * min(face / face_target, 1)``: ``p`` the containment probability the
  driving zoom rule predicts (at least ``p_contain`` where it is framable), ``face`` the head's width in
  that PTZ's image at that zoom, ``face_target`` the rig's ``layout.face_target_px``;
- the slew factor ``tau / (tau + slew)``: ``slew`` the PTZ's command latency and pan/tilt slew time
  from its last command to the track (s), ``tau`` the dwell time (at least :data:`MIN_TAU`): the share
  of one dwell actually spent on the face;
- the need ``1 + wait / tau``: ``wait`` how long the person has gone uncaptured (s since a PTZ last
  stood on them, or since they were first a candidate);

``value = s * need * tau / (tau + slew)``, times ``1 + hysteresis`` for the person the PTZ is on already
(so that PTZs do not swap targets from frame to frame over small differences). The assignment is
lexicographic, solved exactly in one Hungarian assignment (:func:`runtime.realtime.kalman.optimal_assignment`)
with the tiers weighted so that each outweighs any sum of the ones below it:

1. the operator's chosen track (kept on the PTZ best for it while some PTZ can frame it);
2. the number of people with a PTZ (as many as can be: no PTZ spare while a framable person waits);
3. people in a *priority* zone;
4. dwell locks: a PTZ keeps its person until it has stood on them ``dwell_s`` (then the face is
   captured, ``Track.captured``);
5. the values.

**Spare PTZs** (more PTZs than framable people): each one left over goes, in further rounds of the same
assignment, where it adds the most expected capture: ``miss_j * s * tau / (tau + slew)``, ``miss_j`` the
probability that every PTZ already on person j misses them (``prod (1 - s)``): the person whose framing
is weakest gets a second view, at that PTZ's own zoom for ``p_contain``. docs/site.md says why this
rather than a second, wider zoom on one person.

**Hand-offs**: a PTZ leaves a person while another PTZ is on them (took them over this frame or was
on them already): counted for the PTZ that keeps the person (``handoffs``) and the one that left
(``handed_over``). A person walking out of one PTZ's good region (its framing strength falls, or it
can no longer frame them at ``p_contain``) into another's is handed over once the other's value beats
the first's with its hysteresis.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import jax
import numpy as np

from runtime.realtime import kalman
from runtime.realtime.targeting import GhostSites, TrustRule, is_trusted
from runtime.realtime.tracker import Track

#: Value bonus (relative) of the person a PTZ is on already.
HYSTERESIS = 0.25
#: Shortest time scale (s) of the slew factor and the need, whatever the dwell time.
MIN_TAU = 0.5

_solve = jax.jit(kalman.optimal_assignment)


def assign_exact(value: np.ndarray, allowed: np.ndarray, columns: int | None = None) -> np.ndarray:
    """The assignment of rows to columns of largest total ``value`` (R, C) among the ``allowed`` pairs
    (each row at most one column, each column at most one row), with as many pairs as can be first:
    each row's column, -1 for none. Solved exactly by the tracker's Hungarian assignment on a cost
    matrix padded to ``columns`` (one compiled shape), where a row left without an allowed column sits
    on a :data:`~runtime.realtime.kalman.FORBIDDEN` one, which costs more than any sum of the others."""
    R, C = value.shape
    width = max(columns or C, C, R)
    if R == 0 or C == 0 or not allowed.any():
        return np.full(R, -1)
    v = np.where(allowed, value, 0.0)
    v = v - v[allowed].min() + 1.0  # a shift changes no choice among assignments of one size
    cost = np.full((R, width), kalman.FORBIDDEN)
    # totals within (-1, 0): a row left on a FORBIDDEN column costs more than any choice of values gains
    cost[:, :C] = np.where(allowed, -v / (R * v[allowed].max()), kalman.FORBIDDEN)
    col = np.asarray(_solve(cost))
    return np.where((col >= 0) & (col < C), col, -1)


@dataclass
class CameraState:
    """One PTZ's target and its counters."""

    track: int | None = None
    settled_at: float | None = None
    handoffs: int = 0
    handed_over: int = 0
    held: dict[str, int] = field(default_factory=lambda: {"untrusted": 0, "unframeable": 0, "paused": 0})


@dataclass(frozen=True)
class PairValues:
    """Per (PTZ, candidate track), (K, n): ``framable`` (valid pointing, the driving rule reaches
    ``p_contain``), ``probability`` (the containment probability predicted at its zoom), ``face_px``
    (the head's width in the PTZ's image at that zoom), ``slew_s`` (command latency and slew time from
    the PTZ's last command to the track)."""

    framable: np.ndarray
    probability: np.ndarray
    face_px: np.ndarray
    slew_s: np.ndarray

    def strength(self, face_target_px: float) -> np.ndarray:
        """The framing strength ``p * min(face / face_target, 1)`` (K, n), 0 where not framable."""
        s = self.probability * np.minimum(self.face_px / face_target_px, 1.0)
        return np.where(self.framable, np.clip(np.nan_to_num(s), 0.0, 1.0), 0.0)


class CameraAssigner:
    """Assigns people to ``n_cameras`` PTZs every frame (see the module docstring)."""

    def __init__(self, n_cameras: int, dwell_s: float = 2.0, trust: TrustRule | None = None,
                 face_target_px: float = 180.0, hysteresis: float = HYSTERESIS, capacity: int = 32):
        if n_cameras < 1:
            raise ValueError(f"at least one PTZ, got {n_cameras}")
        self.dwell_s, self.trust, self.hysteresis = dwell_s, trust, hysteresis
        self.tau = max(dwell_s, MIN_TAU)
        self.face_target_px, self.capacity = face_target_px, capacity
        self.ghosts = GhostSites(trust) if trust is not None else None
        self.cameras = [CameraState() for _ in range(n_cameras)]
        self.captures = 0
        #: per PTZ, why it has no target this frame (``untrusted``, ``unframeable``, ``paused``; ``None``: it has one)
        self.held: list[str | None] = [None] * n_cameras
        #: frames on which two PTZs were on one person while a framable person had none (0 by construction)
        self.doubled_while_waiting = 0
        #: each covered person's PTZ in charge (track id -> PTZ): the first round's; a change is a hand-off
        self.primary: dict[int, int] = {}
        #: per PTZ, whether it holds on to a person whose track missed its detection this frame
        self.holding: list[bool] = [False] * n_cameras
        #: ``priority(xy) -> bool``: whether a floor point (m) lies in a priority zone (``None``: no zones)
        self.priority: Callable[[np.ndarray], bool] | None = None

    @property
    def n_cameras(self) -> int:
        return len(self.cameras)

    def warm_up(self) -> None:
        """Compile the assignment's one shape."""
        assign_exact(np.ones((self.n_cameras, 1)), np.ones((self.n_cameras, 1), bool), self.capacity)

    def candidates(self, t: float, tracks: list[Track]) -> list[Track]:
        """The trusted tracks (ghost sites updated first), in the order given."""
        if self.trust is None:
            return list(tracks)
        self.ghosts.update(t, tracks)
        return [tr for tr in tracks if is_trusted(tr, self.trust)]

    def choose(self, t: float, tracks: list[Track], settled: list[bool],
               pairs: Callable[[list[Track]], PairValues], manual: int | None = None,
               paused: bool = False, free: list[bool] | None = None, alive: list[Track] = ()) -> list[Track | None]:
        """Each PTZ's target at time ``t`` (the frame's stamp), ``None`` where it has none (``held`` says
        why). ``tracks``: the confirmed tracks (matched this frame: those the control call aimed at);
        ``settled[c]``: whether PTZ c has reached its last command; ``pairs(candidates)``: their
        :class:`PairValues`; ``manual``: the operator's chosen track (kept while some PTZ can frame it,
        trusted or not); ``paused``: no targets; ``free[c]``: False for a PTZ the operator points by hand
        (left out); ``alive``: every track the tracker still holds. A PTZ whose person's track missed its
        detection this frame but is still alive keeps them (``holding[c]``: it stays where it was sent)."""
        K = self.n_cameras
        free = [True] * K if free is None else list(free)
        live = {tr.id: tr for tr in [*alive, *tracks]}
        self._dwell(t, live, settled)
        confirmed = {tr.id for tr in tracks}
        self.holding = [f and not paused and cam.track in live and cam.track not in confirmed
                        for f, cam in zip(free, self.cameras)]
        present = bool(tracks)
        trusted = self.candidates(t, tracks)
        chosen = next((tr for tr in tracks if tr.id == manual), None) if manual is not None else None
        cands = trusted + ([chosen] if chosen is not None and chosen not in trusted else [])
        previous = dict(self.primary)
        targets: list[Track | None] = [live[cam.track] if h else None for cam, h in zip(self.cameras, self.holding)]
        primary = {cam.track: c for c, (cam, h) in enumerate(zip(self.cameras, self.holding))
                   if h and previous.get(cam.track) == c}
        assignable = [f and not h for f, h in zip(free, self.holding)]
        if paused or not cands:
            why = "paused" if paused and present else "untrusted" if present else None
            self.held = [why if f else None for f in assignable]
        else:
            for tr in cands:
                tr.extra.setdefault("last_framed", t)
            pv = pairs(cands)
            allowed = pv.framable & np.asarray(assignable)[:, None]
            first, cols = self._assign(t, cands, pv, allowed, chosen)
            targets = [cands[j] if j >= 0 else held for j, held in zip(cols, targets)]
            primary.update({cands[j].id: c for c, j in enumerate(first) if j >= 0})
            self.held = [None if not f or tr is not None else "unframeable" for tr, f in zip(targets, assignable)]
            self._check(cols, allowed)
        for c, (cam, tr) in enumerate(zip(self.cameras, targets)):
            new = None if tr is None else tr.id
            if new != cam.track:
                cam.track, cam.settled_at = new, None
            if tr is None and self.held[c] is not None:
                cam.held[self.held[c]] += 1
        for track, c in primary.items():  # the person's PTZ in charge changed: a hand-off
            before = previous.get(track)
            if before is not None and before != c:
                self.cameras[before].handed_over += 1
                self.cameras[c].handoffs += 1
        self.primary = primary
        return targets

    # -- the parts -----------------------------------------------------------------------------

    def _dwell(self, t: float, live: dict[int, Track], settled: list[bool]) -> None:
        """Each PTZ on its person: settling starts the dwell, the person counts as framed from then, and
        ``dwell_s`` after settling their face is captured."""
        for c, (cam, ok) in enumerate(zip(self.cameras, settled)):
            tr = live.get(cam.track)
            if tr is None or not ok:
                continue
            if cam.settled_at is None:
                cam.settled_at = t
            tr.extra["last_framed"] = t
            if t - cam.settled_at >= self.dwell_s and not tr.captured:
                tr.captured = True
                tr.extra["captured_by"] = c
                self.captures += 1

    def _locked(self, cam: CameraState, t: float) -> bool:
        return cam.track is not None and (cam.settled_at is None or t - cam.settled_at < self.dwell_s)

    def values(self, t: float, cands: list[Track], pv: PairValues) -> np.ndarray:
        """The values (K, n) of the module docstring, with the hysteresis of the PTZ in charge of each person."""
        need = np.array([1.0 + max(t - tr.extra.get("last_framed", t), 0.0) / self.tau for tr in cands])
        return self._reach(pv, self._in_charge(cands)) * need[None, :]

    def _reach(self, pv: PairValues, stay: np.ndarray) -> np.ndarray:
        """(K, n): the framing strength, times the slew factor and the hysteresis bonus where ``stay``."""
        slew = self.tau / (self.tau + np.maximum(pv.slew_s, 0.0))
        return pv.strength(self.face_target_px) * slew * (1.0 + self.hysteresis * stay)

    def _on(self, cands: list[Track]) -> np.ndarray:
        """(K, n): 1 where the PTZ is on that track already."""
        ids = np.array([tr.id for tr in cands])
        return np.array([ids == cam.track for cam in self.cameras], float)

    def _in_charge(self, cands: list[Track]) -> np.ndarray:
        """(K, n): 1 where the PTZ was the one in charge of that person (the first round's)."""
        return np.array([[self.primary.get(tr.id) == c for tr in cands] for c in range(self.n_cameras)], float)

    def _assign(self, t: float, cands: list[Track], pv: PairValues, allowed: np.ndarray,
                chosen: Track | None) -> tuple[np.ndarray, np.ndarray]:
        """Each PTZ's candidate index (-1: none) in the first round (the PTZs in charge: the lexicographic
        assignment of the module docstring, the most people first, :func:`assign_exact`) and after the
        rounds of the spare PTZs."""
        K, n = allowed.shape
        total = self.values(t, cands, pv)
        lock = np.array([self._locked(cam, t) for cam in self.cameras])[:, None] & (self._in_charge(cands) > 0)
        priority = np.array([self._first(tr) for tr in cands])
        manual = np.array([tr is chosen for tr in cands])
        for tier in (lock, np.broadcast_to(priority, (K, n)), np.broadcast_to(manual, (K, n))):
            total = total + (K * max(float(total.max()), 0.0) + 1.0) * tier  # outweighs any K pairs below it
        first = cols = assign_exact(total, allowed, self.capacity)
        strength, reach = pv.strength(self.face_target_px), self._reach(pv, self._on(cands))
        while True:  # spare PTZs, one round at a time: where they add the most expected capture
            left = cols < 0
            can = allowed & left[:, None]
            if not can.any():
                return first, cols
            extra = assign_exact(np.maximum(miss_probability(strength, cols), 1e-6)[None, :] * reach, can,
                                 self.capacity)
            if (extra < 0).all():
                return first, cols
            cols = np.where(left & (extra >= 0), extra, cols)

    def _first(self, track: Track) -> bool:
        return self.priority is not None and bool(self.priority(track.position))

    def _check(self, cols: np.ndarray, allowed: np.ndarray) -> None:
        """Count a frame with two PTZs on one person while a framable person (by one of them) had none."""
        taken = set(int(j) for j in cols if j >= 0)
        for j in taken:
            on = [c for c, x in enumerate(cols) if x == j]
            if len(on) > 1 and any(allowed[c, k] for c in on for k in range(allowed.shape[1]) if k not in taken):
                self.doubled_while_waiting += 1
                return

    def summary(self) -> list[dict]:
        """Per PTZ: ``id`` (the rig's order), ``handoffs``, ``handed_over``, ``held`` (frames without a target,
        by reason)."""
        return [{"id": c, "handoffs": cam.handoffs, "handed_over": cam.handed_over, "held": dict(cam.held)}
                for c, cam in enumerate(self.cameras)]


def miss_probability(strength: np.ndarray, cols: np.ndarray) -> np.ndarray:
    """Per person (n,), the probability that every PTZ assigned to them (``cols`` (K,): each PTZ's person,
    -1: none) misses them, the PTZs taken as independent with framing strengths ``strength`` (K, n)."""
    miss = np.ones(strength.shape[1])
    for c, j in enumerate(cols):
        if j >= 0:
            miss[j] *= 1.0 - strength[c, j]
    return miss
