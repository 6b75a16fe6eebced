"""How many 640x480 cameras one core can serve at 25 fps through the whole control path.

The control path is what the loop's control thread does per frame (runtime/realtime/loop.py):
the frame to the device, the one compiled call (detection, floor positions, the tracker's
arithmetic, the aim pipeline at every confirmed track), the tracker's bookkeeping, the target
choice, the dead-zone test and the command handed on (no PTZ attached: the serial write is the
driver's thread's, about 10 us), and the background update. Drawing, the video and the log run on
another thread and are not part of it: here they are switched off.

Frames are the demo's scenario (three people walking, the paper's rig), rendered up front so that
rendering is not timed; the background is learnt from every 8th of the first 240 as the demo does.
Each frame is timed by the wall clock and by the process's CPU time (all its threads: XLA's
included; pinned to one core, that is the core's time spent on it). Cameras per core = the frame
period / the mean time per frame (throughput), and the same with the p90 (what a core can
promise in nine frames out of ten); by CPU time the figure holds on a machine that other jobs
share (the wall clock then counts their time too), by the wall clock only on a quiet one.

    taskset -c 0 .venv/bin/python benchmarks/bench_control.py [--frames 300] [--json]
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

import jax

jax.config.update("jax_enable_x64", True)  # as the omnijax command runs
import numpy as np


class _Discard:
    """Stands in for the drawing thread: takes each frame and drops it."""

    error = None

    def submit(self, item) -> bool:
        return True

    def summary(self) -> dict:
        return {}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--frames", type=int, default=300, help="timed frames (default 300)")
    ap.add_argument("--scenario", default=str(ROOT / "configs" / "scenarios" / "three_people.toml"))
    ap.add_argument("--json", action="store_true", help="print JSON only")
    args = ap.parse_args()

    from omnijax import build_detector, learn_background
    from omnijax.world import build_world
    from runtime.cli._options import load_ptz_profile
    from runtime.files import load_scenario
    from runtime.realtime.config import LoopConfig
    from runtime.realtime.loop import RealTimeLoop
    from runtime.realtime.ptz_link import PtzLink
    from runtime.realtime.sources import Frame

    rig, sc = load_scenario(args.scenario)
    n_bg, step = 240, 8
    world = build_world(rig, sc, None, n_frames=n_bg + args.frames)
    bg = learn_background(np.stack([np.asarray(world.frame(t).image) for t in range(0, n_bg, step)]))
    frames = [np.asarray(jax.device_get(world.frame(t).image)) for t in range(n_bg, n_bg + args.frames)]
    W, H = rig.omni.image_size
    period = 1.0 / float(sc.fps)

    class _Source:
        fps = float(sc.fps)

    class _Capture:
        source, counts = _Source(), {"dropped": 0, "stale": 0, "broken": 0, "wrong_size": 0}

    with tempfile.TemporaryDirectory(prefix="bench-control-") as tmp:
        links = [PtzLink(0, None, load_ptz_profile(None, "visca"))]
        loop = RealTimeLoop(rig, build_detector(rig), bg, _Capture(), links, LoopConfig(quiet=True),
                            Path(tmp) / "log.jsonl")
        loop.warm_up()
        loop.off_path = _Discard()
        times, cpu = [], []
        t_start = time.monotonic()
        for k, image in enumerate(frames):
            now, c0 = time.monotonic(), time.process_time()
            frame = Frame(index=n_bg + k, t=now, stamp=(n_bg + k) * period, image=image)
            loop._process(frame)
            jax.block_until_ready(loop.keeper.lines)  # the background update belongs to the frame's cost
            times.append(time.monotonic() - now)
            cpu.append(time.process_time() - c0)
        wall = time.monotonic() - t_start
    ms, cpu_ms = 1e3 * np.asarray(times), 1e3 * np.asarray(cpu)
    stages = {k: float(np.median(v.values())) for k, v in loop.timings.stages.items() if len(v)}
    out = {"frames": len(frames), "size": f"{W}x{H}", "fps": float(sc.fps),
           "frame_ms": {"mean": float(ms.mean()), "p50": float(np.median(ms)), "p90": float(np.percentile(ms, 90)),
                        "p99": float(np.percentile(ms, 99)), "max": float(ms.max())},
           "cpu_ms": {"mean": float(cpu_ms.mean()), "p50": float(np.median(cpu_ms)),
                      "p90": float(np.percentile(cpu_ms, 90)), "p99": float(np.percentile(cpu_ms, 99))},
           "stages_ms_p50": stages,
           "cameras_per_core": {"mean": 1e3 * period / float(ms.mean()),
                                "p90": 1e3 * period / float(np.percentile(ms, 90))},
           "cameras_per_core_cpu": {"mean": 1e3 * period / float(cpu_ms.mean()),
                                    "p90": 1e3 * period / float(np.percentile(cpu_ms, 90))},
           "commands": loop.counts["commands_sent"], "tracks_confirmed_end": len(loop.tracker.confirmed()),
           "wall_s": wall}
    if args.json:
        print(json.dumps(out))
        return
    f = out["frame_ms"]
    print(f"control path at {out['size']}, {out['frames']} frames of '{sc.name}': per frame mean {f['mean']:.2f} ms, "
          f"p50 {f['p50']:.2f}, p90 {f['p90']:.2f}, p99 {f['p99']:.2f}, max {f['max']:.1f} ms")
    print("  stage p50 (ms): " + ", ".join(f"{k} {v:.3f}" for k, v in stages.items()))
    u = out["cpu_ms"]
    print(f"  CPU time per frame (all threads): mean {u['mean']:.2f} ms, p50 {u['p50']:.2f}, p90 {u['p90']:.2f}, "
          f"p99 {u['p99']:.2f}")
    for key, what in (("cameras_per_core", "wall clock"), ("cameras_per_core_cpu", "CPU time")):
        c = out[key]
        print(f"  cameras one core serves at {out['fps']:g} fps by the {what}: {c['mean']:.1f} (by the mean), "
              f"{c['p90']:.1f} (by the p90)")
    print(f"  {out['commands']} commands")
    print(json.dumps(out))


if __name__ == "__main__":
    main()
