"""Loop latency (frame available -> PTZ bytes written) and throughput at 640x480, without video writing.

1. Records a synthetic clip (`omnijax demo --record`, three people, the paper's rig) unless
   --clip is given.
2. Replays it with `omnijax run --pace live` (frames arrive at 25 fps, as from a camera, so each
   is timed from when it became available) on one core, steering the PTZ emulator (another
   process) through the VISCA driver, and prints `latency_ms`, `compute_latency_ms` and the
   per-stage times.
3. Replays it with `--pace all` (every frame, as fast as possible) for the frames per second.

    .venv/bin/python benchmarks/bench_loop.py [--clip omni.avi] [--frames 600]
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def omnijax(*args: str, core: int | None = None) -> None:
    cmd = [sys.executable, "-m", "runtime.cli", *args]
    if core is not None:
        cmd = ["taskset", "-c", str(core), *cmd]
    subprocess.run(cmd, cwd=ROOT, check=True, stdout=subprocess.DEVNULL)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--clip", help="omni video at 640x480 (default: record one)")
    ap.add_argument("--frames", type=int, default=600, help="frames of the recorded clip (600)")
    args = ap.parse_args()
    sys.path.insert(0, str(ROOT))
    from runtime.ptz.child import EmulatorProcess

    with tempfile.TemporaryDirectory(prefix="bench-loop-") as tmp:
        tmp = Path(tmp)
        clip = Path(args.clip) if args.clip else tmp / "rec" / "omni.avi"
        if not args.clip:
            omnijax("demo", "--out", str(tmp / "rec"), "--frames", str(args.frames), "--pace", "all",
                    "--no-video", "--record", "--quiet")
        out = {}
        with EmulatorProcess() as emulator:
            for pace in ("live", "all"):
                omnijax("run", str(clip), "--config", "configs/paper.toml", "--ptz", str(emulator.link),
                        "--out", str(tmp / pace), "--pace", pace, "--no-video", "--quiet", core=0)
                s = json.loads((tmp / pace / "summary.json").read_text())
                out[pace] = {k: s[k] for k in ("frames", "fps", "latency_ms", "compute_latency_ms", "stages_ms")}
                out[pace]["ptz"] = {k: s["ptz"][k] for k in ("commands", "errors", "reconnects")}
                out[pace]["dropped"] = s["faults"]["dropped_frames"]
        print(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
