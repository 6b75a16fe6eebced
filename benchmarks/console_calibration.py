"""The console's calibration assistant on the demo's emulated rig: fitted values against the world's
true rig, and their NEES (issue 25).

For each seed, runs ``omnijax demo --seed S --serve 127.0.0.1:0`` (three_people on copies of the
scenario and its rig) and does through the page's JSON API what an operator does on the page: for each
of ``--marks`` floor positions and each of the heights 0 and 1.5 m, drives the PTZ onto the mark
(``POST /api/ptz``: the true PTZ's pan/tilt at the mark, rounded to the 0.1 deg of a Shift+arrow press,
the operator's eye) and clicks the mark's foot in the omni image (``POST /api/calibration/mark``: where
the true omni camera images it, plus a click error of ``--click-sd-px`` per axis), then fits
(``POST /api/calibration/fit``: ``omnijax calibrate`` on the configured rig). The truth is the world's
true rig (drawn from the seed: H_o, r_m, D_c, theta_c, H_f; the image centre as configured) and the
emulated PTZ's mounting zeros (its profile's). NEES per parameter = (fit - truth)^2 / sigma^2, 1 on
average when the sigmas are honest.

    .venv/bin/python benchmarks/console_calibration.py --seeds 9101 9102 9103
"""

from __future__ import annotations

import argparse
import json
import math
import shutil
import statistics
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _served_demo import ROOT, ServedDemo

SCENARIO = ROOT / "configs" / "scenarios" / "three_people.toml"
#: Floor positions of the marks (m): spread over the room, away from the PTZ. The floor marks of the last two
#: lie below the PTZ's lowest tilt (-30 deg) in most drawn rigs: the assistant refuses them, as it must.
MARKS = ((-1.0, -1.5), (-1.0, 1.8), (-2.5, 2.2), (-3.2, -0.6), (0.8, 2.2), (0.3, -2.1))
HEIGHTS_M = (0.0, 1.5)
#: A Shift+arrow press turns the PTZ by this much (deg): the operator centres the mark to within it.
STEP_DEG = 0.1


def truth(seed: int) -> dict:
    """The true values of the fitted parameters (SI) for the world of ``seed``."""
    import jax

    jax.config.update("jax_enable_x64", True)
    from omnijax.world import build_world
    from runtime.cli._options import load_ptz_profile
    from runtime.files import load_scenario
    from runtime.ptz.transports import EMULATED

    rig, sc = load_scenario(SCENARIO)
    true = build_world(rig, sc, seed, n_frames=1).true_rig
    mounting = load_ptz_profile(None, EMULATED["visca"]).mounting
    return {"rig": true, "values": {
        "H_o": float(true.omni.H_o), "D_c": float(true.foveal.D_c), "theta_c": float(true.foveal.theta_c),
        "H_f": float(true.foveal.H_f), "r_m": float(true.omni.r_m), "center_x": float(true.omni.center[0]),
        "center_y": float(true.omni.center[1]), "pan_zero": math.radians(mounting.pan_zero_deg),
        "tilt_zero": math.radians(mounting.tilt_zero_deg)}}


def aims(true_rig, rng, click_sd_px: float) -> list[dict]:
    """Per mark and height: the PTZ's pan/tilt (deg) an operator ends on and the pixel clicked."""
    import jax.numpy as jnp

    from omnijax import pointing, world_to_image

    out = []
    for X, Y in MARKS:
        x, y = (float(v) for v in world_to_image(true_rig.omni, X, Y, 0.0))
        r, theta = (float(v) for v in true_rig.omni.to_polar(x, y))
        cx, cy = x + click_sd_px * rng.standard_normal(), y + click_sd_px * rng.standard_normal()
        for h in HEIGHTS_M:
            inputs = true_rig.input_mean(r, theta).at[7].set(h).at[8].set(0.0)  # the aim point: H_p - R_h = h
            p = pointing(jnp.asarray(inputs), true_rig.omni.profile)
            out.append({"pan_deg": round(math.degrees(float(p.pan)) / STEP_DEG) * STEP_DEG,
                        "tilt_deg": round(math.degrees(float(p.tilt)) / STEP_DEG) * STEP_DEG,
                        "x": cx, "y": cy, "height_m": h})
    return out


