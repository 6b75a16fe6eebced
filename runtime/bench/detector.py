"""Detector speed on rendered frames against OpenCV's MOG2 (used by ``omnijax bench``).

Call :func:`runtime.benchmarking.pin_to_one_core` before importing this module.
"""

from __future__ import annotations

import cv2
import jax
import jax.monitoring
import numpy as np
from tqdm import tqdm

from omnijax import build_detector, detect, learn_background, line_background
from omnijax.detection import find_sectors, line_change, locate_people
from omnijax.world import build_world
from runtime.bench.timing import time_calls
from runtime.files import load_scenario

#: frames rendered per size: background frames, then frames cycled through by the timed calls
BACKGROUND_FRAMES = 30
TIMED_FRAMES = 50
COMPILE_EVENT = "/jax/core/compile/backend_compile_duration"


class _CompileCounter:
    """Counts XLA backend compilations (JAX's monitoring events) while ``active``."""

    def __init__(self) -> None:
        self.active, self.count = False, 0
        jax.monitoring.register_event_duration_secs_listener(self._on_event)

    def _on_event(self, event: str, duration: float, **_) -> None:
        if self.active and event == COMPILE_EVENT:
            self.count += 1


_COUNTER = None


def _scaled_rig_overrides(rig, size: tuple[int, int]) -> dict:
    """The rig's omni image scaled (centre, r_m, rim) so that its circle fills a ``size`` frame alike."""
    w, h = size
    w0, h0 = rig.omni.image_size
    k = min(w / w0, h / h0)
    omni = {"image_size": [w, h], "center": [w / 2, h / 2], "r_m": float(rig.omni.r_m) * k}
    return {"omni": omni}


def bench_size(scenario_path: str, size: tuple[int, int], repeats: int, progress: bool = True) -> dict:
    """Median / p90 / p99 (ms) of detect, its stages and MOG2 at ``size``; compilations while timed."""
    global _COUNTER
    _COUNTER = _COUNTER or _CompileCounter()
    rig0, _ = load_scenario(scenario_path)
    rig, scenario = load_scenario(scenario_path, _scaled_rig_overrides(rig0, size))
    n = BACKGROUND_FRAMES + TIMED_FRAMES
    world = build_world(rig, scenario, seed=0, n_frames=n)
    frames = np.stack([np.asarray(world.frame(t).image)
                       for t in tqdm(range(n), desc=f"render {size[0]}x{size[1]}", disable=not progress, leave=False)])
    bg_frames, timed = frames[:BACKGROUND_FRAMES], frames[BACKGROUND_FRAMES:]
    detector = build_detector(rig)
    bg = learn_background(bg_frames)
    lines = line_background(detector, bg)

    stage_lines = jax.jit(lambda d, f, ln: (lambda d2: (d2, d2.sum(-1)))(line_change(d, f, ln)))
    stage_sectors = jax.jit(find_sectors)
    stage_people = jax.jit(locate_people)
    D = [stage_lines(detector, f, lines) for f in timed]
    found = [stage_sectors(detector, m) for _, m in D]
    people = float(np.mean([int(detect(detector, f, lines)[0].valid.sum()) for f in timed]))

    def cycling(call):
        state = {"i": 0}

        def step():
            i = state["i"] = (state["i"] + 1) % len(timed)
            jax.block_until_ready(call(i))
        return step

    _COUNTER.count, _COUNTER.active = 0, True
    detect_ms = time_calls(cycling(lambda i: detect(detector, timed[i], lines)), repeats)
    _COUNTER.active = False
    compiles = _COUNTER.count
    stages = {
        "lines_steps_1_3": time_calls(cycling(lambda i: stage_lines(detector, timed[i], lines)), repeats),
        "sectors_step_4": time_calls(cycling(lambda i: stage_sectors(detector, D[i][1])), repeats),
        "people_steps_5_6": time_calls(cycling(lambda i: stage_people(detector, D[i][0], found[i])), repeats),
    }

    mog2 = cv2.createBackgroundSubtractorMOG2()
    for f in bg_frames:
        mog2.apply(f)
    mog2_ms = time_calls(cycling(lambda i: mog2.apply(timed[i])), repeats)
    return {"detect_ms": detect_ms, "stages_ms": stages, "mog2_ms": mog2_ms,
            "mog2_over_detect": mog2_ms["p50"] / detect_ms["p50"], "compiles": compiles,
            "people": people, "frames": len(timed), "polar_samples": int(detector.polar.line_index.size)}
