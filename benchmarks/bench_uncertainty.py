"""Speed of the pointing covariance: one point after jit, and a 200 x 200 floor grid, on one core.

Peer: the same first-order covariance as a hand-written vectorised NumPy closed form,
timed in the same process. Run: `make bench` or
`taskset -c 0 .venv/bin/python benchmarks/bench_uncertainty.py [--json]`.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from runtime.bench.timing import pin_to_one_core, time_calls

pin_to_one_core()

import jax

jax.config.update("jax_enable_x64", True)  # as the omnijax command runs
import numpy as np

from omnijax import pointing_covariance, world_to_image
from runtime.files import load_rig


def numpy_first_order(x: np.ndarray, s: np.ndarray) -> np.ndarray:
    """Hand-derived J Sigma J^T of (pan, tilt) for the paraboloid, vectorised in NumPy (the peer)."""
    r_f, th_f, H_o, H_f, D_c, th_c, r_m, H_p, R_h = np.moveaxis(x, -1, 0)
    q = r_m**2 - r_f**2
    R = 2 * H_o * r_m * r_f / q
    k = 2 * H_o * (r_m**2 + r_f**2) / q**2
    vt = th_f - th_c
    sv, cv = np.sin(vt), np.cos(vt)
    N, M = R * sv, D_c - R * cv
    D2 = N * N + M * M
    D = np.sqrt(D2)
    aim = H_p - R_h - H_f
    z = np.zeros_like(R)
    dR = np.stack([k * r_m, z, R / H_o, z, z, z, -k * r_f, z, z], -1)
    dvt = np.stack([z, z + 1, z, z, z, z - 1, z, z, z], -1)
    dDc = np.stack([z, z, z, z, z + 1, z, z, z, z], -1)
    daim = np.stack([z, z, z, z - 1, z, z, z, z + 1, z - 1], -1)
    dpan = ((D_c * sv)[..., None] * dR + (R * (D_c * cv - R))[..., None] * dvt - N[..., None] * dDc) / D2[..., None]
    dD = (((R - D_c * cv) / D)[..., None] * dR + (D_c * R * sv / D)[..., None] * dvt + (M / D)[..., None] * dDc)
    dtilt = (D[..., None] * daim - aim[..., None] * dD) / (D2 + aim**2)[..., None]
    J = np.stack([dpan, dtilt], -2)
    return np.einsum("...ai,...i,...bi->...ab", J, s**2, J)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--config", default=str(Path(__file__).resolve().parent.parent / "configs/paper.toml"))
    ap.add_argument("--grid", type=int, default=200, help="floor grid is GRID x GRID (default 200)")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()

    rig = load_rig(args.config)
    prof = rig.omni.profile
    out_line = rig.room.outline
    gx = np.linspace(float(out_line[:, 0].min()), float(out_line[:, 0].max()), args.grid)
    gy = np.linspace(float(out_line[:, 1].min()), float(out_line[:, 1].max()), args.grid)
    X, Y = np.meshgrid(gx, gy)
    px, py = world_to_image(rig.omni, X, Y, 0.0)
    r, th = rig.omni.to_polar(px, py)
    x_grid = rig.input_mean(r, th)
    sigma = rig.input_sigma()
    x_one = x_grid[args.grid // 2, args.grid // 3]
    res: dict = {"config": args.config, "grid": f"{args.grid}x{args.grid}", "device": str(jax.devices()[0]),
                 "cores": 1}

    for method in ("autodiff", "analytic", "second_order"):
        one = lambda method=method: pointing_covariance(x_one, sigma, prof, method).cov.block_until_ready()
        grid = lambda method=method: pointing_covariance(x_grid, sigma, prof, method).cov.block_until_ready()
        res[method] = {"one_point_ms": time_calls(one, 2000 if method != "second_order" else 300),
                       "grid_ms": time_calls(grid, 30 if method != "second_order" else 5)}
    x_np, s_np = np.asarray(x_grid), np.asarray(sigma)
    ref = numpy_first_order(x_np, s_np)
    cov = pointing_covariance(x_grid, sigma, prof, "autodiff")
    ours, valid = np.asarray(cov.pan_tilt), np.asarray(cov.valid)
    rel = np.abs(ours - ref) / np.sqrt(np.abs(ref[..., :1, :1] * ref[..., 1:, 1:]))
    res["numpy_first_order"] = {"grid_ms": time_calls(lambda: numpy_first_order(x_np, s_np), 30),
                                "max_rel_diff_vs_autodiff": float(rel[valid].max()),
                                "valid_points": int(valid.sum())}
    if args.json:
        print(json.dumps(res, indent=2))
        return
    print(f"pointing covariance on one core ({res['device']}), {rig.omni.model} rig, {res['grid']} floor grid")
    for method in ("autodiff", "analytic", "second_order"):
        o, g = res[method]["one_point_ms"], res[method]["grid_ms"]
        print(f"  {method:13s} one point p50 {o['p50']*1e3:8.1f} us p90 {o['p90']*1e3:8.1f} us | "
              f"grid p50 {g['p50']:8.2f} ms p90 {g['p90']:8.2f} ms")
    g = res["numpy_first_order"]["grid_ms"]
    print(f"  numpy peer    (hand closed form)                   | grid p50 {g['p50']:8.2f} ms p90 {g['p90']:8.2f} ms"
          f"  (max rel diff vs autodiff {res['numpy_first_order']['max_rel_diff_vs_autodiff']:.1e})")


if __name__ == "__main__":
    main()
