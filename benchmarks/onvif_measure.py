"""ONVIF end to end: `omnijax ptz` round trips through `omnijax ptz-emulator --protocol onvif`, and an outage.

    python benchmarks/onvif_measure.py [--targets 4] [--json OUT]

Round trips: for each emulator set-up (plain, with WS-Security, and each firmware quirk) an
emulator process on 127.0.0.1 and a free port, then `omnijax ptz --ptz onvif://... --pan-deg
--tilt-deg --zoom --json` per target (the real CLI, a new process and session each time); a
target counts as reached when the CLI says so (exit 0) *and* the emulator's state file shows
the camera within one device unit of the target on every axis.

Outage: a driver streams targets at 25 Hz (a person walking past) to an in-process emulator,
which is closed for 2 s and then serves again on the same port: reconnect time after the
camera is back, targets set during the outage (superseded: only the latest matters), and
whether the latest target is on the wire after the reconnect and reached.
"""

import argparse
import json
import logging
import math
import os
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from runtime.ptz.onvif import OnvifDriver
from runtime.ptz.onvif_emulator import OnvifEmulator
from runtime.ptz.profile import default_profile

SETUPS = [
    ("plain", [], ""),
    ("auth", ["--user", "admin", "--password", "s3cret"], "admin:s3cret@"),
    ("relative-only,no-move-status", ["--quirks", "relative-only,no-move-status"], ""),
    ("continuous-only", ["--quirks", "continuous-only"], ""),
    ("always-moving", ["--quirks", "always-moving"], ""),
]
TARGETS = [(30.0, 10.0, 3.0), (-120.0, 45.0, 12.0), (150.0, -25.0, 1.0), (0.0, 0.0, 18.0), (-60.0, 80.0, 6.5),
           (90.0, 20.0, 2.0)]


def round_trips(n_targets: int) -> dict:
    profile = default_profile("onvif")
    cli = [sys.executable, "-m", "runtime.cli"]
    out = {}
    for name, flags, creds in SETUPS:
        with tempfile.TemporaryDirectory() as tmp:
            state = Path(tmp) / "state.json"
            em = subprocess.Popen([*cli, "ptz-emulator", "--protocol", "onvif", "--state-file", str(state),
                                   "--parent-pid", str(os.getpid()), *flags], stdout=subprocess.PIPE,
                                  stderr=subprocess.DEVNULL, text=True, cwd=ROOT)
            try:
                url = em.stdout.readline().strip()
                port = url.split(":")[2].split("/")[0]
                reached, seconds = 0, []
                for pan, tilt, zoom in TARGETS[:n_targets]:
                    t0 = time.perf_counter()
                    r = subprocess.run([*cli, "ptz", "--ptz", f"onvif://{creds}127.0.0.1:{port}", "--pan-deg",
                                        str(pan), "--tilt-deg", str(tilt), "--zoom", str(zoom), "--json"],
                                       capture_output=True, text=True, cwd=ROOT, timeout=120)
                    seconds.append(time.perf_counter() - t0)
                    time.sleep(0.2)  # one state-file period
                    units = json.loads(state.read_text())["units"]
                    want = profile.to_device(math.radians(pan), math.radians(tilt), zoom)
                    on_target = all(abs(units[a] - getattr(want, a)) <= 1 for a in ("pan", "tilt", "zoom"))
                    reached += r.returncode == 0 and on_target
                out[name] = {"targets": n_targets, "reached": reached, "cli_seconds_median": sorted(seconds)[
                    len(seconds) // 2]}
                print(f"round trips {name}: {reached}/{n_targets} reached", flush=True)
            finally:
                em.terminate()
                try:
                    em.wait(60)
                except subprocess.TimeoutExpired:
                    em.kill()
                    em.wait()
                    out.setdefault(name, {})["emulator_exit"] = "killed: no exit within 60 s of SIGTERM"
    # a wrong password: one line, exit 2
    with OnvifEmulator(profile, user="admin", password="s3cret") as em:
        r = subprocess.run([*cli, "ptz", "--ptz", f"onvif://admin:wrong@127.0.0.1:{em.address[1]}"],
                           capture_output=True, text=True, cwd=ROOT, timeout=120)
        lines = [ln for ln in r.stderr.splitlines() if not ln.startswith(("WARNING", "INFO"))]
        out["wrong_password"] = {"exit": r.returncode, "message": lines}
        print(f"wrong password: exit {r.returncode}: {lines}", flush=True)
    return out


def outage(seconds: float = 2.0) -> dict:
    logging.disable(logging.WARNING)
    profile = default_profile("onvif")
    em = OnvifEmulator(profile).start()
    port = em.address[1]
    d = OnvifDriver(f"onvif://127.0.0.1:{port}", profile).connect(timeout=30)
    stop = threading.Event()

    def stream():
        t0 = time.monotonic()
        while not stop.is_set():
            t = time.monotonic() - t0
            d.set_target(math.radians(60 * math.sin(0.4 * t)), math.radians(10 + 5 * math.sin(0.3 * t)),
                         4 + math.sin(0.2 * t))
            time.sleep(0.04)

    walker = threading.Thread(target=stream, daemon=True)
    walker.start()
    time.sleep(2.0)
    d.take_writes()
    seq_down = d.sequence
    em.close()
    time.sleep(seconds)
    seq_back = d.sequence
    em = OnvifEmulator(profile, port=port).start()
    t_back = time.monotonic()
    while not d.connected and time.monotonic() - t_back < 30:
        time.sleep(0.002)
    reconnect_s = time.monotonic() - t_back
    time.sleep(1.0)
    stop.set()
    walker.join()
    writes = d.take_writes()
    after = [s for s, t in writes if t >= t_back]
    reached = d.wait_reached(10)
    result = {"outage_s": seconds, "reconnect_after_back_s": reconnect_s,
              "targets_set_during_outage": seq_back - seq_down,
              "first_write_after_back_seq": min(after) if after else None, "latest_seq_at_back": seq_back,
              "latest_target_reached_after": reached, "counters": d.counters}
    d.disconnect()
    em.close()
    print(f"outage {seconds:g} s: reconnected {1e3 * reconnect_s:.0f} ms after the camera was back; "
          f"{seq_back - seq_down} targets set while it was away (superseded); first target on the wire after: "
          f"seq {result['first_write_after_back_seq']} (latest at the return {seq_back}); final target reached "
          f"{reached}; counters {d.counters}", flush=True)
    return result


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--targets", type=int, default=4)
    ap.add_argument("--json", metavar="OUT")
    args = ap.parse_args()
    out = {"outage": outage(), "round_trips": round_trips(args.targets)}
    if args.json:
        Path(args.json).write_text(json.dumps(out, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
