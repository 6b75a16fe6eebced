"""Where Table 1's r_f bias comes from: the foot error per position under controlled variants of the world.

For each of Table 1's positions (``omnijax validate``'s, fixed rig), ``--trials`` rendered frames per
variant, the person jittered around the position (:func:`runtime.validation.endtoend.jittered_feet`):

- ``table1``     validate's world: a fresh person (H_p, R_h, clothing from the priors), lamps and shadows;
- ``prior_size`` the person's H_p and R_h at the prior means (only the clothing varies): the height
                 mismatch between the person and the detector's model removed;
- ``no_shadow``  no lamps, only ambient light (the same grey level): no cast shadows;
- ``exact``      ``prior_size`` without jitter, the person at the nominal position (validate's old trials);
- ``axis_model`` ``table1`` with the detector's foot hypotheses changed (monkeypatched here, not in
                 omnijax): the window's model of the image (outer end, width) too from an axis ``rho``
                 beyond the inner end, not ``pi rho / 4`` (the detector has ``rho`` for the foot only:
                 docs/detection.md, "The foot is rho beyond the inner end");
- ``axis_prior_size`` ``axis_model`` with the person's H_p and R_h at the prior means (what is left once
                 the height is no longer a mismatch: the detector's height hypothesis).

Per position and variant: the r_f error (detected minus true axis foot, px) mean and sd; the inner end's
error (the detector's ``r_in``, where its foot hypothesis starts the silhouette, minus the true
silhouette's foot end ``r_inner`` on the centre line); and the model's offset from the inner end to the
axis foot at the detected inner end against the true one (what eq 1 adds to go from silhouette to axis).
With ``r_f error = inner-end error + (model offset - true offset)``, the last term is the person model's
share of the bias. Prints one table per variant and writes ``--out`` (JSON).

    .venv/bin/python benchmarks/table1_bias.py --config configs/paper.toml --trials 200 --out bias.json
"""

from __future__ import annotations

import argparse
import json
import time

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from omnijax import floor_radius, person_image_extent, point_image_radius
from omnijax.detection import _polar
from omnijax.detection._polar import body_radius
from runtime.files import load_rig
from runtime.validation import endtoend as e

VARIANTS = ("table1", "prior_size", "no_shadow", "exact", "axis_model", "axis_prior_size")


@jax.jit
def _axis_tables(rig, radii, theta):
    """``omnijax.detection._polar._geometry_tables`` with the window's model of the image too from the
    axis ``rho`` beyond the inner end, not ``pi rho / 4``: the ``axis_model`` variant."""
    omni = rig.omni
    x, y = omni.to_pixel(radii[None, :], theta[:, None])
    R_floor = floor_radius(radii, omni.r_m, omni.H_o, omni.profile)[0]
    rho = body_radius(rig)
    R_axis = R_floor + rho
    outer = lambda H_p: person_image_extent(R_axis, omni, H_p, rig.person.R_h, rho)[1]
    r_out, dout_dH = jax.jvp(outer, (rig.person.H_p,), (jnp.ones_like(rig.person.H_p),))
    r_f = point_image_radius(R_axis, 0.0, omni.r_m, omni.H_o, omni.profile)
    width = 2 * jnp.arcsin(jnp.minimum(rho / R_axis, 1.0))
    return x, y, R_floor, r_out, r_f, dout_dH, width, R_axis


def _axis_bench(rig, seed, positions):
    saved = _polar._geometry_tables
    _polar._geometry_tables = _axis_tables
    try:
        b = e.prepare(rig, e.table1_scenario(rig, seed), seed=seed, foot_mc_profiles=64)
    finally:
        _polar._geometry_tables = saved
    return e.Bench(**{**vars(b), "positions": positions})


def _no_lamps(rig, seed):
    sc = e.table1_scenario(rig, seed)
    # the three lamps' share of the light moved to the ambient term: about the same grey levels, no shadows
    light = eqx.tree_at(lambda s: (s.lighting.intensity, s.lighting.ambient), sc,
                        (jnp.zeros_like(sc.lighting.intensity), sc.lighting.ambient * 3.0))
    return light


