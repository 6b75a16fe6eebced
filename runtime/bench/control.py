"""How many 640x480 cameras one core serves at the frame rate through the whole control path (used by
``omnijax bench`` and benchmarks/bench_control.py).

The control path is what the loop's control thread does per frame (runtime/realtime/loop.py): the
frame to the device, the one compiled call (detection, floor positions, the tracker's arithmetic,
the aim pipeline at every confirmed track), the tracker's bookkeeping, the target choice, the
dead-zone test and the command handed on (no PTZ attached: the serial write is the driver's
thread's, about 10 us), and the background's life. Drawing, the video and the log run on another
thread and are not part of it: here they are switched off.

Frames are a scenario's (the demo's by default: three people walking, the paper's rig), rendered up
front so that rendering is not timed; the background is learnt from every 8th of the first 240 as
the demo does. Each frame is timed by the wall clock and by the process's CPU time (all its threads:
XLA's included; pinned to one core, that is the core's time spent on it). Cameras per core = the
frame period / the mean time per frame (throughput), and the same with the p90 (what a core can
promise in nine frames out of ten); by CPU time the figure holds on a machine that other jobs share
(the wall clock then counts their time too), by the wall clock only on a quiet one.

Call :func:`runtime.bench.timing.pin_to_one_core` before importing this module.
"""

from __future__ import annotations

import tempfile
import time
from pathlib import Path

import jax
import numpy as np
from tqdm import tqdm

from omnijax import build_detector, learn_background
from omnijax.world import build_world
from runtime.files import load_scenario

#: Frames the background is learnt from: every LEARN_STEP-th of the first LEARN_SPAN (as the demo).
LEARN_SPAN, LEARN_STEP = 240, 8


class _Discard:
    """Stands in for the drawing thread: takes each frame and drops it."""

    error = None

    def submit(self, item) -> bool:
        return True

    def summary(self) -> dict:
        return {}


def bench_control(scenario_path: str, frames: int, progress: bool = True) -> dict:
    """Per-frame wall and CPU time (ms) of the control path over ``frames`` frames, its stages' medians,
    and the cameras one core serves at the scenario's frame rate (see the module docstring)."""
    from runtime.cli._options import load_ptz_profile
    from runtime.realtime.config import LoopConfig
    from runtime.realtime.loop import RealTimeLoop
    from runtime.realtime.ptz_link import PtzLink
    from runtime.realtime.sources import Frame

    rig, sc = load_scenario(scenario_path)
    world = build_world(rig, sc, None, n_frames=LEARN_SPAN + frames)
    bar = lambda it, what: tqdm(it, desc=what, disable=not progress, leave=False)
    bg = learn_background(np.stack([np.asarray(world.frame(t).image)
                                    for t in bar(range(0, LEARN_SPAN, LEARN_STEP), "render background")]))
    images = [np.asarray(jax.device_get(world.frame(t).image))
              for t in bar(range(LEARN_SPAN, LEARN_SPAN + frames), "render frames")]
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
        times, cpu, life = [], [], []
        t_start = time.monotonic()
        for k, image in enumerate(bar(images, "control path")):
            now, c0 = time.monotonic(), time.process_time()
            frame = Frame(index=LEARN_SPAN + k, t=now, stamp=(LEARN_SPAN + k) * period, image=image)
            stepped = loop.keeper.counts.frames
            loop._process(frame)
            waited = time.monotonic()
            jax.block_until_ready(loop.keeper.lines)  # the background update belongs to the frame's cost
            times.append(time.monotonic() - now)
            cpu.append(time.process_time() - c0)
            if loop.keeper.counts.frames > stepped:  # the life's step ran on after its dispatch ("adapt")
                life.append(time.monotonic() - waited)
        wall = time.monotonic() - t_start
    ms, cpu_ms = 1e3 * np.asarray(times), 1e3 * np.asarray(cpu)
    stats = lambda a: {"mean": float(a.mean()), "p50": float(np.median(a)), "p90": float(np.percentile(a, 90)),
                       "p99": float(np.percentile(a, 99)), "max": float(a.max())}
    per = lambda a: {"mean": 1e3 * period / float(a.mean()), "p90": 1e3 * period / float(np.percentile(a, 90))}
    return {"frames": len(images), "size": f"{W}x{H}", "fps": float(sc.fps), "frame_ms": stats(ms),
            "cpu_ms": stats(cpu_ms),
            "stages_ms_p50": {k: float(np.median(v.values())) for k, v in loop.timings.stages.items() if len(v)},
            "life_ms": {**stats(1e3 * np.asarray(life)), "n": len(life)} if life else None,
            "cameras_per_core": per(ms), "cameras_per_core_cpu": per(cpu_ms),
            "commands": loop.counts["commands_sent"], "tracks_confirmed_end": len(loop.tracker.confirmed()),
            "wall_s": wall}


def print_control(out: dict, name: str) -> None:
    """The report of :func:`bench_control` as lines of text."""
    f = out["frame_ms"]
    print(f"control path at {out['size']}, {out['frames']} frames of '{name}': per frame mean {f['mean']:.2f} ms, "
          f"p50 {f['p50']:.2f}, p90 {f['p90']:.2f}, p99 {f['p99']:.2f}, max {f['max']:.1f} ms")
    print("  stage p50 (ms): " + ", ".join(f"{k} {v:.3f}" for k, v in out["stages_ms_p50"].items()))
    if out.get("life_ms"):
        life = out["life_ms"]
        print(f"  the background's life, waited for after its dispatch, on the frames it steps: "
              f"p50 {life['p50']:.2f} ms, p90 {life['p90']:.2f}")
    u = out["cpu_ms"]
    print(f"  CPU time per frame (all threads): mean {u['mean']:.2f} ms, p50 {u['p50']:.2f}, p90 {u['p90']:.2f}, "
          f"p99 {u['p99']:.2f}")
    for key, what in (("cameras_per_core", "wall clock"), ("cameras_per_core_cpu", "CPU time")):
        c = out[key]
        print(f"  cameras one core serves at {out['fps']:g} fps by the {what}: {c['mean']:.1f} (by the mean), "
              f"{c['p90']:.1f} (by the p90)")
    print(f"  {out['commands']} commands")
