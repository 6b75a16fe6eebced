"""Faults injected into a running loop (``--faults``), to show that it keeps going and counts each.

A plan is a comma-separated list of events at frame indices of the source::

    broken@120,wrong-size@200,ptz-unplug@300:2.0,end@900

- ``broken@N``: frame N is delivered broken (the source failed to read it);
- ``wrong-size@N``: frame N arrives at half the expected size;
- ``ptz-unplug@N:S``: when frame N is processed the PTZ port vanishes for S seconds (default 2)
  and then returns on the same path (the demo's emulator is killed and restarted);
- ``end@N``: the source ends before frame N.

``@N`` may be repeated for every kind but ``end``.
"""

from __future__ import annotations

from dataclasses import dataclass, field

KINDS = ("broken", "wrong-size", "ptz-unplug", "end")


@dataclass
class FaultPlan:
    """Frame indices of each injected fault; ``ptz_unplug`` maps a frame index to the outage (s)."""

    broken: set[int] = field(default_factory=set)
    wrong_size: set[int] = field(default_factory=set)
    ptz_unplug: dict[int, float] = field(default_factory=dict)
    end: int | None = None

    @classmethod
    def parse(cls, text: str) -> FaultPlan:
        """From ``"broken@120,ptz-unplug@300:2"``; a bad entry is a one-line ``ValueError``."""
        plan = cls()
        for item in filter(None, (s.strip() for s in text.split(","))):
            kind, at, where = item.partition("@")
            if kind not in KINDS or not at:
                raise ValueError(f"{item!r}: expected KIND@FRAME with KIND one of {', '.join(KINDS)}")
            frame, _, seconds = where.partition(":")
            try:
                n = int(frame)
                s = float(seconds) if seconds else 2.0
            except ValueError:
                raise ValueError(f"{item!r}: expected a frame index (and for ptz-unplug ':SECONDS')") from None
            if n < 0 or not 0 < s <= 60 or (seconds and kind != "ptz-unplug"):
                raise ValueError(f"{item!r}: expected a frame index >= 0 (and for ptz-unplug 0 < SECONDS <= 60)")
            if kind == "broken":
                plan.broken.add(n)
            elif kind == "wrong-size":
                plan.wrong_size.add(n)
            elif kind == "ptz-unplug":
                plan.ptz_unplug[n] = s
            else:
                plan.end = n
        return plan

    @property
    def empty(self) -> bool:
        return not (self.broken or self.wrong_size or self.ptz_unplug) and self.end is None

    def describe(self) -> dict:
        """The plan as JSON (what the summary reports as injected)."""
        return {"broken_frames": sorted(self.broken), "wrong_size_frames": sorted(self.wrong_size),
                "ptz_unplug": [{"frame": k, "seconds": v} for k, v in sorted(self.ptz_unplug.items())],
                "end_at_frame": self.end}
