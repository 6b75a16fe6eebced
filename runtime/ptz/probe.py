"""What a PTZ camera offers (``omnijax ptz probe``) and how fast it moves (``omnijax ptz calibrate``).

Both work through any driver that :func:`runtime.ptz.transports.make_driver` returns: they use
``capabilities()``, ``set_target``, ``query_position``, ``take_writes`` and ``stats()`` only.

:func:`probe` reads the driver's static :class:`~runtime.ptz.transports.Capabilities` and checks
the live ones: position read-back (a few inquiries, their round trip), and a small move (pan
by ``step_deg`` and back) for whether the camera moves, reports the end of a move, and ends
where it was told.

:func:`calibrate` times moves along each axis: it polls the position while the camera moves,
fits a straight line (least squares) to the samples strictly between the start and the end,
and takes the slope as the speed and the line's crossing of the start as the moment the motion
began; the command latency is that moment minus when the command's bytes went on the wire.
A pan/tilt sample is stamped half-way through its position inquiry, a zoom sample when its
reply arrives (the pan/tilt inquiry goes first, the zoom's second), so on a symmetric link a
latency is late by one one-way transit (emulator: exact, its delay is on the way in).
Each axis is timed ``moves`` times, alternating direction; speeds are reported at the speed
code the driver sends and, for the profile, scaled to the top code (VISCA speed codes are
linear in the profile's model).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np

from .errors import PtzError

#: Fraction of a move's span, at either end, whose samples are left out of the speed fit (acceleration,
#: and a sample that caught the start or the end).
_EDGE = 0.05
#: Fewest samples strictly inside a move for a fit.
_MIN_SAMPLES = 4


@dataclass
class AxisFit:
    """One axis's timed moves: speed (device deg/s, or zoom positions/s) and latency (s) per move."""

    axis: str
    speeds: list[float] = field(default_factory=list)
    latencies: list[float] = field(default_factory=list)
    samples: list[int] = field(default_factory=list)

    @property
    def speed(self) -> float:
        return float(np.median(self.speeds)) if self.speeds else math.nan

    @property
    def latency(self) -> float:
        return float(np.median(self.latencies)) if self.latencies else math.nan

    def as_dict(self) -> dict:
        return {"speed": self.speed, "latency_s": self.latency, "speeds": self.speeds,
                "latencies_s": self.latencies, "samples": self.samples}


def _geo(profile, pan_dev_deg: float, tilt_dev_deg: float) -> tuple[float, float]:
    """omnijax pan, tilt (rad) that the profile maps to device angles ``pan_dev_deg``, ``tilt_dev_deg``."""
    m = profile.mounting
    return (math.radians((pan_dev_deg - m.pan_zero_deg) * m.pan_direction),
            math.radians((tilt_dev_deg - m.tilt_zero_deg) * m.tilt_direction))


def _device_deg(profile, pos) -> tuple[float, float]:
    pan_u, tilt_u, _ = pos.units
    return pan_u / profile.pan.units_per_deg, tilt_u / profile.tilt.units_per_deg


def _goto(driver, profile, pan_deg: float, tilt_deg: float, zoom: float, timeout: float) -> None:
    driver.set_target(*_geo(profile, pan_deg, tilt_deg), zoom)
    if not driver.wait_reached(timeout):
        raise PtzError(f"{driver.port}: did not reach pan {pan_deg:g} deg, tilt {tilt_deg:g} deg, zoom {zoom:g}x "
                       f"within {timeout:g} s")


# ----------------------------------------------------------------------------------------
# Probe
# ----------------------------------------------------------------------------------------


def probe(driver, step_deg: float = 1.0, inquiries: int = 5, timeout: float = 10.0) -> dict:
    """The camera's capabilities, the live checks, and a verdict (``drivable``, ``how``, ``why``)."""
    caps = driver.capabilities()
    profile = driver.profile
    report: dict = {"capabilities": caps.as_dict(), "checks": {}}
    checks = report["checks"]
    rtts = []
    pos = None
    for _ in range(inquiries):
        t0 = time.perf_counter()
        try:
            pos = driver.query_position(timeout=2.0)
        except (PtzError, TimeoutError) as exc:
            checks["position"] = {"ok": False, "error": str(exc) or "no answer"}
            break
        rtts.append(1e3 * (time.perf_counter() - t0))
    else:
        checks["position"] = {"ok": True, "rtt_ms": {"p50": float(np.median(rtts)), "max": float(np.max(rtts))},
                              "pan_deg": pos.pan_deg, "tilt_deg": pos.tilt_deg, "zoom": pos.zoom}
    if pos is not None and checks["position"]["ok"]:
        pan_dev, tilt_dev = _device_deg(profile, pos)
        lo, hi = profile.pan.limits_deg
        step = step_deg if pan_dev + step_deg <= hi else -step_deg
        before = driver.stats()
        t0 = time.monotonic()
        try:
            _goto(driver, profile, pan_dev + step, tilt_dev, pos.zoom, timeout)
            moved_s = time.monotonic() - t0
            after = driver.stats()
            _goto(driver, profile, pan_dev, tilt_dev, pos.zoom, timeout)
            checks["move"] = {"ok": True, "step_deg": step, "seconds": moved_s,
                              "completions": after.get("completions", 0) - before.get("completions", 0),
                              "errors": after["errors"] - before["errors"]}
        except (PtzError, TimeoutError) as exc:
            checks["move"] = {"ok": False, "step_deg": step, "error": str(exc) or "no answer"}
    stats = driver.stats()
    report["link"] = {k: stats[k] for k in ("commands", "errors", "reconnects")}
    if "transport" in stats:
        report["link"]["transport"] = stats["transport"]
    report["verdict"] = _verdict(caps, checks)
    return report


