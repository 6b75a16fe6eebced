"""``omnijax calibrate``: the omni image's centre and rim, the rig and the PTZ's zero offsets, with sigmas."""

from __future__ import annotations

import argparse
import math

HELP = "calibrate a rig from a frame and PTZ observations (or simulate calibrations)"
DESCRIPTION = """\
From one omni frame: the mirror rim / fisheye image circle (centre and r_m, with
their covariance). From observations (OBS.json, see docs/calibration.md): H_o, D_c,
theta_c, H_f and the PTZ's pan/tilt zero offsets by least squares, with their
covariance; the observations' own noise (detector, marks' heights, rim) is
carried as nuisance parameters.

  omnijax calibrate --config C --frame IMAGE --observations OBS.json --out DIR
      DIR/calibrated.toml   the rig file with the fitted values and sigmas
      DIR/calibration.json  params {name: {value, sigma, unit}}, rms_residual, ...
      DIR/residuals.png, DIR/rim.png
      DIR/<profile>.toml    with --ptz-profile: the profile with the fitted [mounting]

  omnijax calibrate --simulate N --config C --out DIR
      N simulated calibrations per K in --positions (true rig drawn from the
      rig file's sigmas): DIR/calibration.json with nees_mean per parameter and
      the sigmas against K; DIR/sigmas.png

A set-up that cannot determine the rig (too few positions, marks at one height,
positions on one line, ...) is refused with one line and exit code 2.
"""


