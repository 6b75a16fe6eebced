"""``omnijax validate``: characterise a rig: theory against simulation, with maps."""

from __future__ import annotations

import argparse
import time

HELP = "characterise a rig: eq 5 and the pointing variances against Monte Carlo, with maps"
DESCRIPTION = """\
Writes DIR/report.json and PNG maps beside it:

  chroma   eq 5 against J sigma^2 I J^T and against Monte Carlo on the paper's
           B = 50 grid (figure 9): chroma.png
  ptz      var(sin pan), var(tan tilt), var(pan), var(tilt) over the floor by
           autodiff, analytic (eq 13/14), second order and Monte Carlo, and their
           relative differences (figure 10): ptz_sin_pan.png, ptz_tan_tilt.png,
           ptz_pan.png, ptz_tilt.png

The report's ptz keys summarise where the person is at least --min-distance
from the PTZ's foot; per_quantity says where each worst case is.
"""


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("validate", help=HELP, description=DESCRIPTION,
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--config", required=True, metavar="FILE", help="rig TOML file")
    p.add_argument("--out", required=True, metavar="DIR", help="output folder (created)")
    p.add_argument("--quick", action="store_true",
                   help="coarser grids and fewer Monte Carlo trials (CI-sized, under a minute)")
    p.add_argument("--grid-step", type=float, metavar="PX",
                   help="floor grid spacing in omni-image pixels (default: image width / 80; --quick / 40)")
    p.add_argument("--min-distance", type=float, default=1.0, metavar="M",
                   help="compare with Monte Carlo only this far from the PTZ's foot (default 1 m)")
    p.add_argument("--rel-tol", type=float, metavar="REL",
                   help="Monte Carlo tolerance of the variances, 95%% (default 0.01; --quick 0.03)")
    p.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    import platform

    import jax
    from tqdm import tqdm

    from runtime.cli import UsageError
    from runtime.config_io import load_rig
    from runtime.output import dumps, staged_output
    from runtime.plots import chroma_figure, ptz_figure
    from runtime.validation import QUANTITIES, chroma_check, ptz_check

    rig = load_rig(args.config)
    width = rig.omni.image_size[0]
    step = args.grid_step or width / (40 if args.quick else 80)
    rel_tol = args.rel_tol or (0.03 if args.quick else 0.01)
    if not step > 0:
        raise UsageError(f"--grid-step: expected a positive number of pixels, got {step}")
    if not 0 < rel_tol < 1:
        raise UsageError(f"--rel-tol: expected a number in (0, 1), got {rel_tol}")
    if not args.min_distance >= 0:
        raise UsageError(f"--min-distance: expected metres >= 0, got {args.min_distance}")

    t0 = time.perf_counter()
    report: dict = {"config": str(args.config), "camera_model": rig.omni.model, "quick": args.quick,
                    "seed": args.seed}
    with staged_output(args.out) as stage, tqdm(total=6, desc="validate", unit="step") as bar:
        bar.set_postfix_str("chroma: eq 5 vs Monte Carlo")
        sigma = float(rig.detection.sensor_sigma)
        chroma, chroma_maps = chroma_check(sigma, samples=20_000 if args.quick else 100_000,
                                           step=16 if args.quick else 8, seed=args.seed)
        report["chroma"] = chroma
        chroma_figure(chroma_maps, stage / "chroma.png", chroma["blue"], sigma)
        bar.update(1)

        def progress(stage_name, frac):
            bar.set_postfix_str(f"ptz: {stage_name} {100 * frac:.0f}%")

        ptz, maps = ptz_check(rig, step_px=step, min_distance=args.min_distance, rel_tol=rel_tol,
                              max_trials=100_000 if args.quick else 400_000, seed=args.seed,
                              progress=progress)
        report["ptz"] = ptz
        bar.update(1)
        for q in QUANTITIES:
            bar.set_postfix_str(f"maps: {q}")
            ptz_figure(maps, rig, q, stage / f"ptz_{q}.png", args.min_distance)
            bar.update(1)
        report["seconds"] = time.perf_counter() - t0
        report["versions"] = {"python": platform.python_version(), "jax": jax.__version__}
        (stage / "report.json").write_text(dumps(report) + "\n")
    c, p = report["chroma"], report["ptz"]
    print(f"chroma: eq 5 vs Monte Carlo max rel {c['max_rel_diff']:.4f} "
          f"(sampling ~{c['expected_sampling_rel']:.4f}); eq 5 vs jax Jacobian {c['eq5_vs_jacobian_max_rel']:.1e}")
    print(f"ptz ({p['points_compared']} points >= {p['min_distance_m']} m from the PTZ): "
          f"autodiff vs MC {p['autodiff_vs_mc_max_rel']:.4f}, analytic vs MC {p['analytic_vs_mc_max_rel']:.3f}, "
          f"autodiff vs analytic {p['autodiff_vs_analytic_max_rel']:.3f}; MC {p['montecarlo']['trials']} trials, "
          f"tolerance {p['montecarlo']['tolerance']:.4f}")
    print(f"wrote {args.out}/report.json and maps in {report['seconds']:.1f} s")
    return 0
