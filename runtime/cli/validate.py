"""``omnijax validate``: characterise a rig: theory against simulation, with maps."""

from __future__ import annotations

import argparse
import threading
import time
from concurrent.futures import ThreadPoolExecutor

HELP = "characterise a rig: eq 5 and the pointing variances against Monte Carlo, with maps"
DESCRIPTION = """\
Writes DIR/report.json and PNG maps beside it:

  chroma   eq 5 against J sigma^2 I J^T and against Monte Carlo on the paper's
           B = 50 grid (figure 9): chroma.png
  ptz      var(sin pan), var(tan tilt), var(pan), var(tilt) over the floor by
           autodiff, analytic (eq 13/14), second order and Monte Carlo, and their
           relative differences (figure 10): ptz_sin_pan.png, ptz_tan_tilt.png,
           ptz_pan.png, ptz_tilt.png

  table1   the paper's Table 1 end to end on rendered frames: a person stands
           still at eight positions P1-P8, each trial a fresh person (height,
           head, clothing from the priors) with fresh sensor noise, moved by up
           to half a pixel of radius and half a radial line of azimuth around
           the position (so that the polar grid's quantisation is random across
           trials, as the prediction treats it), through the detector; one fixed
           rig, predicted with the detection sigmas and the person priors (no
           calibration sigmas). Measured: the mean squared error of the pointing
           about the truth (bias included); ratio = predicted variance / measured,
           with its standard error. As many trials per position as put both
           ratios' relative standard error at --ratio-se (at most --trials).
           Beside each row, labelled paper_fixed_position: --paper-trials at the
           exact position and the variance about their mean, as the paper
           measured it. table1.png, table1_positions.png
  table1_full_propagation
           the same (jittered) with a fresh true rig and person per trial
           (--fresh-trials), the pointing error against the full propagation
  pointing the NEES of the aimed pan/tilt against the true head direction
           under the aim's covariance over the fresh-rig trials (each one a PTZ
           aimed and arrived, as the loop aims)
  rates    false alarms per radial line on empty frames against x_f, misses per
           person trial against x_m, with 95 % intervals
  containment
           how often the true head disc lies in the foveal frame at the zoom of
           each rule (paper, calibrated) for p_contain 0.9, 0.95, 0.99 (and the
           rig's): containment.png

and DIR/report.md, every table and figure with a sentence of what it shows.
Compiled programs are cached in --cache-dir (JAX's persistent compilation
cache), so later runs skip most of the compilation; --no-cache compiles afresh.
The report's ptz keys summarise where the person is at least --min-distance
from the PTZ's foot; per_quantity says where each worst case is.
"""


#: Table 1's sequential sample (runtime.validation.endtoend.MIN_TRIALS, ROUND_TRIALS; not imported here,
#: which would load JAX for --help): the standard error is first looked at after MIN_TRIALS trials.
MIN_TRIALS, ROUND_TRIALS = 400, 200


