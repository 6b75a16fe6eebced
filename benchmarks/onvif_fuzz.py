"""Fuzz the ONVIF emulator and driver: random and mutated SOAP bodies; exceptions and hangs must be 0.

    python benchmarks/onvif_fuzz.py [--n 10000] [--driver-n 10000] [--seed 0] [--json OUT]

Emulator: N bodies into the SOAP service. Driver: the driver against a camera that mutates half
of its replies, until DRIVER_N mutated replies were served (minutes: every mutated discovery reply
costs a reconnect with back-off). See runtime/bench/onvif_fuzz.py.
"""

import argparse
import json
import logging
import sys
from dataclasses import asdict
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from runtime.bench.onvif_fuzz import fuzz_driver, fuzz_emulator
from runtime.ptz.profile import default_profile


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--n", type=int, default=10_000)
    ap.add_argument("--driver-n", type=int, default=10_000)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--json", metavar="OUT")
    args = ap.parse_args()
    logging.disable(logging.CRITICAL)  # zeep logs every unparsable value it meets; the counts are the result
    profile = default_profile("onvif")
    out = {}
    for name, user in (("emulator", None), ("emulator_auth", "admin")):
        r = fuzz_emulator(profile, args.n, args.seed, user=user)
        out[name] = asdict(r)
        print(f"{name}: {r.bodies} bodies, exceptions {r.exceptions}, hangs {r.hangs}, statuses {r.statuses}, "
              f"{r.seconds:.1f} s", flush=True)
    if args.driver_n:
        r = fuzz_driver(profile, args.driver_n, args.seed)
        out["driver"] = asdict(r)
        s = r.statuses
        print(f"driver: {r.bodies} mutated replies of {s.get('requests')} requests, exceptions {r.exceptions}, "
              f"hangs {r.hangs}; driver counted malformed {s.get('malformed')}, faults {s.get('faults')}, "
              f"errors {s.get('errors')}, reconnects {s.get('reconnects')}; {r.seconds:.1f} s", flush=True)
    if args.json:
        Path(args.json).write_text(json.dumps(out, indent=2, default=str))
    bad = sum(v["exceptions"] + v["hangs"] for v in out.values())
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
