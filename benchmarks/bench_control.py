"""How many 640x480 cameras one core can serve at 25 fps through the whole control path: what
``omnijax bench`` reports as ``cameras_per_core`` (runtime/bench/control.py says how it is measured),
on its own and with more frames.

    .venv/bin/python benchmarks/bench_control.py [--frames 300] [--core 0] [--json]
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--frames", type=int, default=300, help="timed frames (default 300)")
    ap.add_argument("--scenario", default=str(ROOT / "configs" / "scenarios" / "three_people.toml"))
    ap.add_argument("--core", type=int, default=0, help="CPU core to pin to (default 0)")
    ap.add_argument("--json", action="store_true", help="print JSON only")
    args = ap.parse_args()

    from runtime.bench.timing import pin_to_one_core

    pin_to_one_core(args.core)  # before JAX loads
    import jax

    jax.config.update("jax_enable_x64", True)  # as the omnijax command runs
    from runtime.bench.control import bench_control, print_control

    out = bench_control(args.scenario, args.frames, progress=not args.json)
    if not args.json:
        print_control(out, Path(args.scenario).stem)
    print(json.dumps(out))


if __name__ == "__main__":
    main()