def _verdict(caps, checks: dict) -> dict:
    why = []
    if not checks.get("position", {}).get("ok"):
        why.append("the camera does not report its position")
    if not checks.get("move", {}).get("ok"):
        why.append("a 1-step move did not end where it was sent" if "move" in checks else "no move was tried")
    modes = set(caps.move_modes)
    if "absolute" in modes:
        how = "absolute moves"
    elif modes & {"relative", "continuous"}:
        how = f"{sorted(modes & {'relative', 'continuous'})[0]} moves with a position estimate"
    else:
        how = ""
        why.append("no move mode omnijax can use")
    status = {"completion": "completion replies", "status": "polled move status",
              "timer": "a timer from the profile's slew rates"}.get(caps.move_status, caps.move_status)
    if checks.get("move", {}).get("ok") and caps.move_status == "completion" and not checks["move"]["completions"]:
        why.append("no completion reply arrived for the test move")
    drivable = not why
    return {"drivable": drivable,
            "how": f"{how}, end of move from {status}, over {caps.transport} ({caps.protocol})" if drivable else "",
            "why": why}


def probe_table(report: dict, url: str) -> str:
    """The probe report as the table ``omnijax ptz probe`` prints."""
    c, k = report["capabilities"], report["checks"]
    pos, move = k.get("position", {}), k.get("move", {})
    rows = [
        ("camera", f"{url} ({c['protocol']} over {c['transport']})"),
        ("move modes", ", ".join(c["move_modes"])),
        ("move status", c["move_status"]),
        ("position read-back", (f"yes, round trip p50 {pos['rtt_ms']['p50']:.1f} ms" if pos.get("ok")
                                else f"NO ({pos.get('error', 'not tried')})")),
        ("test move", (f"pan {move['step_deg']:+g} deg and back: {move['seconds']:.2f} s, "
                       f"{move['completions']} completion(s), {move['errors']} error(s)" if move.get("ok")
                       else f"FAILED ({move.get('error', 'not tried')})")),
        ("zoom range", f"{c['zoom'][0]:g}x - {c['zoom'][1]:g}x"),
        ("pan limits", "{:g} .. {:g} deg".format(*c["limits_deg"]["pan"])),
        ("tilt limits", "{:g} .. {:g} deg".format(*c["limits_deg"]["tilt"])),
    ]
    rows += [("note", n) for n in c.get("notes", ())]
    v = report["verdict"]
    rows.append(("verdict", f"drivable: {v['how']}" if v["drivable"] else "NOT drivable: " + "; ".join(v["why"])))
    width = max(len(r[0]) for r in rows)
    return "\n".join(f"{name:<{width}}  {value}" for name, value in rows)


# ----------------------------------------------------------------------------------------
# Calibrate
# ----------------------------------------------------------------------------------------


def fit_move(samples: list[tuple[float, float]], start: float, end: float, t_write: float) -> tuple[float, float]:
    """(speed, latency) of one move from ``(time, position)`` samples: the least-squares line through
    the samples strictly inside the move (away from either end by :data:`_EDGE` of the span), its slope
    (positive, position units/s) and where it crosses ``start`` minus ``t_write`` (s).
    ``ValueError`` if too few samples lie inside the move."""
    span = end - start
    inside = [(t, p) for t, p in samples
              if _EDGE < (p - start) / span < 1 - _EDGE]
    if len(inside) < _MIN_SAMPLES:
        raise ValueError(f"only {len(inside)} position samples during the move (need {_MIN_SAMPLES}); "
                         "use a longer move or a faster link")
    t, p = np.array(inside).T
    slope, intercept = np.polyfit(t - t_write, p, 1)
    return abs(float(slope)), float((start - intercept) / slope)


