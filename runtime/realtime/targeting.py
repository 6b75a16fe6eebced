"""Which person the PTZ looks at, and whether a new command is worth sending.

- :class:`TargetSelector`: ``round-robin`` (default) keeps a target until the PTZ has dwelt on it
  for ``dwell_s`` after settling, marks its face captured, and moves on, preferring people whose
  face was not yet captured (longest-waiting first); ``single`` follows one person until lost.
  Only *trusted* tracks (:func:`is_trusted`, under a :class:`TrustRule`) that the PTZ *can frame*
  (the caller's ``framable`` test, :func:`can_frame` on the aim) are targeted; when tracks exist
  but none qualifies, the selector holds (no target) and says why in ``held``: ``"untrusted"``
  or ``"unframeable"``. People in a *priority* zone (``priority``, from the rig's ``[[zones]]``)
  come first, and take the PTZ from a target outside one at once. The operator may choose the
  target (``manual``: kept while it is there and can be framed, trusted or not) or pause the
  automatic choice (``paused``: no target, ``held`` is ``"paused"``).
- :func:`outside_dead_zone`: a new pan/tilt is sent only when it moves by more than ``k`` standard
  deviations of the propagated pointing uncertainty (or the zoom by more than ``zoom_rel``), so
  that the PTZ does not hunt after noise.

All times are the frames' own stamps (``Frame.stamp``), never the wall clock, so that a run that
processes every frame (``--pace all``) chooses the same targets every time.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from omnijax.geometry import wrap_pi
from runtime.realtime.tracker import HISTORY, Track

#: How the target is chosen (``LoopConfig.target``, ``--target``).
TARGET_MODES: tuple[str, ...] = ("round-robin", "single")
#: Why the selector holds with tracks present (``TargetSelector.held``).
HOLD_REASONS: tuple[str, ...] = ("untrusted", "unframeable", "paused")


@dataclass(frozen=True)
class TrustRule:
    """When a track is trusted as a person (the PTZ is never spent on a track before).

    A track is trusted once it has been detected in at least ``hits`` of the last ``window``
    frames (M of N), is at least ``min_age_s`` old, and its filtered position has moved at least
    ``min_travel_m`` from where it was born (a person walks; a static blob on empty floor, such
    as a ghost the background left behind, does not). Trust is kept for the track's life, so a
    person who stops walking stays a target; someone standing still from their first frame is not
    targeted until they move. ``hits = 0``, ``min_age_s = 0`` and ``min_travel_m = 0`` trust
    every confirmed track (the behaviour before trust existed).

    Ghost sites (:class:`GhostSites`): a place where an untrusted track has stayed static (moved
    less than ``min_travel_m`` from its origin, where it was born or last lost its trust) for
    ``site_s`` seconds is a ghost site until ``site_life_s`` after
    such a track was last seen there. A track within ``site_radius_m`` of a ghost site loses its
    trust and starts its travel anew from there: a trusted track that took over a ghost's
    detections when its person walked past (and stays on the ghost while the person walks on) is
    no longer targeted, and a person passing a ghost site is targeted again once ``min_travel_m``
    beyond it. ``site_radius_m = 0`` turns ghost sites off.
    """

    hits: int = 8
    window: int = 10
    min_age_s: float = 0.4
    min_travel_m: float = 0.5
    site_s: float = 1.0
    site_radius_m: float = 0.4
    site_life_s: float = 10.0

    def __post_init__(self):
        if not 1 <= self.window <= HISTORY:
            raise ValueError(f"trust window must be 1 to {HISTORY} frames, got {self.window}")
        if not 0 <= self.hits <= self.window:
            raise ValueError(f"trust hits must be 0 to the window ({self.window}), got {self.hits}")
        if min(self.min_age_s, self.min_travel_m, self.site_s, self.site_radius_m, self.site_life_s) < 0:
            raise ValueError(f"trust times and distances must be >= 0, got {self}")


def trust_rule(config) -> TrustRule:
    """The :class:`TrustRule` of a :class:`~runtime.realtime.config.LoopConfig` (its ``trust_*`` fields)."""
    return TrustRule(hits=config.trust_hits, window=config.trust_window, min_age_s=config.trust_age_s,
                     min_travel_m=config.trust_travel_m, site_s=config.trust_site_s,
                     site_radius_m=config.trust_site_radius_m, site_life_s=config.trust_site_life_s)


def is_trusted(track: Track, rule: TrustRule) -> bool:
    """Whether ``track`` is trusted under ``rule`` (see :class:`TrustRule`); once true, it stays true
    (``track.trusted``)."""
    if not track.trusted:
        hits = bin(track.recent & ((1 << rule.window) - 1)).count("1")
        track.trusted = (hits >= rule.hits and track.t - track.born >= rule.min_age_s
                         and track.travel >= rule.min_travel_m)
    return track.trusted


def distrust(track: Track) -> None:
    """Take ``track``'s trust away: it must move ``min_travel_m`` from where it is now to regain it."""
    track.trusted = False
    track.origin, track.origin_t = np.array(track.position, float), track.t
    track.travel = 0.0