def add_parser(sub: argparse._SubParsersAction) -> None:
    from runtime.cli._options import add_cache_options, deprecated_alias
    from runtime.settings import finite_float

    p = sub.add_parser("validate", help=HELP, description=DESCRIPTION,
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--config", required=True, metavar="FILE", help="rig TOML file")
    p.add_argument("--out", required=True, metavar="DIR", help="output folder (created)")
    p.add_argument("--quick", action="store_true",
                   help="coarser grids and fewer Monte Carlo trials (CI-sized, under a minute)")
    deprecated_alias(p, "--grid-step", p.add_argument(
        "--grid-step-px", type=finite_float, metavar="PX",
        help="floor grid spacing in omni-image pixels (default: image width / 80; --quick / 40)"))
    p.add_argument("--min-distance", type=finite_float, default=1.0, metavar="M",
                   help="compare with Monte Carlo only this far from the PTZ's foot (default 1 m)")
    p.add_argument("--rel-tol", type=finite_float, metavar="REL",
                   help="Monte Carlo tolerance of the variances, 95%% (default 0.01; --quick 0.03)")
    p.add_argument("--trials", type=int, metavar="N",
                   help="Table 1 frames per position, fixed rig: at most N, fewer once --ratio-se is reached "
                        "(default 4000; --quick 40, all of them)")
    p.add_argument("--ratio-se", type=finite_float, metavar="REL",
                   help="stop a position's Table 1 trials once both ratios' relative standard error is at most "
                        f"REL, looked at after {MIN_TRIALS} trials and every {ROUND_TRIALS} more (default 0.035; "
                        "--quick: off; 0: off, exactly --trials)")
    p.add_argument("--paper-trials", type=int, metavar="N",
                   help="frames per position at the exact position, for the paper's fixed-position variance "
                        "(default 100, the paper's; --quick 25)")
    p.add_argument("--fresh-trials", type=int, metavar="N",
                   help="frames per position with a fresh rig and person each (default 500; --quick 24)")
    p.add_argument("--empty-frames", type=int, metavar="N",
                   help="empty frames for the false-alarm rate (default 500; --quick 40)")
    p.add_argument("--scenario", metavar="S",
                   help="scenario TOML, or a name in configs/scenarios, for the rendered frames (its room, lamps, "
                        "furniture, sensor; the rig is --config's); default: a plain room on the rig's outline")
    p.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    add_cache_options(p)
    p.set_defaults(func=run)


def _counts(args) -> tuple[int, int, int, int, float | None]:
    """Frames per position (Table 1 at most, paper's fixed position, fresh rig), empty frames, and
    Table 1's target relative standard error (``None``: exactly the Table 1 frames)."""
    from runtime.errors import UsageError

    quick = args.quick
    given = (args.trials, args.paper_trials, args.fresh_trials, args.empty_frames)
    defaults = (40, 25, 24, 40) if quick else (4000, 100, 500, 500)
    n = tuple(d if v is None else v for v, d in zip(given, defaults))
    for name, v in zip(("--trials", "--paper-trials", "--fresh-trials", "--empty-frames"), n):
        if v < 8:
            raise UsageError(f"{name}: expected at least 8 frames, got {v}")
    rel = args.ratio_se if args.ratio_se is not None else (None if quick else 0.035)
    if rel is not None and not 0 <= rel < 1:
        raise UsageError(f"--ratio-se: expected a relative standard error in [0, 1), got {rel:g}")
    return (*n, rel or None)


def _scenario(args, rig):
    from omnijax.world import parse_scenario
    from runtime.cli._options import scenario_file
    from runtime.files import read_toml
    from runtime.validation.endtoend import table1_scenario

    if args.scenario is None:
        return table1_scenario(rig, args.seed), "a plain room on the rig's floor outline"
    path = scenario_file(args.scenario)
    return parse_scenario(read_toml(path, "scenario file"), rig, source=str(path)), str(path)


def run(args: argparse.Namespace) -> int:
    import platform

    import jax
    from tqdm import tqdm

    from runtime.cli._options import enable_cache
    from runtime.errors import UsageError
    from runtime.files import load_rig
    from runtime.output import dumps, staged_output
    from runtime.validation.plots import chroma_figure, ptz_figure
    from runtime.validation.report import report_markdown
    from runtime.validation.theory import QUANTITIES, chroma_check, ptz_check

    # a value given is checked, never replaced by the default
    if args.grid_step_px is not None and not args.grid_step_px > 0:
        raise UsageError(f"--grid-step-px: expected a positive number of pixels, got {args.grid_step_px:g}")
    if args.rel_tol is not None and not 0 < args.rel_tol < 1:
        raise UsageError(f"--rel-tol: expected a number in (0, 1), got {args.rel_tol:g}")
    if not args.min_distance >= 0:
        raise UsageError(f"--min-distance: expected metres >= 0, got {args.min_distance:g}")
    counts = _counts(args)
    rig = load_rig(args.config)
    width = rig.omni.image_size[0]
    step = args.grid_step_px if args.grid_step_px is not None else width / (40 if args.quick else 80)
    if not 1 <= step <= width / 4:
        raise UsageError(f"--grid-step-px: expected 1 px (a point per pixel) to a quarter of the omni image's width "
                         f"({width / 4:g} px), got {step:g}")
    rel_tol = args.rel_tol if args.rel_tol is not None else (0.03 if args.quick else 0.01)

    scenario, scenario_name = _scenario(args, rig)
    enable_cache(args)

    t0 = time.perf_counter()
    report: dict = {"config": str(args.config), "camera_model": rig.omni.model, "quick": args.quick,
                    "seed": args.seed}
    timing: dict = {}
    # the figures are drawn on one thread of their own (matplotlib's pyplot is used by no other) once the
    # rendered trials have started (``go``: their set-up traces Python as the figures do; the trials run
    # compiled code): they took 6-8 s of a 60-s `validate --quick`, mostly matplotlib's constrained layout
    go = threading.Event()
    with staged_output(args.out) as stage, tqdm(total=7, desc="validate", unit="step") as bar, \
            ThreadPoolExecutor(max_workers=1, thread_name_prefix="figures") as figures:
        figures.submit(go.wait)
        try:
            drawn = []

            def draw(figure, *figure_args) -> None:
                drawn.append(figures.submit(figure, *figure_args))

            bar.set_postfix_str("chroma: eq 5 vs Monte Carlo")
            sigma = float(rig.detection.sensor_sigma)
            chroma, chroma_maps = chroma_check(sigma, samples=20_000 if args.quick else 100_000,
                                               step=16 if args.quick else 8, seed=args.seed)
            report["chroma"] = chroma
            draw(chroma_figure, chroma_maps, stage / "chroma.png", chroma["blue"], sigma)
            bar.update(1)

            def progress(stage_name, frac):
                bar.set_postfix_str(f"ptz: {stage_name} {100 * frac:.0f}%")

            ptz, maps = ptz_check(rig, step_px=step, min_distance=args.min_distance, rel_tol=rel_tol,
                                  max_trials=100_000 if args.quick else 400_000, seed=args.seed,
                                  progress=progress)
            report["ptz"] = ptz
            bar.update(1)
            for q in QUANTITIES:
                draw(ptz_figure, maps, rig, q, stage / f"ptz_{q}.png", args.min_distance)
            timing["chroma_ptz_maps_s"] = time.perf_counter() - t0
            bar.set_postfix_str("Table 1, rates, containment: rendering and detecting")
            _end_to_end(args, rig, scenario, scenario_name, counts, report, timing, stage, draw, go)
            bar.update(1)
            bar.set_postfix_str("figures")
            t = time.perf_counter()
            for done in drawn:
                done.result()  # a figure that failed fails the run here, before report.json is written
            timing["figures_wait_s"] = time.perf_counter() - t
            bar.update(bar.total - bar.n)
            report["seconds"] = time.perf_counter() - t0
            report["timing"] = timing
            report["versions"] = {"python": platform.python_version(), "jax": jax.__version__}
            (stage / "report.json").write_text(dumps(report) + "\n")
            (stage / "report.md").write_text(report_markdown(report) + "\n")
        except BaseException:  # a failure (or Ctrl-C) draws no more figures; the one being drawn ends
            figures.shutdown(wait=False, cancel_futures=True)
            raise
        finally:
            go.set()  # never leave the figures' thread waiting for the trials
    c, p = report["chroma"], report["ptz"]
    print(f"chroma: eq 5 vs Monte Carlo max rel {c['max_rel_diff']:.4f} "
          f"(sampling ~{c['expected_sampling_rel']:.4f}); eq 5 vs jax Jacobian {c['eq5_vs_jacobian_max_rel']:.1e}")
    print(f"ptz ({p['points_compared']} points >= {p['min_distance_m']} m from the PTZ): "
          f"autodiff vs MC {p['autodiff_vs_mc_max_rel']:.4f}, analytic vs MC {p['analytic_vs_mc_max_rel']:.3f}, "
          f"autodiff vs analytic {p['autodiff_vs_analytic_max_rel']:.3f}; MC {p['montecarlo']['trials']} trials, "
          f"tolerance {p['montecarlo']['tolerance']:.4f}")
    ratios = lambda rows, q: " ".join("n/a" if r[f"ratio_{q}"] is None
                                      else f"{r[f'ratio_{q}']:.3f}+-{r[f'ratio_{q}_se']:.3f}" for r in rows)
    for name in ("table1", "table1_full_propagation"):
        rows = report[name]
        print(f"{name} (predicted variance / mean squared error about the truth, +- one standard error), "
              f"P1..P{len(rows)}, trials {'/'.join(str(r['trials']) for r in rows)}:\n"
              f"  tan tilt {ratios(rows, 'tan_tilt')}\n  sin pan  {ratios(rows, 'sin_pan')}")
    paper = [r["paper_fixed_position"] for r in report["table1"]]
    print(f"table1, the paper's fixed-position variance ({paper[0]['trials']} trials): "
          f"tan tilt {ratios(paper, 'tan_tilt')}; sin pan {ratios(paper, 'sin_pan')}")
    pt = report["pointing"]
    print(f"pointing (fresh-rig trials): NEES mean per dof {pt['nees_mean']:.3f}, P(NEES > 5.99) "
          f"{pt['nees_over_5_99']:.3f} over {pt['frames']} (1 and 0.05 when the covariance is right)")
    r = report["rates"]
    print(f"rates: false alarm per line {r['false_alarm_rate']:.4f} (x_f {r['x_f']:g}), "
          f"miss {r['miss_rate']:.4f} (x_m {r['x_m']:g})")
    print("containment: " + ", ".join(f"{c['rule']} {c['p_contain']:g}: {c['rate']:.3f}"
                                      for c in report["containment"]["curve"]))
    f = report["framing"]
    print(f"framing at p_contain {f['p_contain']:g} over all {f['trials']} fresh-rig trials: " + ", ".join(
        f"{rule} {r['rate_all_trials']:.3f} (median face {r['face_px_median'] or float('nan'):.0f} px)"
        for rule, r in f["rules"].items()) + f"; aimed at no person {f['no_person_share']:.3f}, "
          f"no target {f['no_target_share']:.3f}")
    print(f"wrote {args.out}/report.json, report.md and maps in {report['seconds']:.1f} s")
    return 0


def _end_to_end(args, rig, scenario, scenario_name, counts, report, timing, stage, draw, go) -> None:
    """Table 1 (both variants), rates and containment on rendered frames, with their figures (handed to
    ``draw(figure_function, *args)``); ``go`` is set once the trials are set up (figures may be drawn)."""
    import jax
    import numpy as np
    from tqdm import tqdm

    from runtime.validation import endtoend as e
    from runtime.validation.plots import containment_figure, positions_figure, table1_figure

    n_fixed, n_paper, n_fresh, n_empty, rel_se = counts
    t = time.perf_counter()
    bench = e.prepare(rig, scenario, seed=args.seed, foot_mc_profiles=64 if args.quick else None)
    timing["world_detector_background_s"] = time.perf_counter() - t
    go.set()
    key = jax.random.key(args.seed)
    n_pos = len(bench.positions)
    fixed, paper, fresh = [], [], []
    table_s = []
    t0 = time.perf_counter()
    with tqdm(total=n_pos * (n_fixed + n_paper + n_fresh) + n_empty, desc="frames", unit="frame",
              leave=False) as bar:
        for k, foot in enumerate(bench.positions):
            t1 = time.perf_counter()
            bar.set_postfix_str(f"P{k + 1} fixed rig")
            fixed.append(e.table1_trials(bench, foot, jax.random.fold_in(key, k), n_fixed, rel_se,
                                         progress=bar.update))
            if rel_se is not None:
                bar.total -= n_fixed - len(fixed[-1].det.found)
            table_s.append(time.perf_counter() - t1)
            bar.set_postfix_str(f"P{k + 1} exact position")
            paper.append(e.trials(bench, foot, n_paper, jax.random.fold_in(key, 200 + k), "person",
                                  progress=bar.update))
            bar.set_postfix_str(f"P{k + 1} fresh rig")
            fresh.append(e.table1_trials(bench, foot, jax.random.fold_in(key, 100 + k), n_fresh, None, "rig",
                                         progress=bar.update))
        bar.set_postfix_str("empty frames")
        empty = e.trials(bench, e.AWAY, n_empty, jax.random.fold_in(key, 999), "noise", progress=bar.update)
    n_table = [len(t.det.found) for t in fixed]
    timing["frames_s"] = time.perf_counter() - t0
    timing["frames"] = sum(n_table) + n_pos * (n_paper + n_fresh) + n_empty
    t = time.perf_counter()
    names = [f"P{k + 1}" for k in range(n_pos)]
    report["table1"] = [e.table_row(rig, n, foot, tr, True, pp)
                        for n, foot, tr, pp in zip(names, bench.positions, fixed, paper)]
    for row, seconds in zip(report["table1"], table_s):
        row["seconds"] = seconds
    report["table1_full_propagation"] = [e.table_row(rig, n, foot, tr, False)
                                         for n, foot, tr in zip(names, bench.positions, fresh)]
    report["table1_summary"] = {
        "fixed_rig": e.summarise(report["table1"]), "fresh_rig": e.summarise(report["table1_full_propagation"]),
        "scenario": scenario_name, "trials_fixed_rig": n_table, "trials_fixed_rig_max": n_fixed,
        "target_ratio_rel_se": rel_se, "trials_paper_fixed_position": n_paper, "trials_fresh_rig": n_fresh,
        "seconds_fixed_rig": sum(table_s),
        "jitter": "each trial's foot moved uniformly by up to half a pixel of image radius and half a radial line "
                  "of azimuth either way from the position",
        "measured": "emp_var_*: mean squared error of the pointing about the truth, bias included; ratio_*: "
                    "pred_var_* / emp_var_* with its standard error",
        "goal": "predicted / measured within +-10 % (the paper: 18.5 %)"}
    report["rates"] = e.rates(rig, bench.detector, empty, fixed + paper + fresh)
    p_main, rule_main = float(rig.p_contain), rig.zoom_rule
    curve = e.containment(rig, e.concat(fresh), tuple(sorted({*e.P_CONTAIN, p_main})))
    main = next(c for c in curve if c["rule"] == rule_main and abs(c["p_contain"] - p_main) < 1e-12)
    report["containment"] = {**main, "curve": curve,
                             "meaning": "share of detected fresh-rig trials whose true head disc lies inside the "
                                        "foveal frame at the zoom the rule chose; curve: every rule and p_contain"}
    report["framing"] = e.framing(rig, fresh, names, p_main)
    report["pointing"] = e.pointing_report(rig, fresh)
    timing["statistics_s"] = time.perf_counter() - t
    draw(positions_figure, rig, np.asarray(bench.positions), stage / "table1_positions.png")
    draw(table1_figure, {"fixed rig: detection and person sigmas": report["table1"],
                         "fresh rig per trial, full propagation": report["table1_full_propagation"]},
         stage / "table1.png")
    draw(containment_figure, curve, stage / "containment.png")