def calibrate(seed: int, folder: Path, click_sd_px: float) -> dict:
    import numpy as np

    t = truth(seed)
    folder.mkdir(parents=True)
    shutil.copy(SCENARIO.parent.parent / "paper.toml", folder / "paper.toml")
    (folder / "scenario.toml").write_text(SCENARIO.read_text().replace('rig = "../paper.toml"', 'rig = "paper.toml"'))
    marks = aims(t["rig"], np.random.default_rng(seed), click_sd_px)
    args = ["--scenario", str(folder / "scenario.toml"), "--seed", str(seed), "--frames", "30000",
            "--background-seconds", "0", "--no-video", "--max-seconds", "900"]
    refused = 0
    with ServedDemo(args, folder / "out") as demo:
        for m in marks:
            code, body = demo.call("POST", "/api/ptz", {"pan_deg": m["pan_deg"], "tilt_deg": m["tilt_deg"],
                                                       "zoom": 1.0, "seconds": 600})
            if code != 200:
                raise SystemExit(f"seed {seed}: POST /api/ptz: {code} {body}")
            code, body = demo.call("POST", "/api/calibration/mark", {"x": m["x"], "y": m["y"],
                                                                     "height_m": m["height_m"]})
            if code == 422 and "limit" in body.get("error", ""):
                refused += 1  # beyond the PTZ's reach: an operator cannot centre it (the assistant says so)
                continue
            if code != 200:
                raise SystemExit(f"seed {seed}: POST /api/calibration/mark: {code} {body}")
        code, report = demo.call("POST", "/api/calibration/fit")
        if code != 200 or report.get("error"):
            raise SystemExit(f"seed {seed}: the fit failed: {code} {report.get('error')}")
    params = report["result"]["params"]
    rows = {}
    for name, true_value in t["values"].items():
        if name in params:
            p = params[name]
            rows[name] = {"fit": p["value"], "sigma": p["sigma"], "truth": true_value, "unit": p.get("unit"),
                          "nees": (p["value"] - true_value) ** 2 / p["sigma"] ** 2}
    return {"seed": seed, "aims": len(marks) - refused, "refused": refused,
            "rms_residual_deg": report["result"]["rms_residual_deg"],
            "params": rows, "nees_mean": statistics.fmean(r["nees"] for r in rows.values())}


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--seeds", type=int, nargs="+", default=[9101, 9102, 9103])
    p.add_argument("--click-sd-px", type=float, default=1.0, help="the operator's click error per axis (px)")
    p.add_argument("--json", action="store_true", help="print JSON instead of the tables")
    args = p.parse_args(argv)
    if any(s < 0 for s in args.seeds) or not 0 <= args.click_sd_px <= 20:
        p.error("--seeds: expected integers >= 0; --click-sd-px: expected 0 to 20 px")
    base = Path(tempfile.mkdtemp(prefix="console_calibration_"))
    try:
        runs = [calibrate(seed, base / str(seed), args.click_sd_px) for seed in args.seeds]
    finally:
        shutil.rmtree(base, ignore_errors=True)
    if args.json:
        print(json.dumps(runs, indent=2))
        return 0
    for run in runs:
        print(f"seed {run['seed']}: {run['aims']} aims ({run['refused']} refused: beyond the PTZ's reach), "
              f"rms residual {run['rms_residual_deg']:.3f} deg, mean NEES {run['nees_mean']:.2f}")
        print("| parameter | fit | sigma | truth | fit - truth | NEES |")
        print("| --- | --- | --- | --- | --- | --- |")
        for name, r in run["params"].items():
            print(f"| {name} ({r['unit']}) | {r['fit']:.5g} | {r['sigma']:.3g} | {r['truth']:.5g} | "
                  f"{r['fit'] - r['truth']:+.3g} | {r['nees']:.2f} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