def _floats(text: str) -> list[float]:
    try:
        return [float(v) for v in text.split(",") if v.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected comma-separated numbers, got {text!r}") from None


def _ints(text: str) -> list[int]:
    try:
        return [int(v) for v in text.split(",") if v.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected comma-separated integers, got {text!r}") from None


def add_parser(sub: argparse._SubParsersAction) -> None:
    from runtime.cli._options import add_ptz_profile_option, deprecated_alias
    from runtime.settings import finite_float

    p = sub.add_parser("calibrate", help=HELP, description=DESCRIPTION,
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--config", required=True, metavar="FILE", help="rig TOML file (the starting rig)")
    p.add_argument("--out", required=True, metavar="DIR", help="output folder (created)")
    p.add_argument("--frame", metavar="IMAGE",
                   help="one omni frame (any image OpenCV reads) to fit the rim on; without it the rig "
                        "file's centre and r_m (with its sigma_r_m) are used")
    p.add_argument("--observations", metavar="OBS", help="observations JSON (see docs/calibration.md)")
    add_ptz_profile_option(p, "PTZ device profile (name or file): its mounting directions are used, its zero "
                              "offsets are the start, and DIR/<profile>.toml gets the fitted ones", alias=False)
    p.add_argument("--simulate", type=int, metavar="N", help="run N simulated calibrations per K instead")
    p.add_argument("--positions", type=_ints, default=[4, 8, 16], metavar="K,K",
                   help="simulate: floor positions per calibration (default 4,8,16)")
    p.add_argument("--heights", type=_floats, default=[0.0, 1.5], metavar="M,M",
                   help="simulate: heights of the marks aimed at above each position (default 0,1.5 m)")
    p.add_argument("--sigma-ptz-deg", type=finite_float, default=0.1, metavar="DEG",
                   help="simulate: PTZ reading / aiming noise per axis (default 0.1 deg)")
    deprecated_alias(p, "--sigma-height", p.add_argument(
        "--sigma-height-m", type=finite_float, default=0.005, metavar="M",
        help="simulate: error of the marks' heights, as OBS.json's sigma_height_m (default 0.005 m)"))
    p.add_argument("--sigma-zero-deg", type=finite_float, default=2.0, metavar="DEG",
                   help="simulate: spread of the true pan/tilt zero offsets (default 2 deg)")
    p.add_argument("--seed", type=int, default=0, help="simulate: random seed (default 0)")
    p.add_argument("--rim-search", type=finite_float, default=0.25, metavar="FRAC",
                   help="look for the rim within the configured rim radius * (1 +- FRAC) (default 0.25)")
    p.add_argument("--max-sigma-m", type=finite_float, default=0.10, metavar="M",
                   help="refuse a rig whose fitted length sigmas exceed this (default 0.10 m)")
    p.add_argument("--max-sigma-deg", type=finite_float, default=2.0, metavar="DEG",
                   help="refuse a rig whose fitted angle sigmas exceed this (default 2 deg)")
    p.set_defaults(func=run)


def _profile(args):
    """(profile or None, its path, mounting directions, zero offsets in rad)."""
    if args.ptz_profile is None:
        return None, None, (1, 1), (0.0, 0.0)
    from runtime.cli._options import load_ptz_profile
    from runtime.ptz.profile import resolve_profile_path

    path = resolve_profile_path(args.ptz_profile)
    prof = load_ptz_profile(args.ptz_profile)
    m = prof.mounting
    return prof, path, (m.pan_direction, m.tilt_direction), (math.radians(m.pan_zero_deg),
                                                              math.radians(m.tilt_zero_deg))


def _check_args(args) -> None:
    from runtime.errors import UsageError

    if args.simulate is not None:
        if args.frame or args.observations:
            raise UsageError("--simulate runs without --frame and --observations; give one or the other")
        if args.simulate < 1:
            raise UsageError(f"--simulate: expected a number of runs >= 1, got {args.simulate}")
        if not args.positions or min(args.positions) < 3:
            raise UsageError(f"--positions: expected numbers of floor positions >= 3, got {args.positions}")
        if len(set(args.heights)) < 2 or min(args.heights) < 0:
            raise UsageError(f"--heights: expected two different mark heights >= 0 at least, got {args.heights}")
        for flag, v in (("--sigma-ptz-deg", args.sigma_ptz_deg), ("--sigma-height-m", args.sigma_height_m),
                        ("--sigma-zero-deg", args.sigma_zero_deg)):
            if not (v >= 0 and math.isfinite(v)):
                raise UsageError(f"{flag}: expected a finite sigma >= 0, got {v}")
        if not args.sigma_ptz_deg > 0:
            raise UsageError("--sigma-ptz-deg: expected a sigma > 0 (the readings' weights)")
    elif not args.observations:
        raise UsageError("expected --observations OBS.json (with --frame IMAGE), or --simulate N")
    if not 0 < args.rim_search < 1:
        raise UsageError(f"--rim-search: expected a fraction in (0, 1), got {args.rim_search}")
    if not (args.max_sigma_m > 0 and args.max_sigma_deg > 0):
        raise UsageError("--max-sigma-m, --max-sigma-deg: expected positive bounds")


def run(args: argparse.Namespace) -> int:
    _check_args(args)
    from runtime.files import load_rig

    rig = load_rig(args.config)
    profile = _profile(args)
    if args.simulate is not None:
        return _simulate(args, rig, profile)
    return _calibrate(args, rig, profile)


def _read_frame(path: str, size: tuple[int, int]):
    import cv2
    import numpy as np

    from runtime.errors import UsageError

    img = cv2.imread(path, cv2.IMREAD_GRAYSCALE)
    if img is None:
        raise UsageError(f"--frame: cannot read {path!r} as an image")
    if (img.shape[1], img.shape[0]) != tuple(size):
        raise UsageError(f"--frame: {path} is {img.shape[1]}x{img.shape[0]} px, the rig's omni.image_size is "
                         f"{size[0]}x{size[1]}")
    return img.astype(np.float32)


def _read_json(path: str):
    from runtime.errors import UsageError
    from runtime.files import read_json

    try:
        return read_json(path, "observations file (JSON)", UsageError)
    except UsageError as exc:
        raise UsageError(f"--observations: {exc}") from None


def _calibrate(args, rig, profile) -> int:
    import datetime
    from pathlib import Path

    import numpy as np

    from omnijax import PARAM_NAMES, fit_rim
    from runtime.calibration.plots import residual_figure, rim_figure
    from runtime.calibration.runs import (
        CHI2_P_MIN,
        CalibrationError,
        calibrated_profile,
        calibrated_toml,
        check_fit,
        check_limits,
        check_setup,
        chi2_p_value,
        config_prior,
        face_widths,
        fit_observations,
        params_report,
        parse_observations,
        rim_prior,
        with_sigmas,
    )
    from runtime.errors import UsageError
    from runtime.files import load_rig
    from runtime.output import dumps, staged_output
    from runtime.ptz.profile import load_profile

    prof, prof_path, direction, zero = profile
    gray = _read_frame(args.frame, rig.omni.image_size) if args.frame else None
    obs = parse_observations(_read_json(args.observations), rig, direction, source=args.observations)
    check_setup(obs, rig, args.observations)
    check_limits(obs, prof, args.observations)

    rim = edges = rim_report = None
    if gray is None:
        prior = config_prior(rig)
    else:
        c = rig.omni.center
        rim, edges = fit_rim(gray, (float(c[0]), float(c[1])), float(rig.omni.rim), search=args.rim_search)
        n_ok = int(np.asarray(edges.ok).sum())
        if not bool(rim.converged) or int(rim.inliers) < 0.25 * edges.ok.shape[0]:
            raise UsageError(f"--frame: no rim found ({int(rim.inliers)} of {n_ok} edge points agree on a circle); "
                             f"check omni.center and the rim radius in {args.config} "
                             f"(searched +-{args.rim_search:.0%})")
        prior, rim_report = rim_prior(rig, rim)
    fit = fit_observations(rig, obs, prior, zero)
    why = check_fit(fit, args.max_sigma_m, args.max_sigma_deg)
    if why is not None:
        raise CalibrationError(f"{args.observations}: {why}")

    p_value = chi2_p_value(fit)
    scale = float(fit.chi2) / fit.dof if p_value < CHI2_P_MIN else 1.0
    values = np.asarray(fit.values)
    cov = np.asarray(fit.cov) * scale
    sigmas = np.sqrt(np.diag(cov))
    v, s = dict(zip(PARAM_NAMES, values)), dict(zip(PARAM_NAMES, sigmas))
    res = np.concatenate([np.asarray(fit.pan_residual), np.asarray(fit.tilt_residual)])
    mounting = {
        "pan_zero_deg": math.degrees(v["pan_zero"]), "sigma_pan_zero_deg": math.degrees(s["pan_zero"]),
        "tilt_zero_deg": math.degrees(v["tilt_zero"]), "sigma_tilt_zero_deg": math.degrees(s["tilt_zero"]),
        "pan_direction": direction[0], "tilt_direction": direction[1],
        "profile": str(prof_path) if prof_path else None,
    }
    estimated = {n: s[n] for n in ("H_o", "H_f", "D_c", "theta_c", "r_m")}
    stamp = datetime.datetime.now(datetime.UTC).strftime("%Y-%m-%d %H:%M UTC")
    source = f"{args.frame} and {args.observations}" if args.frame else args.observations
    header = (f"Calibrated by `omnijax calibrate` on {stamp} from {source};\n"
              f"started from {args.config}. Sigmas are the fit's (see calibration.json).")
    report = {
        "config": str(args.config), "frame": args.frame, "observations": str(args.observations),
        "camera_model": rig.omni.model,
        "params": params_report(values, sigmas),
        "rms_residual": float(np.sqrt(np.mean(res**2))),
        "rms_residual_deg": math.degrees(float(np.sqrt(np.mean(res**2)))),
        "chi2": float(fit.chi2), "dof": fit.dof, "chi2_p_value": p_value,
        "covariance_scaled": scale != 1.0, "covariance_scale": scale,
        "condition": float(fit.singular[-1] / fit.singular[0]),
        "covariance": {"names": list(PARAM_NAMES), "matrix": cov},
        "mounting": mounting,
        "rim": rim_report,
        "observations_used": {"positions": int(obs.r_f.shape[0]), "aims": int(obs.pan.shape[0]),
                              "heights_m": sorted(set(np.round(np.asarray(obs.height), 4).tolist()))},
        "residuals_deg": {"pan": np.degrees(np.asarray(fit.pan_residual)),
                          "tilt": np.degrees(np.asarray(fit.tilt_residual))},
        "zoom": {
            "assumed": face_widths(rig),
            "estimated": face_widths(with_sigmas(rig, estimated)),
            "estimated_with_mounting": face_widths(with_sigmas(rig, estimated), (s["pan_zero"], s["tilt_zero"])),
        },
    }
    out = Path(args.out)
    with staged_output(out) as stage:
        (stage / "calibrated.toml").write_text(calibrated_toml(Path(args.config), out, rig, values, sigmas, header))
        load_rig(stage / "calibrated.toml")  # what we write must load
        if prof_path is not None:
            name = f"{prof_path.stem}.toml"
            (stage / name).write_text(calibrated_profile(prof_path, mounting["pan_zero_deg"],
                                                         mounting["tilt_zero_deg"], header))
            load_profile(stage / name)
            report["mounting"]["written"] = name
        oc = rim_report.get("ocamcalib") if rim_report else None
        if gray is not None:
            file_circle = (*oc["file_center"], oc["file_rim_px"]) if oc else None
            rim_figure(gray, rim, edges, stage / "rim.png", file_circle)
        residual_figure(fit, obs, stage / "residuals.png", rim, edges)
        (stage / "calibration.json").write_text(dumps(report) + "\n")

    if rim is not None:
        sd = rim_report["sigma"]
        print(f"rim: centre ({float(rim.center[0]):.2f}, {float(rim.center[1]):.2f}) px, radius "
              f"{float(rim.radius):.2f} px (sigma {sd['center_x']:.2f}, {sd['center_y']:.2f}, {sd['radius']:.2f}; "
              f"residual scale {rim_report['scale_px']:.2f} px)")
    if oc:
        print(f"rim vs {rig.omni.model} file: centre {oc['center_offset_px']:.1f} px apart, radius - file rim "
              f"{oc['radius_minus_file_rim_px']:+.1f} px (the file's centre and r_m are kept)")
    for n in PARAM_NAMES:
        unit = PARAM_UNITS_SHOWN[n]
        k = math.degrees(1) if unit == "deg" else 1.0
        print(f"  {n:10s} {v[n] * k:12.5f} +- {s[n] * k:.5f} {unit}")
    print(f"readings: rms {report['rms_residual_deg']:.3f} deg, chi2 {float(fit.chi2):.1f} on {fit.dof} dof "
          f"(p = {p_value:.3f})" + (f"; covariance scaled by {scale:.2f}" if scale != 1.0 else ""))
    print(f"wrote {out}/calibrated.toml, calibration.json, residuals.png" + (", rim.png" if rim else "")
          + (f", {report['mounting']['written']}" if prof_path is not None else ""))
    return 0


PARAM_UNITS_SHOWN = {"H_o": "m", "D_c": "m", "theta_c": "deg", "H_f": "m", "pan_zero": "deg",
                     "tilt_zero": "deg", "center_x": "px", "center_y": "px", "r_m": "px"}


def _simulate(args, rig, profile) -> int:
    import time
    from pathlib import Path

    import jax.numpy as jnp
    from tqdm import tqdm

    from omnijax import PARAM_NAMES, SimulationSettings
    from runtime.calibration.plots import sigma_figure
    from runtime.calibration.runs import face_widths, simulate_many, with_sigmas
    from runtime.output import dumps, staged_output

    _, prof_path, direction, zero = profile
    settings = SimulationSettings(
        heights=jnp.asarray(args.heights, float), sigma_ptz=jnp.asarray(math.radians(args.sigma_ptz_deg)),
        sigma_height=jnp.asarray(args.sigma_height_m), sigma_zero=jnp.asarray(math.radians(args.sigma_zero_deg)),
        zero=jnp.asarray(zero), sigma_center=rig.sigmas.r_m, direction=jnp.asarray(direction, float),
        min_ptz_distance=jnp.asarray(0.5),
    )
    t0 = time.perf_counter()
    by_positions = []
    with tqdm(total=args.simulate * len(args.positions), desc="calibrate --simulate", unit="run") as bar:
        for K in args.positions:
            bar.set_postfix_str(f"K = {K}")
            by_positions.append(simulate_many(rig, settings, K, args.simulate, args.seed, args.max_sigma_m,
                                              args.max_sigma_deg, progress=bar.update))
    counted = sum(b["counted"] for b in by_positions)
    if counted == 0:
        from runtime.errors import UsageError

        raise UsageError("--simulate: no simulated calibration gave a determined rig; raise --max-sigma-m / "
                         "--max-sigma-deg or use more --positions")
    nees = {n: sum(b["nees_mean"][n] * b["counted"] for b in by_positions) / counted for n in PARAM_NAMES}
    s = rig.sigmas
    assumed = {"H_o": float(s.H_o), "D_c": float(s.D_c), "theta_c": float(s.theta_c), "H_f": float(s.H_f),
               "r_m": float(s.r_m)}
    best = by_positions[-1]["sigma_median"]
    estimated = {n: best[n] for n in ("H_o", "H_f", "D_c", "theta_c", "r_m")}
    report = {
        "config": str(args.config), "camera_model": rig.omni.model, "simulate": args.simulate, "seed": args.seed,
        "settings": {"positions": args.positions, "heights_m": args.heights, "sigma_ptz_deg": args.sigma_ptz_deg,
                     "sigma_height_m": args.sigma_height_m, "sigma_zero_deg": args.sigma_zero_deg,
                     "sigma_center_px": float(s.r_m), "sigma_r_f": float(rig.detection.sigma_r_f),
                     "sigma_theta_f_deg": math.degrees(float(rig.detection.sigma_theta_f)),
                     "profile": str(prof_path) if prof_path else None},
        "nees_mean": nees,
        "runs_counted": counted,
        "by_positions": by_positions,
        "sigma": {n: {str(b["positions"]): b["sigma_median"][n] for b in by_positions} for n in PARAM_NAMES},
        "assumed_sigma": assumed,
        "zoom": {
            "positions_for_estimated": by_positions[-1]["positions"],
            "assumed": face_widths(rig),
            "estimated": face_widths(with_sigmas(rig, estimated)),
            "estimated_with_mounting": face_widths(with_sigmas(rig, estimated),
                                                   (best["pan_zero"], best["tilt_zero"])),
        },
    }
    out = Path(args.out)
    with staged_output(out) as stage:
        sigma_figure(by_positions, assumed, stage / "sigmas.png")
        report["seconds"] = time.perf_counter() - t0
        (stage / "calibration.json").write_text(dumps(report) + "\n")
    print("mean NEES over " + f"{counted} runs: " + ", ".join(f"{n} {nees[n]:.2f}" for n in PARAM_NAMES))
    for b in by_positions:
        sm = b["sigma_median"]
        print(f"K = {b['positions']:3d} ({b['counted']}/{b['runs']} counted): sigma H_o {100 * sm['H_o']:.2f} cm, "
              f"D_c {100 * sm['D_c']:.2f} cm, H_f {100 * sm['H_f']:.2f} cm, theta_c {math.degrees(sm['theta_c']):.3f} "
              f"deg, pan zero {math.degrees(sm['pan_zero']):.3f} deg, "
              f"tilt zero {math.degrees(sm['tilt_zero']):.3f} deg")
    print(f"wrote {out}/calibration.json and sigmas.png in {report['seconds']:.1f} s")
    return 0
