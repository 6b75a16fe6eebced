"""Speed of the zoom rules on one core: one person per call, one at a time inside a jitted loop,
a vmapped batch, and the batch's forward-mode Jacobian (what the layout optimiser pushes through
the calibrated rule's root).

Inputs: the pointing covariances of N random floor points of the rig (default 400), scaled by
factors 0.01 to 10 so that the calibrated rule meets all three of its cases (longest zoom,
widest zoom, a root in between). Run: `make bench` or
`taskset -c 0 .venv/bin/python benchmarks/bench_zoom.py [--json]`.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from runtime.bench.timing import pin_to_one_core, time_calls

pin_to_one_core()

import jax

jax.config.update("jax_enable_x64", True)  # as the omnijax command runs
import jax.numpy as jnp
import numpy as np

from omnijax import aim, choose_zoom, world_to_image
from runtime.files import load_rig


def covariance_inputs(rig, n: int, seed: int = 0):
    """Pointing covariances, tilts, slants and distances of ``n`` random floor points, scaled."""
    outline = np.asarray(rig.room.outline)
    rng = np.random.default_rng(seed)
    X = rng.uniform(outline[:, 0].min(), outline[:, 0].max(), n)
    Y = rng.uniform(outline[:, 1].min(), outline[:, 1].max(), n)
    r, th = rig.omni.to_polar(*world_to_image(rig.omni, X, Y, 0.0))
    a = jax.vmap(lambda r_f, theta_f: aim(rig, r_f, theta_f))(r, th)
    ok = np.asarray(a.covariance.valid)
    scale = jnp.asarray(rng.choice([0.01, 0.3, 1.0, 3.0, 10.0], n))[ok]
    p = a.pointing
    return a.covariance.cov[ok] * scale[:, None, None], p.tilt[ok], p.slant[ok], p.distance[ok]


def time_rule(zoom, inputs) -> dict:
    """Timings of ``zoom(cov4, tilt, slant, distance)`` over the stacked ``inputs``."""
    n = int(inputs[0].shape[0])
    one = jax.jit(zoom)
    looped = jax.jit(lambda *xs: jax.lax.map(lambda x: zoom(*x), xs))
    batch = jax.jit(jax.vmap(zoom))
    jac = jax.jit(jax.vmap(jax.jacfwd(zoom, argnums=(0, 1, 2, 3))))
    one(*(x[0] for x in inputs)).block_until_ready()
    calls = []
    for _ in range(3):
        for i in range(n):
            t0 = time.perf_counter()
            one(*(x[i] for x in inputs)).block_until_ready()
            calls.append(time.perf_counter() - t0)
    us = 1e6 * np.array(calls)
    loop = time_calls(lambda: looped(*inputs).block_until_ready(), 30)
    return {
        "single_call_us": {"p50": float(np.median(us)), "p90": float(np.percentile(us, 90)), "n": us.size},
        "in_jitted_loop_us_per_point": {k: 1e3 * loop[k] / n for k in ("p50", "p90")},
        "vmapped_ms": time_calls(lambda: batch(*inputs).block_until_ready(), 100),
        "vmapped_jacfwd_ms": time_calls(lambda: jax.block_until_ready(jac(*inputs)), 30),
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--config", default=str(Path(__file__).resolve().parent.parent / "configs/paper.toml"))
    ap.add_argument("--points", type=int, default=400, help="floor points (default 400)")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()

    rig = load_rig(args.config)
    lens, R_h, p = rig.foveal.lens, rig.person.R_h, rig.p_contain
    cov, tilt, slant, dist = covariance_inputs(rig, args.points)
    n = int(cov.shape[0])
    res: dict = {"config": args.config, "points": n, "device": str(jax.devices()[0]), "cores": 1}
    for rule in ("paper", "calibrated"):
        zoom = lambda c, t, s, d, rule=rule: choose_zoom(lens, rule, c, d, t, s, R_h, p).zoom
        res[rule] = time_rule(zoom, (cov, tilt, slant, dist))
        z = np.asarray(jax.jit(jax.vmap(zoom))(cov, tilt, slant, dist))
        res[rule]["at_longest"] = int(np.sum(z >= float(lens.zoom_range[1])))
        res[rule]["at_widest"] = int(np.sum(z <= float(lens.zoom_range[0])))
    if args.json:
        print(json.dumps(res, indent=2))
        return
    print(f"zoom rules on one core ({res['device']}), {n} pointing covariances from {Path(args.config).name}")
    for rule in ("paper", "calibrated"):
        r = res[rule]
        s, lp, v, j = r["single_call_us"], r["in_jitted_loop_us_per_point"], r["vmapped_ms"], r["vmapped_jacfwd_ms"]
        print(f"  {rule:10s} one call p50 {s['p50']:7.1f} us p90 {s['p90']:7.1f} us | in a jitted loop "
              f"{lp['p50']:6.2f} us/point | vmapped p50 {v['p50']:6.3f} ms p90 {v['p90']:6.3f} ms | "
              f"jacfwd vmapped p50 {j['p50']:6.2f} ms p90 {j['p90']:6.2f} ms "
              f"({r['at_longest']} at the longest zoom, {r['at_widest']} at the widest)")


if __name__ == "__main__":
    main()