def _timed_move(driver, profile, axis: str, start, end, timeout: float) -> tuple[float, float, int]:
    """Go to ``start`` (pan_deg, tilt_deg, zoom), then to ``end`` while polling; (speed, latency, samples)."""
    _goto(driver, profile, *start, timeout)
    driver.take_writes()
    driver.set_target(*_geo(profile, end[0], end[1]), end[2])
    seq = driver.sequence
    samples: list[tuple[float, float]] = []
    index = {"pan": 0, "tilt": 1, "zoom": 2}[axis]
    target = driver.target
    goal = (target.pan, target.tilt, target.zoom)[index]
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        t0 = time.monotonic()
        pos = driver.query_position(timeout=2.0)
        at = time.monotonic()
        value = pos.units[index]
        # pan and tilt are asked first, the zoom last (VISCA: two inquiries in turn)
        samples.append((at if axis == "zoom" else 0.5 * (t0 + at), float(value)))
        if profile.units_apart(axis, value, goal) <= 1:
            break
    else:
        raise PtzError(f"{driver.port}: {axis} did not reach its end within {timeout:g} s")
    writes = [t for s, t in driver.take_writes() if s == seq]
    if not writes:
        raise PtzError(f"{driver.port}: the {axis} move was never written")
    start_units = {"pan": lambda: round(start[0] * profile.pan.units_per_deg),
                   "tilt": lambda: round(start[1] * profile.tilt.units_per_deg),
                   "zoom": lambda: round(profile.zoom_position(start[2]))}[axis]()
    speed, latency = fit_move(samples, float(start_units), float(goal), writes[0])
    return speed, latency, len(samples)


def calibrate(driver, moves: int = 2, span: float = 0.8, timeout: float = 60.0) -> dict:
    """Time ``moves`` moves per axis over ``span`` of its range (centred); the fitted figures.

    Returns {``pan``, ``tilt``, ``zoom``: :meth:`AxisFit.as_dict` (speeds in device deg/s at the
    sent speed code, zoom in positions/s), ``command_latency_s`` (median of all moves),
    ``profile``: the values for the device profile (``max_speed_deg_s`` per axis, scaled to the
    top speed code, ``seconds_full_range``, ``command_latency_s``)}.
    """
    if not 0 < span <= 1:
        raise ValueError(f"span: expected a fraction of the range in (0, 1], got {span}")
    p = driver.profile
    pos = driver.query_position(timeout=2.0)
    home_pan, home_tilt = _device_deg(p, pos)
    zoom_mid = math.sqrt(p.zoom.magnification[0] * p.zoom.magnification[-1])

    def ends(limits, centre_ok):
        lo, hi = limits
        c = 0.5 * (lo + hi) if centre_ok else 0.0
        half = 0.5 * span * (hi - lo)
        return max(lo, c - half), min(hi, c + half)

    pan_ends = ends(p.pan.limits_deg, True)
    tilt_ends = ends(p.tilt.limits_deg, True)
    tilt_level = min(max(0.0, p.tilt.limits_deg[0]), p.tilt.limits_deg[1])
    pan_centre = min(max(0.0, p.pan.limits_deg[0]), p.pan.limits_deg[1])
    z = p.zoom.magnification
    zoom_ends = (z[0], z[0] + span * (z[-1] - z[0]))
    fits = {}
    plans = {
        "pan": [((a, tilt_level, zoom_mid), (b, tilt_level, zoom_mid)) for a, b in [pan_ends, pan_ends[::-1]]],
        "tilt": [((pan_centre, a, zoom_mid), (pan_centre, b, zoom_mid)) for a, b in [tilt_ends, tilt_ends[::-1]]],
        "zoom": [((pan_centre, tilt_level, a), (pan_centre, tilt_level, b)) for a, b in [zoom_ends, zoom_ends[::-1]]],
    }
    for axis, plan in plans.items():
        fit = AxisFit(axis)
        for i in range(moves):
            start, end = plan[i % 2]
            speed, latency, n = _timed_move(driver, p, axis, start, end, timeout)
            if axis != "zoom":
                speed /= getattr(p, axis).units_per_deg
            fit.speeds.append(speed)
            fit.latencies.append(latency)
            fit.samples.append(n)
        fits[axis] = fit
    _goto(driver, p, home_pan, home_tilt, pos.zoom, timeout)
    latency = float(np.median([x for f in fits.values() for x in f.latencies]))
    zoom_span = p.zoom.position[-1] - p.zoom.position[0]
    out = {axis: f.as_dict() for axis, f in fits.items()}
    out["command_latency_s"] = latency
    out["profile"] = {
        "pan.max_speed_deg_s": _top(p.pan, fits["pan"].speed),
        "tilt.max_speed_deg_s": _top(p.tilt, fits["tilt"].speed),
        "zoom.seconds_full_range": zoom_span / fits["zoom"].speed,
        "link.command_latency_s": max(0.0, latency),
    }
    return out


def _top(axis, speed: float) -> float:
    """The slew rate at the top speed code, from ``speed`` measured at the code the driver sends."""
    if axis.max_speed and axis.speed:
        return speed * axis.max_speed / axis.speed
    return speed


def calibrated_profile_text(source_text: str, fitted: dict, header: str) -> str:
    """The profile's TOML with the fitted values in place (comments kept), headed by ``header``."""
    import tomlkit

    doc = tomlkit.parse(source_text)
    for dotted, value in fitted.items():
        section, key = dotted.split(".")
        if section not in doc:
            doc[section] = tomlkit.table()
        doc[section][key] = round(float(value), 4)
    return "".join(f"# {line}\n" for line in header.splitlines()) + tomlkit.dumps(doc)
