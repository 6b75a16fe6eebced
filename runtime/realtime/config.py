"""The real-time loop's settings, written once: :class:`LoopConfig` is also the flags of ``run`` and ``demo``.

Each field made by :func:`runtime.settings.setting` becomes a command-line option with its
help, unit, allowed names and bounds (:func:`runtime.settings.add_options`); the same
metadata checks a config built in code. This module imports nothing heavy, so that the
command line can be built without JAX.
"""

from __future__ import annotations

from dataclasses import dataclass

from runtime.errors import UsageError
from runtime.settings import Names, check, setting


@dataclass(frozen=True)
class LoopConfig:
    """Settings of :class:`~runtime.realtime.loop.RealTimeLoop` (fields without a flag are fixed here)."""

    zoom_rule: str = setting("calibrated", "%(choices)s: the zoom rule that drives the PTZ (both are logged)",
                             metavar="RULE", choices=Names("omnijax.zoom:ZOOM_RULES"))
    tracker: str = setting("kalman", "%(choices)s: constant velocity with optimal assignment, or the paper's "
                           "nearest neighbour", metavar="NAME", choices=Names("runtime.realtime.tracker:TRACKERS"))
    target: str = setting("round-robin", "%(choices)s: over people with a dwell time, or follow one person",
                          metavar="MODE", choices=Names("runtime.realtime.targeting:TARGET_MODES"))
    dwell_s: float = setting(2.0, "seconds on each face once reached", unit="seconds", metavar="S", ge=0,
                             flag="--dwell")
    # 0.5, not 1: a held command lags a walker by up to K sigmas, about K^2 / 3 more mean square; at 1 the
    # loop's pan NEES was 1.21 over 90 people, at 0.5 0.90, for 1.44x the commands (docs/validation.md,
    # "The loop's pointing over ninety people")
    dead_zone_sd: float = setting(0.5, "send a new pan/tilt only when it moves by more than K standard deviations",
                                  unit="a number of standard deviations", metavar="K", ge=0)
    rate_wait_ms: float | None = setting(None, "hand a PTZ command only on a frame whose command would wait at most "
                                         "MS in the driver for the device's rate limit (its profile's "
                                         "link.min_interval_s), else hold it for the next frame's (counts.rate_held); "
                                         "default: every command, waiting for its slot (the head is predicted to "
                                         "the slot; docs/runtime.md)", unit="milliseconds", metavar="MS", ge=0)
    # when a track is trusted as a person and may get the PTZ (runtime.realtime.targeting.TrustRule)
    trust_hits: int = setting(8, "trust a track once detected in at least M of the last --trust-window frames",
                              unit="frames", metavar="M", ge=0)
    trust_window: int = setting(10, "the window of --trust-hits", unit="frames", metavar="N", gt=0)
    trust_age_s: float = setting(0.4, "trust a track only once it is at least S old", unit="seconds",
                                 metavar="S", ge=0)
    trust_travel_m: float = setting(0.5, "trust a track only once it has moved D from where it was born (a "
                                    "static blob on empty floor never does; 0: trust static tracks)",
                                    unit="metres", metavar="D", ge=0)
    # ghost sites (TrustRule): where an untrusted track stayed static this long, tracks within the radius lose
    # trust, until the site has not been seen for its life
    trust_site_s: float = 1.0
    trust_site_radius_m: float = 0.4
    trust_site_life_s: float = 10.0
    adapt_every: int = 2
    home: tuple[float, float, float] = (0.0, 0.0, 1.0)
    status_every_s: float = 0.5
    max_frames: int | None = setting(None, "stop after N processed frames", unit="frames", metavar="N", gt=0)
    max_seconds: float | None = setting(None, "stop after S seconds", unit="seconds", metavar="S", gt=0)
    quiet: bool = setting(False, "no live status line")

    def __post_init__(self):
        check(self)
        if self.trust_window > 32 or self.trust_hits > self.trust_window:
            raise UsageError(f"--trust-hits / --trust-window: expected M <= N <= 32 frames, got "
                             f"{self.trust_hits} of {self.trust_window}")
