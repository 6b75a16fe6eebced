"""Helpers for the PTZ tests: shipped profiles with quicker link timing, and event waits."""

from __future__ import annotations

import time
import tomllib
from collections.abc import Callable

from runtime.ptz.profile import DEFAULT_PROFILES, DEVICES_DIR, DeviceProfile, parse_profile


def profile_mapping(protocol: str) -> dict:
    with (DEVICES_DIR / f"{DEFAULT_PROFILES[protocol]}.toml").open("rb") as fh:
        return tomllib.load(fh)


def quick_profile(protocol: str, **link) -> DeviceProfile:
    """The shipped profile, 5x faster in motion, with a short reconnect back-off (and ``link`` keys overridden).

    Slew rates themselves are tested at the shipped speeds in test_ptz_emulator.py.
    """
    m = profile_mapping(protocol)
    for axis in ("pan", "tilt"):
        m[axis]["max_speed_deg_s"] *= 5
    m["zoom"]["seconds_full_range"] /= 5
    m["link"] = {**m.get("link", {}), "reconnect_backoff_s": [0.02, 0.2], **link}
    return parse_profile(m, source=f"quick {protocol}")


def wait_for(condition: Callable[[], bool], timeout: float = 20.0, poll: float = 0.01) -> bool:
    """Poll ``condition`` until it holds; generous time-outs, never a tight timing bound."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if condition():
            return True
        time.sleep(poll)
    return condition()