class GhostSites:
    """Places where untrusted tracks stayed static (see :class:`TrustRule`): ``sites`` rows are
    (x, y, time last seen)."""

    def __init__(self, rule: TrustRule):
        self.rule = rule
        self.sites = np.zeros((0, 3))

    def update(self, t: float, tracks: list[Track]) -> None:
        """Mark or refresh a site under each static untrusted track, forget sites not seen for
        ``site_life_s``, and take the trust of every track on a site away (:func:`distrust`)."""
        r = self.rule
        if r.site_radius_m <= 0:
            return
        for tr in tracks:
            if not tr.trusted and tr.travel < r.min_travel_m and tr.t - tr.origin_t >= r.site_s:
                d = np.hypot(*(self.sites[:, :2] - tr.position).T) if len(self.sites) else np.zeros(0)
                if d.size and d.min() <= r.site_radius_m:
                    self.sites[np.argmin(d), 2] = t
                else:
                    self.sites = np.vstack([self.sites, [*tr.position, t]])
        self.sites = self.sites[t - self.sites[:, 2] <= r.site_life_s]
        for tr in tracks:
            if self.near(tr.position):
                distrust(tr)

    def near(self, xy) -> bool:
        """Whether floor point ``xy`` (m) is within ``site_radius_m`` of a ghost site."""
        return bool(len(self.sites)) and bool(
            np.hypot(*(self.sites[:, :2] - np.asarray(xy)).T).min() <= self.rule.site_radius_m)


def can_frame(aimed, rule: str) -> bool:
    """Whether an :class:`~omnijax.aiming.Aim` can be framed as promised: the pointing is valid (not
    at the PTZ's foot nor beyond its tilt range) and zoom rule ``rule`` reaches ``p_contain``."""
    return bool(aimed.pointing.valid) and bool(aimed.zooms[rule].feasible)


class TargetSelector:
    """Chooses the target track (see the module docstring)."""

    def __init__(self, mode: str = "round-robin", dwell_s: float = 2.0, trust: TrustRule | None = None):
        if mode not in TARGET_MODES:
            raise ValueError(f"target mode must be one of {TARGET_MODES}, got {mode!r}")
        self.mode, self.dwell_s, self.trust = mode, dwell_s, trust
        self.ghosts = GhostSites(trust) if trust is not None else None
        self.current: int | None = None
        self.settled_at: float | None = None
        self.captures = 0
        self.held: str | None = None
        #: ``priority(xy) -> bool``: whether a floor point (m) lies in a priority zone (``None``: no zones)
        self.priority: Callable[[np.ndarray], bool] | None = None

    def _first(self, track: Track) -> bool:
        return self.priority is not None and bool(self.priority(track.position))

    def _dwell(self, t: float, cur: Track, settled: bool) -> bool:
        """Whether the PTZ has dwelt on ``cur`` for ``dwell_s`` since settling; marks its face captured then."""
        if settled and self.settled_at is None:
            self.settled_at = t
        dwelt = self.settled_at is not None and t - self.settled_at >= self.dwell_s
        if dwelt and not cur.captured:
            cur.captured = True
            self.captures += 1
        return dwelt

    def choose(self, t: float, tracks: list[Track], settled: bool,
               framable: Callable[[Track], bool] | None = None, manual: int | None = None,
               paused: bool = False) -> Track | None:
        """The track to aim at at time ``t`` (the frame's stamp); ``settled`` says whether the PTZ has
        reached the last command, ``framable(track)`` whether the PTZ can frame it (default: all can);
        ``manual`` the operator's choice, ``paused`` whether the operator paused the automatic choice.
        Untrusted tracks are never chosen automatically; ``held`` says why there is no target while
        tracks exist."""
        self.held = None
        present, everyone = bool(tracks), tracks
        if self.trust is not None:
            self.ghosts.update(t, tracks)
            tracks = [tr for tr in tracks if is_trusted(tr, self.trust)]
        ok = framable or (lambda _tr: True)
        if paused:
            self.current, self.settled_at = None, None
            self.held = "paused" if present else None
            return None
        chosen = next((tr for tr in everyone if tr.id == manual), None) if manual is not None else None
        if chosen is not None and ok(chosen):
            if self.current != chosen.id:
                self.current, self.settled_at = chosen.id, None
            self._dwell(t, chosen, settled)
            return chosen
        cur = next((tr for tr in tracks if tr.id == self.current), None)
        cur_ok = cur is not None and ok(cur)
        if cur_ok:
            dwelt = self._dwell(t, cur, settled)
            waiting = not self._first(cur) and any(tr.id != cur.id and self._first(tr) and ok(tr) for tr in tracks)
            if (self.mode == "single" or not dwelt) and not waiting:
                return cur
        others = sorted((tr for tr in tracks if tr.id != self.current),
                        key=lambda tr: (not self._first(tr), tr.captured, tr.extra.get("last_targeted", -math.inf),
                                        tr.id))
        for nxt in others:
            if ok(nxt):
                if cur is not None:
                    cur.extra["last_targeted"] = t
                self.current, self.settled_at = nxt.id, None
                return nxt
        if cur_ok:  # dwelt, but nobody else can be framed: stay
            return cur
        if cur is not None:
            cur.extra["last_targeted"] = t
        self.current, self.settled_at = None, None
        self.held = "unframeable" if tracks else "untrusted" if present else None
        return None


def outside_dead_zone(new: tuple[float, float, float], sent: tuple[float, float, float] | None,
                      sd_pan: float, sd_tilt: float, k: float = 1.0, zoom_rel: float = 0.08) -> bool:
    """Whether ``new`` (pan, tilt rad, zoom) differs from the ``sent`` command enough to send it."""
    if sent is None:
        return True
    d_pan = abs(wrap_pi(new[0] - sent[0]))
    return (d_pan > k * sd_pan or abs(new[1] - sent[1]) > k * sd_tilt
            or abs(math.log(new[2] / sent[2])) > zoom_rel)
