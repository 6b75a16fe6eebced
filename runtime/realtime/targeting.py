"""Which person the PTZ looks at, and whether a new command is worth sending.

- :class:`TargetSelector`: ``round-robin`` (default) keeps a target until the PTZ has dwelt on it
  for ``dwell_s`` after settling, marks its face captured, and moves on, preferring people whose
  face was not yet captured (longest-waiting first); ``single`` follows one person until lost.
- :func:`outside_dead_zone`: a new pan/tilt is sent only when it moves by more than ``k`` standard
  deviations of the propagated pointing uncertainty (or the zoom by more than ``zoom_rel``), so
  that the PTZ does not hunt after noise.
"""

from __future__ import annotations

import math

from omnijax.geometry import wrap_pi
from runtime.realtime.tracker import Track

#: How the target is chosen (``LoopConfig.target``, ``--target``).
TARGET_MODES: tuple[str, ...] = ("round-robin", "single")


class TargetSelector:
    """Chooses the target track (see the module docstring)."""

    def __init__(self, mode: str = "round-robin", dwell_s: float = 2.0):
        if mode not in TARGET_MODES:
            raise ValueError(f"target mode must be one of {TARGET_MODES}, got {mode!r}")
        self.mode, self.dwell_s = mode, dwell_s
        self.current: int | None = None
        self.settled_at: float | None = None
        self.captures = 0

    def choose(self, t: float, tracks: list[Track], settled: bool) -> Track | None:
        """The track to aim at at time ``t``; ``settled`` says whether the PTZ has reached the last command."""
        by_id = {tr.id: tr for tr in tracks}
        cur = by_id.get(self.current)
        if cur is not None:
            if settled and self.settled_at is None:
                self.settled_at = t
            dwelt = self.settled_at is not None and t - self.settled_at >= self.dwell_s
            if dwelt and not cur.captured:
                cur.captured = True
                self.captures += 1
            if self.mode == "single" or not dwelt or len(tracks) == 1:
                return cur
        candidates = [tr for tr in tracks if tr.id != self.current] or tracks
        if not candidates:
            self.current, self.settled_at = None, None
            return None
        nxt = min(candidates, key=lambda tr: (tr.captured, tr.extra.get("last_targeted", -math.inf), tr.id))
        if cur is not None:
            cur.extra["last_targeted"] = t
        self.current, self.settled_at = nxt.id, None
        return nxt


def outside_dead_zone(new: tuple[float, float, float], sent: tuple[float, float, float] | None,
                      sd_pan: float, sd_tilt: float, k: float = 1.0, zoom_rel: float = 0.08) -> bool:
    """Whether ``new`` (pan, tilt rad, zoom) differs from the ``sent`` command enough to send it."""
    if sent is None:
        return True
    d_pan = abs(wrap_pi(new[0] - sent[0]))
    return (d_pan > k * sd_pan or abs(new[1] - sent[1]) > k * sd_tilt
            or abs(math.log(new[2] / sent[2])) > zoom_rel)
