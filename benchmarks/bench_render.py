"""Speed of the synthetic world's omni renderer: frames per second on one core, after compilation.

One call of ``World.frame(t)`` (people, shadows, lamps, drift, noise, 8-bit quantisation,
labels and truth; JPEG where the scenario asks for it), t cycling through the walk, for:

- the paper rig (640 x 480 paraboloid): empty room, one, three and six people;
- 1280 x 960: the three-people scenario on the paper rig scaled by 2 (image size, centre,
  r_m), and the fisheye office (equidistant, four people) with and without its JPEG.

Wall time per frame (p50 / p90 / p99) and the process's CPU time per frame (median: on a
shared machine it is the steadier figure). Run: `make bench` or
`taskset -c 0 .venv/bin/python benchmarks/bench_render.py [--json]`.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from runtime.bench.timing import pin_to_one_core, time_calls

pin_to_one_core()

import equinox as eqx
import jax

jax.config.update("jax_enable_x64", True)  # as the omnijax command runs
import numpy as np

from omnijax.world import build_world
from runtime.files import load_scenario

SCENARIOS = ROOT / "configs" / "scenarios"


def scaled(rig, factor: int):
    """The rig with its omni image ``factor`` times larger (same field of view)."""
    om = rig.omni
    rig = eqx.tree_at(lambda r: (r.omni.center, r.omni.r_m, r.omni.rim), rig,
                      (om.center * factor, om.r_m * factor, om.rim * factor))
    size = (om.image_size[0] * factor, om.image_size[1] * factor)
    return eqx.tree_at(lambda r: r.omni, rig, replace_fn=lambda o: dataclasses.replace(o, image_size=size))


def without_jpeg(scenario):
    return eqx.tree_at(lambda s: s.sensor, scenario,
                       replace_fn=lambda se: dataclasses.replace(se, jpeg_quality=0))


def cases():
    for name in ("empty_room", "one_person", "three_people", "six_people"):
        rig, sc = load_scenario(SCENARIOS / f"{name}.toml")
        yield name, rig, sc
    rig, sc = load_scenario(SCENARIOS / "three_people.toml")
    yield "three_people (paper rig x2)", scaled(rig, 2), sc
    rig, sc = load_scenario(SCENARIOS / "fisheye_office.toml")
    yield "fisheye_office (JPEG q90)", rig, sc
    yield "fisheye_office (no JPEG)", rig, without_jpeg(sc)


def measure(world, repeats: int) -> dict:
    n = world.n_frames
    counter = iter(range(10**9))

    def one():
        jax.block_until_ready(world.frame(next(counter) % n))

    wall = time_calls(one, repeats, warmup=5)
    cpu = []
    for _ in range(repeats):
        t0 = time.process_time()
        one()
        cpu.append(time.process_time() - t0)
    cpu_ms = 1e3 * float(np.median(cpu))
    return {"wall_ms": wall, "cpu_ms_p50": cpu_ms, "fps_wall_p50": 1e3 / wall["p50"], "fps_cpu": 1e3 / cpu_ms}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--repeats", type=int, default=200, help="timed frames per case (default 200)")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    results = {"device": str(jax.devices()[0]), "cores": 1, "cases": {}}
    for name, rig, sc in cases():
        t0 = time.perf_counter()
        world = build_world(rig, sc, n_frames=250)
        jax.block_until_ready(world.frame(0))
        setup = time.perf_counter() - t0
        w, h = world.true_rig.omni.image_size
        res = {"size": f"{w}x{h}", "camera_model": world.true_rig.omni.model, "people": world.people.count,
               "jpeg_quality": sc.sensor.jpeg_quality or None, "build_and_compile_s": setup,
               **measure(world, args.repeats)}
        results["cases"][name] = res
        if not args.json:
            wm = res["wall_ms"]
            print(f"{name:30s} {res['size']:>9s} {res['people']} people  wall p50 {wm['p50']:6.2f} ms "
                  f"p90 {wm['p90']:6.2f} p99 {wm['p99']:6.2f} ({res['fps_wall_p50']:5.0f} fps)  "
                  f"cpu {res['cpu_ms_p50']:6.2f} ms ({res['fps_cpu']:5.0f} fps)  build+compile {setup:5.1f} s",
                  flush=True)
    if args.json:
        print(json.dumps(results, indent=2))


if __name__ == "__main__":
    main()
