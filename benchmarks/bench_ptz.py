"""PTZ output through the real stacks: round trip, fuzzing, unplug/reconnect, command latency, calibration.

Every figure goes driver -> pyserial -> pseudo-terminal -> `omnijax ptz-emulator`
(a separate process), or, for visca-ip, driver -> UDP on 127.0.0.1 -> `omnijax
ptz-emulator --protocol visca-ip`, with the shipped device profiles unless said otherwise.

- roundtrip: random targets within the device's limits, both protocols: commanded
  against reached (the camera's own position answer) pan, tilt (deg) and zoom.
- fuzz: >= 1e4 random and 1e4 mutated byte streams per parser (tests/ptz_fuzz.py).
- unplug: the emulator is SIGKILLed mid-motion and restarted on the same path
  (a symlink); time to reconnect, whether the last target set during the outage
  is reached, and that nothing is written or queued while the port is gone.
- latency: write-to-ACK (VISCA ACK, Pelco-D general response) over the pty or UDP,
  with the rate limit off and a new target every 2 ms; and how long set_target takes.
- fuzz-ip: 10,000 random and mutated datagrams to the VISCA over IP emulator and
  10,000 to the driver's UDP reply parser (tests/runtime/ptz/fuzz_ip.py).
- calibrate: `omnijax ptz calibrate` against a visca-ip emulator with --latency-ms
  set: fitted speeds and latency against the configured ones.

Run: `.venv/bin/python benchmarks/bench_ptz.py [--json] [--only SECTION ...]`.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import random
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

import numpy as np

from runtime.files import read_toml
from runtime.ptz import default_profile, make_driver, parse_profile
from runtime.ptz.profile import DEFAULT_PROFILES, resolve_profile_path
from runtime.ptz.transports import EMULATED, emulator_url
from tests.runtime.ptz import fuzz as ptz_fuzz, fuzz_ip

#: The emulated links: the serial protocols on a pty, and VISCA over IP on UDP.
PROTOCOLS = tuple(EMULATED)

OMNIJAX = str(Path(sys.executable).parent / "omnijax")


class Emulator:
    """`omnijax ptz-emulator` in its own process."""

    def __init__(self, protocol: str, link: Path | None = None, listen: str | None = None,
                 extra: tuple[str, ...] = ()) -> None:
        args = [OMNIJAX, "ptz-emulator", "--protocol", protocol, *extra]
        if link is not None and protocol != "visca-ip":
            args += ["--link", str(link)]
        if listen is not None:
            args += ["--listen", listen]
        self.proc = subprocess.Popen(args, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
        self.path = self.proc.stdout.readline().strip()
        self.ready = time.monotonic()
        self.listen = self.path.removeprefix("udp://") if protocol == "visca-ip" else None
        # what the driver opens: the stable link if any, else the printed address
        self.url = emulator_url(protocol, self.path) if protocol == "visca-ip" else str(link or self.path)

    def kill(self) -> None:
        os.kill(self.proc.pid, signal.SIGKILL)
        self.proc.wait()

    def close(self) -> None:
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGTERM)
            self.proc.wait()


def _percentiles(ms: list[float]) -> dict:
    a = np.asarray(ms)
    return {"p50": float(np.median(a)), "p99": float(np.percentile(a, 99)), "max": float(a.max()), "n": int(a.size)}


def _wait(cond, timeout: float, poll: float = 0.0005) -> bool:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if cond():
            return True
        time.sleep(poll)
    return cond()


def _random_target(profile, rng: random.Random) -> tuple[float, float, float]:
    """omnijax pan, tilt (rad) and zoom whose device angles lie inside the limits."""
    m = profile.mounting
    (p_lo, p_hi), (t_lo, t_hi) = profile.pan.limits_deg, profile.tilt.limits_deg
    pan_dev, tilt_dev = rng.uniform(p_lo, p_hi), rng.uniform(t_lo, t_hi)
    pan = math.radians((pan_dev - m.pan_zero_deg) * m.pan_direction)
    tilt = math.radians((tilt_dev - m.tilt_zero_deg) * m.tilt_direction)
    zoom = math.exp(rng.uniform(math.log(profile.zoom.magnification[0]), math.log(profile.zoom.magnification[-1])))
    return pan, tilt, zoom


def roundtrip(n_targets: int, seed: int) -> dict:
    out = {}
    for protocol in PROTOCOLS:
        profile = default_profile(EMULATED[protocol])
        rng = random.Random(seed)
        emu = Emulator(protocol)
        errs = {"pan_deg": [], "tilt_deg": [], "zoom_rel": [], "units": [], "seconds": []}
        reached = 0
        try:
            with make_driver(emu.url, profile) as ptz:
                for _ in range(n_targets):
                    pan, tilt, zoom = _random_target(profile, rng)
                    t = ptz.set_target(pan, tilt, zoom)
                    t0 = time.monotonic()
                    ok = ptz.wait_reached(timeout=30)
                    errs["seconds"].append(time.monotonic() - t0)
                    pos = ptz.query_position()
                    reached += ok and not t.clamped
                    d_pan = (pos.pan - pan + math.pi) % (2 * math.pi) - math.pi
                    errs["pan_deg"].append(abs(math.degrees(d_pan)))
                    errs["tilt_deg"].append(abs(math.degrees(pos.tilt - tilt)))
                    errs["zoom_rel"].append(abs(pos.zoom - zoom) / zoom)
                    errs["units"].append(max(profile.units_apart(a, u, v) for a, u, v in
                                             zip(("pan", "tilt", "zoom"), pos.units, (t.pan, t.tilt, t.zoom))))
                counters = ptz.counters
        finally:
            emu.close()
        out[protocol] = {
            "targets": n_targets, "reached": reached,
            "max_abs_error": {k: float(np.max(v)) for k, v in errs.items() if k != "seconds"},
            "mean_abs_error": {k: float(np.mean(v)) for k, v in errs.items() if k != "seconds"},
            "quantum_deg": {"pan": 1 / profile.pan.units_per_deg, "tilt": 1 / profile.tilt.units_per_deg},
            "seconds_to_reach": {"median": float(np.median(errs["seconds"])), "max": float(np.max(errs["seconds"]))},
            "ptz": counters,
        }
    return out


def fuzz(n: int, seed: int) -> dict:
    out = {}
    for name, kind in ptz_fuzz.KINDS.items():
        t0 = time.perf_counter()
        totals = ptz_fuzz.run(kind, n_random=n, n_mutated=n, seed=seed)
        totals["seconds"] = time.perf_counter() - t0
        out[name] = totals
    return out


def unplug(trials: int, outage_s: float, seed: int) -> dict:
    out = {}
    rng = random.Random(seed)
    for protocol in PROTOCOLS:
        profile = default_profile(EMULATED[protocol])
        rows = []
        set_ms: list[float] = []
        with tempfile.TemporaryDirectory() as tmp:
            link = Path(tmp) / "ptz"
            emu = Emulator(protocol, link)
            try:
                with make_driver(emu.url, profile) as ptz:
                    for _ in range(trials):
                        ptz.set_target(*_random_target(profile, rng))
                        time.sleep(0.3)                        # mid-motion
                        t_kill = time.monotonic()
                        emu.kill()
                        detected = _wait(lambda: not ptz.connected, 10)
                        t_detect = time.monotonic()
                        written = ptz.counters["commands"]
                        n_set = 0
                        refused = ptz.request_position().exception(timeout=0) is not None
                        while time.monotonic() < t_detect + outage_s:
                            target = _random_target(profile, rng)
                            t0 = time.perf_counter()
                            last = ptz.set_target(*target)
                            set_ms.append(1e3 * (time.perf_counter() - t0))
                            n_set += 1
                            time.sleep(0.001)
                        written_during = ptz.counters["commands"] - written
                        reconnects = ptz.counters["reconnects"]
                        emu = Emulator(protocol, link, listen=emu.listen)
                        _wait(lambda before=reconnects: ptz.counters["reconnects"] > before, 30)
                        t_conn = time.monotonic()
                        ok = ptz.wait_reached(timeout=30)
                        t_reached = time.monotonic()
                        pos = ptz.query_position()
                        rows.append({
                            "detect_s": t_detect - t_kill if detected else None,
                            "reconnect_after_restart_s": t_conn - emu.ready,
                            "reached_last_target": bool(ok and pos.units == (last.pan, last.tilt, last.zoom)),
                            "reach_after_reconnect_s": t_reached - t_conn,
                            "targets_set_during_outage": n_set,
                            "commands_written_during_outage": written_during,
                            "query_refused_at_once": refused,
                        })
                    counters = ptz.counters
            finally:
                emu.close()
        col = lambda k, rows=rows: [r[k] for r in rows]
        out[protocol] = {
            "trials": trials, "outage_s": outage_s,
            "reconnect_after_outage_start_s": _percentiles([r["detect_s"] + outage_s + r["reconnect_after_restart_s"]
                                                            for r in rows if r["detect_s"] is not None]),
            "reconnect_after_restart_s": {"median": float(np.median(col("reconnect_after_restart_s"))),
                                          "max": float(np.max(col("reconnect_after_restart_s")))},
            "detect_s_max": max(col("detect_s")),
            "reached_last_target": sum(col("reached_last_target")),
            "commands_written_during_outage": sum(col("commands_written_during_outage")),
            "targets_set_during_outage": sum(col("targets_set_during_outage")),
            "queries_refused_at_once": sum(col("query_refused_at_once")),
            "set_target_ms_during_outage": _percentiles(set_ms),
            "ptz": counters, "rows": rows,
        }
    return out


def latency(n: int) -> dict:
    out = {}
    for protocol in PROTOCOLS:
        mapping = read_toml(resolve_profile_path(DEFAULT_PROFILES[EMULATED[protocol]]), "device profile")
        mapping["link"] = {**mapping.get("link", {}), "min_interval_s": 0.0}
        profile = parse_profile(mapping, source="latency")
        emu = Emulator(protocol)
        try:
            set_ms = []
            with make_driver(emu.url, profile) as ptz:
                for i in range(n):
                    t0 = time.perf_counter()
                    ptz.set_target(math.radians(10.0 if i % 2 else -10.0), 0.0, 1.0)
                    set_ms.append(1e3 * (time.perf_counter() - t0))
                    time.sleep(0.002)  # pace the targets without polling the driver (which would perturb it)
                for _ in range(min(n, 500)):
                    ptz.query_position()
                s = ptz.stats()
        finally:
            emu.close()
        out[protocol] = {"write_to_ack_ms": s["latency_ms"]["ack"], "query_round_trip_ms": s["latency_ms"]["query"],
                         "set_target_ms": _percentiles(set_ms), "errors": s["errors"],
                         **({"transport": s["transport"]} if s.get("transport") else {})}
    return out


def fuzz_ip_section(n: int, seed: int) -> dict:
    return {"emulator": fuzz_ip.fuzz_emulator(n, seed), "driver_reply_parser": fuzz_ip.fuzz_port(n, seed + 1)}


def calibrate_section(latency_ms: float, moves: int) -> dict:
    from runtime.ptz.probe import calibrate

    profile = default_profile("visca")
    emu = Emulator("visca-ip", extra=("--latency-ms", f"{latency_ms:g}"))
    try:
        with make_driver(emu.url, profile) as ptz:
            fitted = calibrate(ptz, moves=moves)
    finally:
        emu.close()
    configured = {"pan.max_speed_deg_s": profile.pan.max_speed_deg_s,
                  "tilt.max_speed_deg_s": profile.tilt.max_speed_deg_s,
                  "zoom.seconds_full_range": profile.zoom.seconds_full_range,
                  "link.command_latency_s": latency_ms / 1e3}
    return {"moves_per_axis": moves, "fitted": fitted["profile"], "configured": configured,
            "relative_error": {k: fitted["profile"][k] / v - 1 for k, v in configured.items()},
            "per_axis": {a: fitted[a] for a in ("pan", "tilt", "zoom")}}


def main() -> None:
    global PROTOCOLS
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sections = ("roundtrip", "fuzz", "unplug", "latency", "fuzz-ip", "calibrate")
    ap.add_argument("--only", nargs="+", choices=sections, default=list(sections))
    ap.add_argument("--protocols", nargs="+", choices=PROTOCOLS, default=list(PROTOCOLS),
                    help="roundtrip, unplug, latency: the emulated links (default all)")
    ap.add_argument("--targets", type=int, default=25, help="roundtrip: random targets per protocol")
    ap.add_argument("--streams", type=int, default=10_000, help="fuzz: random and mutated streams each, per parser")
    ap.add_argument("--trials", type=int, default=5, help="unplug: kills per protocol")
    ap.add_argument("--outage", type=float, default=1.0, help="unplug: seconds the port stays gone")
    ap.add_argument("--commands", type=int, default=2000, help="latency: commands per protocol")
    ap.add_argument("--datagrams", type=int, default=10_000, help="fuzz-ip: datagrams each way")
    ap.add_argument("--latency-ms", type=float, default=30.0, help="calibrate: the emulator's command latency")
    ap.add_argument("--moves", type=int, default=3, help="calibrate: timed moves per axis")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    PROTOCOLS = tuple(args.protocols)
    runs = {"roundtrip": lambda: roundtrip(args.targets, args.seed), "fuzz": lambda: fuzz(args.streams, args.seed),
            "unplug": lambda: unplug(args.trials, args.outage, args.seed), "latency": lambda: latency(args.commands),
            "fuzz-ip": lambda: fuzz_ip_section(args.datagrams, args.seed),
            "calibrate": lambda: calibrate_section(args.latency_ms, args.moves)}
    report = {}
    for name in args.only:
        t0 = time.perf_counter()
        report[name] = runs[name]()
        print(f"{name}: {time.perf_counter() - t0:.1f} s", file=sys.stderr)
    print(json.dumps(report, indent=None if args.json else 2))


if __name__ == "__main__":
    main()