def _fixed_size(bench):
    rig = bench.world.rig
    rig0 = eqx.tree_at(lambda r: (r.sigmas.H_p, r.sigmas.R_h), rig, (jnp.zeros(()), jnp.zeros(())))
    return e.Bench(**{**vars(bench), "world": eqx.tree_at(lambda w: w.scene.rig, bench.world, rig0)})


def stats(t) -> dict:
    d = t.det
    f = np.asarray(d.found, bool)
    x = np.asarray(t.x_true)[f]
    r_f, r_in, r_inner = np.asarray(d.r_f)[f], np.asarray(d.r_in)[f], np.asarray(t.r_inner)[f]
    true_off = x[:, 0] - r_inner
    model_off = r_f - r_in
    e_rf, e_in = r_f - x[:, 0], r_in - r_inner
    e_th = np.asarray(e.wrap_pi(np.asarray(d.theta_f)[f] - x[:, 1]))
    return {"trials": int(f.sum()), "missed": int((~f).sum()),
            "r_f_bias_px": float(e_rf.mean()), "r_f_sd_px": float(e_rf.std(ddof=1)),
            "r_f_bias_se_px": float(e_rf.std(ddof=1) / np.sqrt(f.sum())),
            "inner_end_bias_px": float(e_in.mean()), "inner_end_sd_px": float(e_in.std(ddof=1)),
            "model_minus_true_offset_px": float((model_off - true_off).mean()),
            "theta_f_bias_rad": float(e_th.mean()), "theta_f_sd_rad": float(e_th.std(ddof=1))}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--config", default="configs/paper.toml")
    ap.add_argument("--trials", type=int, default=200)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--variants", default=",".join(VARIANTS))
    ap.add_argument("--out")
    args = ap.parse_args(argv)
    jax.config.update("jax_enable_x64", True)
    rig = load_rig(args.config)
    variants = args.variants.split(",")
    t0 = time.perf_counter()
    bench = e.prepare(rig, e.table1_scenario(rig, args.seed), seed=args.seed, foot_mc_profiles=64)
    benches = {"table1": bench, "prior_size": _fixed_size(bench), "exact": _fixed_size(bench)}
    if "no_shadow" in variants:
        dark = e.prepare(rig, _no_lamps(rig, args.seed), seed=args.seed, foot_mc_profiles=64)
        benches["no_shadow"] = e.Bench(**{**vars(dark), "positions": bench.positions})
    if {"axis_model", "axis_prior_size"} & set(variants):
        benches["axis_model"] = _axis_bench(rig, args.seed, bench.positions)
        benches["axis_prior_size"] = _fixed_size(benches["axis_model"])
    key = jax.random.key(args.seed)
    out = {"config": args.config, "trials": args.trials, "variants": {}}
    for v in variants:
        rows = []
        for k, foot in enumerate(bench.positions):
            t = e.trials(benches[v], foot, args.trials, jax.random.fold_in(key, k), "person", jitter=v != "exact")
            rows.append({"position": f"P{k + 1}", **stats(t)})
        out["variants"][v] = rows
        print(f"\n{v}: r_f bias (px) +- se | r_f sd | inner-end bias | model - true offset | theta bias (mrad) | sd")
        for r in rows:
            print(f"  {r['position']}: {r['r_f_bias_px']:+.2f} +- {r['r_f_bias_se_px']:.2f} | {r['r_f_sd_px']:.2f} | "
                  f"{r['inner_end_bias_px']:+.2f} | {r['model_minus_true_offset_px']:+.2f} | "
                  f"{1e3 * r['theta_f_bias_rad']:+.2f} | {1e3 * r['theta_f_sd_rad']:.2f}", flush=True)
    out["seconds"] = time.perf_counter() - t0
    print(f"{out['seconds']:.0f} s")
    if args.out:
        with open(args.out, "w") as fh:
            json.dump(out, fh, indent=1)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
