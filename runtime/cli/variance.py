"""``omnijax variance``: pan/tilt, their uncertainty and the zoom for one foot position."""

from __future__ import annotations

import argparse
import math

HELP = "pan/tilt, their (co)variances and the zoom for one foot position"
DESCRIPTION = """\
Propagate the uncertainty of one foot detection and of the rig's calibration to
the PTZ's pan and tilt, and choose the zoom with the rig's zoom rule.

Methods: autodiff (J Sigma J^T, J = jax.jacfwd of the geometry), analytic (the
paper's eq 13 and 14 as printed), second_order (GUM higher-order terms from
jax.hessian), montecarlo (adaptive, GUM Supplement 1).

The JSON object has pan, tilt (rad), distance_m (D_p), radius_m (R_p),
var {sin_pan, tan_tilt, pan, tilt, cov_pan_tilt}, fov {h, v} (rad), zoom,
camera_model, valid, and inputs {name: {mean, sigma}} (px, rad, m): the exact
numbers the result was computed from.

--sigma-theta-deg replaces --sigma-theta, which gave the sigma in radians (the
name the original command contract uses): --sigma-theta RAD still works, in
radians, for one release, and says so on stderr.
"""


def add_parser(sub: argparse._SubParsersAction) -> None:
    from runtime.cli._options import deprecated_alias
    from runtime.settings import Names, finite_float

    p = sub.add_parser("variance", help=HELP, description=DESCRIPTION,
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--config", required=True, metavar="FILE", help="rig TOML file")
    p.add_argument("--foot", nargs=2, type=finite_float, required=True, metavar=("R_F", "THETA_F"),
                   help="foot image radius (px from the image centre) and azimuth (rad)")
    p.add_argument("--method", default="autodiff", choices=Names("omnijax.uncertainty:METHODS"), metavar="M",
                   help="%(choices)s (default autodiff)")
    p.add_argument("--sigma-rf", type=finite_float, metavar="PX",
                   help="sigma of r_f in px (default: [detection] sigma_r_f)")
    deprecated_alias(p, "--sigma-theta", p.add_argument(
        "--sigma-theta-deg", type=finite_float, metavar="DEG",
        help="sigma of theta_f in degrees (default: [detection] sigma_theta_f_deg)"),
        dest="sigma_theta_rad", note=" (which takes degrees; --sigma-theta is in radians)")
    p.add_argument("--rel-tol", type=finite_float, default=0.005, metavar="REL",
                   help="montecarlo: relative tolerance of the variances (95%%), default 0.005")
    p.add_argument("--seed", type=int, default=0, help="montecarlo: random seed (default 0)")
    p.add_argument("--json", action="store_true", help="print one JSON object instead of a table")
    p.set_defaults(func=run)


def variance_report(rig, r_f: float, theta_f: float, method: str, sigma_r_f=None, sigma_theta_f=None,
                    rel_tol: float = 0.005, seed: int = 0) -> dict:
    """The ``omnijax variance`` JSON object (docs/design.md section 7.3) for one foot position."""
    import jax

    from omnijax import INPUT_NAMES, aim, aim_with_covariance, pointing_covariance_mc

    if method == "montecarlo":
        x = rig.input_mean(r_f, theta_f)
        sigma = rig.input_sigma(sigma_r_f, sigma_theta_f)
        mc = pointing_covariance_mc(x, sigma, rig.omni.profile, jax.random.key(seed), rel_tol=rel_tol)
        result = aim_with_covariance(rig, x, mc.covariance)
        extra = {"montecarlo": {"trials": mc.trials, "batches": mc.batches, "tolerance": mc.tolerance,
                                "rel_tol": rel_tol, "seed": seed}}
    else:
        result = aim(rig, r_f, theta_f, sigma_r_f, sigma_theta_f, method)
        x = rig.input_mean(r_f, theta_f)
        sigma = rig.input_sigma(sigma_r_f, sigma_theta_f)
        extra = {}
    p, c, z = result.pointing, result.covariance, result.zoom
    return {
        "method": method,
        "camera_model": rig.omni.model,
        "valid": bool(p.valid),
        "pan": float(p.pan),
        "tilt": float(p.tilt),
        "pan_deg": math.degrees(float(p.pan)),
        "tilt_deg": math.degrees(float(p.tilt)),
        "distance_m": float(p.distance),
        "radius_m": float(p.radius),
        "slant_m": float(p.slant),
        "var": {
            "sin_pan": float(c.var_sin_pan),
            "tan_tilt": float(c.var_tan_tilt),
            "pan": float(c.var_pan),
            "tilt": float(c.var_tilt),
            "cov_pan_tilt": float(c.cov_pan_tilt),
        },
        "fov": {"h": float(z.fov_h), "v": float(z.fov_v)},
        "fov_deg": {"h": math.degrees(float(z.fov_h)), "v": math.degrees(float(z.fov_v))},
        "zoom": float(z.zoom),
        "zoom_rule": rig.zoom_rule,
        "p_contain": float(rig.p_contain),
        "containment_probability": float(z.probability),
        "zoom_feasible": bool(z.feasible),
        "inputs": {
            name: {"mean": float(m), "sigma": float(s)} for name, m, s in zip(INPUT_NAMES, x, sigma)
        },
        **extra,
    }


def _table(rep: dict) -> str:
    lines = [
        f"method {rep['method']}, camera {rep['camera_model']}, "
        f"{'valid' if rep['valid'] else 'INVALID (horizon or at the PTZ foot)'}",
        f"pan  {rep['pan_deg']:9.3f} deg   sd {math.degrees(math.sqrt(rep['var']['pan'])):.4f} deg",
        f"tilt {rep['tilt_deg']:9.3f} deg   sd {math.degrees(math.sqrt(rep['var']['tilt'])):.4f} deg",
        f"corr(pan, tilt) {rep['var']['cov_pan_tilt'] / math.sqrt(rep['var']['pan'] * rep['var']['tilt']):+.3f}",
        f"var sin(pan) {rep['var']['sin_pan']:.4e}   var tan(tilt) {rep['var']['tan_tilt']:.4e}",
        f"R_p {rep['radius_m']:.3f} m   D_p {rep['distance_m']:.3f} m   to head {rep['slant_m']:.3f} m",
        f"zoom {rep['zoom']:.2f}x ({rep['zoom_rule']} rule)   fov {rep['fov_deg']['h']:.2f} x "
        f"{rep['fov_deg']['v']:.2f} deg   P(head in frame) {rep['containment_probability']:.4f}",
        "inputs (mean, sigma):",
    ]
    for name, v in rep["inputs"].items():
        lines.append(f"  {name:8s} {v['mean']:12.6g} {v['sigma']:12.6g}")
    if "montecarlo" in rep:
        mc = rep["montecarlo"]
        lines.append(f"montecarlo: {mc['trials']} trials, tolerance reached {mc['tolerance']:.4f}")
    return "\n".join(lines)


def run(args: argparse.Namespace) -> int:
    from runtime.errors import UsageError
    from runtime.files import load_rig
    from runtime.output import dumps

    sigma_theta_rad = getattr(args, "sigma_theta_rad", None)
    if sigma_theta_rad is not None and args.sigma_theta_deg is not None:
        raise UsageError("--sigma-theta: give --sigma-theta-deg only (--sigma-theta is its old spelling, in radians)")
    for flag, value in (("--sigma-rf", args.sigma_rf), ("--sigma-theta-deg", args.sigma_theta_deg),
                        ("--sigma-theta", sigma_theta_rad)):
        if value is not None and not (value >= 0 and math.isfinite(value)):
            raise UsageError(f"{flag}: expected a finite sigma >= 0, got {value}")
    sigma_theta = math.radians(args.sigma_theta_deg) if args.sigma_theta_deg is not None else sigma_theta_rad
    if not all(math.isfinite(v) for v in args.foot) or args.foot[0] < 0:
        raise UsageError(f"--foot: expected R_F >= 0 (px) and a finite THETA_F (rad), got {args.foot}")
    if not 0 < args.rel_tol < 1:
        raise UsageError(f"--rel-tol: expected a number in (0, 1), got {args.rel_tol}")
    rig = load_rig(args.config)
    rim = float(rig.omni.rim)
    if args.foot[0] > rim:
        raise UsageError(f"--foot: R_F = {args.foot[0]:g} px lies beyond the omni image's rim ({rim:g} px, omni.rim); "
                         "expected a radius where the mirror images the floor")
    if args.sigma_rf is not None and args.sigma_rf > rim:
        raise UsageError(f"--sigma-rf: {args.sigma_rf:g} px is larger than the omni image's rim ({rim:g} px, "
                         "omni.rim); expected a detection's sigma, a few px")
    rep = variance_report(rig, args.foot[0], args.foot[1], args.method, args.sigma_rf, sigma_theta,
                          args.rel_tol, args.seed)
    print(dumps(rep) if args.json else _table(rep))
    return 0
