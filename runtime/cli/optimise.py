"""``omnijax optimise``: where to put the PTZ camera for a room, with proof (a grid) and maps."""

from __future__ import annotations

import argparse
import importlib
import math
import time
from concurrent.futures import ThreadPoolExecutor

HELP = "optimise the PTZ placement (D_c, H_f; optionally theta_c, H_o) for the room: layout.json and maps"
DESCRIPTION = """\
Searches the PTZ camera's placement that optimises a floor-wide objective, with
optimistix BFGS from several starts in an unconstrained map of the [layout]
box, and checks it against a vmapped grid of layouts over the same box.

Objectives (per floor point, over the room's outline minus excluded zones, left
out within --near-radius of the PTZ's foot where a person cannot be framed):
  face_px   face width in foveal pixels at the zoom the rig's rule chooses for
            p_contain, within the lens's zoom range (maximised)
  variance  var(pan) + var(tilt), the paper's pan and tilt uncertainty (minimised)
each as the floor's mean or its worst case (--statistic).

Writes DIR/layout.json (D_c_m, H_f_m, objective, objective_start, grid_best
{D_c_m, H_f_m, objective}, seconds, and more: theta_c_deg, H_o_m, on_bound, every
start, every statistic before and after, the paper's findings checked on the
grid) and PNG maps in the manner of the paper's figure 12 (before and after,
contours, both cameras, the operational region where p_contain and the face
target are met): face_px_map.png, variance_map.png, pan_tilt_map.png (var sin pan
and var tan tilt, eq 14 and 13's quantities); and landscape.png (the grid over
D_c and H_f: the objective, mean var sin pan, mean var tan tilt, the other
objective).

Several PTZs (--cameras K): every camera's D_c (up to the wall along its own
azimuth), H_f and theta_c are searched at once, for k = 1 .. K cameras in turn;
the objective is, over the floor, the best camera's face (or variance) at each
point. BFGS from several starts (the objective is symmetric under exchanging
cameras), checked against every set of k placements of a grid of candidates
(--landscape values per variable, default 7). Adds to layout.json: cameras
[{D_c_m, H_f_m, theta_c_deg}], grid_best {objective, cameras, method},
marginal_gain [{k, objective, gain_rel, framing, ...}] and framing (share of
the floor where the best camera meets p_contain with a face of at least
face_target_px); maps cameras_map.png (per camera and of the best, for K) and
marginal_gain.png. A rig of several [[foveal]] tables gives each camera its
own lens and sigmas (camera i > tables: the last table's).

Flags override the [layout] keys they name (--grid-step-m: grid_step; see
configs/paper.toml).
The search's BFGS program compiles on a second thread while the landscape grid
runs; compiled programs are cached in --cache-dir (JAX's persistent compilation
cache), so later runs skip most of the compilation.
"""

#: Option (dest) -> [layout] key.
OVERRIDES = {"objective": "objective", "statistic": "statistic", "vary": "vary", "grid_step_m": "grid_step",
             "starts": "starts", "landscape": "landscape", "near_radius": "near_radius",
             "face_target_px": "face_target_px"}


def add_parser(sub: argparse._SubParsersAction) -> None:
    from runtime.cli._options import add_cache_options, deprecated_alias
    from runtime.settings import Names, finite_float

    p = sub.add_parser("optimise", help=HELP, description=DESCRIPTION,
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--config", required=True, metavar="FILE", help="rig TOML file")
    p.add_argument("--out", required=True, metavar="DIR", help="output folder (created)")
    p.add_argument("--objective", choices=Names("optimise:OBJECTIVES"), metavar="NAME",
                   help="what to optimise: %(choices)s (layout.objective)")
    p.add_argument("--statistic", choices=Names("optimise:STATISTICS"), metavar="NAME",
                   help="over the floor: %(choices)s (layout.statistic)")
    p.add_argument("--vary", nargs="+", choices=Names("omnijax.config:LAYOUT_NAMES"), metavar="NAME",
                   help="placement variables to search: %(choices)s (layout.vary)")
    deprecated_alias(p, "--grid-step", p.add_argument("--grid-step-m", type=finite_float, metavar="M",
                                                      help="floor grid spacing in m (layout.grid_step)"))
    p.add_argument("--starts", type=int, metavar="N", help="BFGS starts (layout.starts)")
    p.add_argument("--landscape", type=int, metavar="N", help="grid values per varied variable (layout.landscape)")
    p.add_argument("--near-radius", type=finite_float, metavar="M",
                   help="left out around the PTZ's foot, m (layout.near_radius)")
    deprecated_alias(p, "--face-target", p.add_argument(
        "--face-target-px", type=finite_float, metavar="PX",
        help="face width bounding the operational region, px (layout.face_target_px)"))
    p.add_argument("--cameras", type=int, metavar="K",
                   help="search K PTZ placements at once (and k = 1 .. K-1 for the marginal gain of each)")
    add_cache_options(p)
    p.add_argument("--no-maps", action="store_true", help="write layout.json only")
    p.set_defaults(func=run)


#: How ``layout.json`` names each placement variable (and its unit).
JSON_KEYS = {"D_c": "D_c_m", "H_f": "H_f_m", "theta_c": "theta_c_deg", "H_o": "H_o_m"}


def _json_values(names, values) -> dict:
    """Placement variables as ``layout.json`` writes them: metres, and degrees for theta_c."""
    return {JSON_KEYS[n]: math.degrees(float(v)) if n == "theta_c" else float(v) for n, v in zip(names, values)}


def _layout_keys(layout) -> dict:
    d = layout.as_dict()
    return _json_values(d.keys(), d.values())


def _findings(result, rig) -> dict | None:
    """The paper's section 6 findings, checked on the landscape grid over (D_c, H_f)."""
    import numpy as np

    names = list(result.box.names)
    if not {"D_c", "H_f"} <= set(names):
        return None
    ls = result.landscape
    best = result.box.values(result.best)
    index = tuple(slice(None) if n in ("D_c", "H_f") else int(np.argmin(np.abs(ls.axes[n] - v)))
                  for n, v in zip(names, best))
    transpose = names.index("D_c") > names.index("H_f")
    take = lambda k: ls.summaries[k][index].T if transpose else ls.summaries[k][index]
    D, H = ls.axes["D_c"], ls.axes["H_f"]

    def falls(key):  # how the mean changes along D_c, over all H_f rows
        z = take(key)
        return {"share_of_D_c_steps_falling": float((np.diff(z, axis=0) < 0).mean()),
                "D_c_of_minimum_m": float(np.median(D[np.argmin(z, axis=0)])),
                "median_at_D_c_min_max": [float(np.median(z[0])), float(np.median(z[-1]))]}

    def best_H_f(key):  # the H_f of the smallest mean, per D_c column
        h = H[np.argmin(take(key), axis=1)]
        return {"median_over_D_c_m": float(np.median(h)), "range_over_D_c_m": [float(h.min()), float(h.max())]}

    out = {
        "pan_variance_falls_with_D_c": {"var_sin_pan": falls("var_sin_pan_mean"), "var_pan": falls("var_pan_mean")},
        "tilt_variance_best_H_f": {
            "var_tan_tilt": best_H_f("var_tan_tilt_mean"), "var_tilt": best_H_f("var_tilt_mean"),
            "H_p_minus_R_h_m": float(rig.person.H_p - rig.person.R_h), "grid_spacing_m": float(H[1] - H[0]),
        },
        "grid_optimum": {},
    }
    for key, sense in (("variance_mean", 1), ("variance_worst", 1), ("face_px_mean", -1), ("face_px_worst", -1)):
        z = take(key)
        i, j = np.unravel_index(np.argmin(sense * z), z.shape)
        out["grid_optimum"][key] = {"D_c_m": float(D[i]), "H_f_m": float(H[j]), "value": float(z[i, j])}
    return out


def layout_report(result, rig, seconds: float, timing: dict, config: str) -> dict:
    """The ``layout.json`` object (docs/design.md section 7.3's keys and more)."""
    from optimise import SENSE, SHARPNESS

    spec = rig.layout
    key = f"{spec.objective}_{spec.statistic}"
    sense = SENSE[spec.objective]
    box = result.box
    gain = sense * (result.grid_objective - result.objective) / abs(result.grid_objective)
    lower, upper = _json_values(box.names, box.lower), _json_values(box.names, box.upper)
    bounds = {k: [lower[k], upper[k]] for k in lower}
    return {
        "config": config,
        **_layout_keys(result.best),
        "objective": result.objective,
        "objective_start": result.objective_start,
        "objective_name": spec.objective,
        "statistic": spec.statistic,
        "sense": "max" if sense < 0 else "min",
        "units": "px" if spec.objective == "face_px" else "rad^2",
        "start": _layout_keys(result.configured),
        "grid_best": {**_layout_keys(result.grid_best), "objective": result.grid_objective},
        "vs_grid_rel": gain,
        "on_bound": result.on_bound,
        "vary": list(box.names),
        "bounds": bounds,
        "optimiser": {
            "method": "optimistix.BFGS on u, x = lower + (upper - lower) (1 + sin u) / 2",
            "iterations": sum(s.steps for s in result.starts),
            "polished_from_grid": result.polished_from_grid,
            "starts": [{"from": _json_values(box.names, s.start), "to": _json_values(box.names, s.x),
                        "objective": s.objective, "iterations": s.steps, "converged": s.converged}
                       for s in result.starts],
            **({"sharpness": list(SHARPNESS)} if spec.statistic == "worst" else {}),
        },
        "values": {"start": result.summary_start, "optimum": result.summary_best},
        "landscape": {"cells_per_variable": spec.landscape, "layouts": result.evaluations["landscape_layouts"],
                      "axes": {n: [math.degrees(v) for v in a] if n == "theta_c" else a
                               for n, a in result.landscape.axes.items()},
                      "values": result.landscape.summaries},
        "floor": {"grid_step_m": spec.grid_step, "points": result.evaluations["floor_points"],
                  "near_radius_m": float(spec.near_radius), "face_target_px": float(spec.face_target_px)},
        "findings": _findings(result, rig),
        "zoom_rule": rig.zoom_rule,
        "p_contain": float(rig.p_contain),
        "seconds": seconds,
        "timing_s": timing,
        "objective_key": key,
    }


def run(args: argparse.Namespace) -> int:
    import platform

    from tqdm import tqdm

    from runtime.cli._options import enable_cache
    from runtime.errors import UsageError
    from runtime.files import load_rig
    from runtime.output import dumps, staged_output

    t0 = time.perf_counter()
    check_cameras_flags(args)
    overrides = {key: getattr(args, flag) for flag, key in OVERRIDES.items() if getattr(args, flag) is not None}
    cache = enable_cache(args)
    flags = {f"layout.{key}": "--" + flag.replace("_", "-") for flag, key in OVERRIDES.items()}
    rig = load_rig(args.config, overrides={"layout": overrides}, flags=flags)

    import jax

    from optimise import compile_minimiser, floor_grid, search

    spec = rig.layout
    try:
        floor = floor_grid(rig.room, spec.grid_step)
    except ValueError as exc:
        raise UsageError(f"layout.grid_step: {exc}") from None
    if args.cameras is not None:
        return run_cameras(args, rig, floor, t0, cache)
    from optimise import BATCH

    chunks = -(-spec.landscape ** len(spec.vary) // BATCH)
    timing: dict[str, float] = {}
    marks = {"t": t0, "stage": "setup"}

    steps = chunks + spec.starts + 1 + (0 if args.no_maps else 1)
    with staged_output(args.out) as stage, tqdm(total=steps, desc="optimise", unit="step") as bar:
        def progress(stage_name: str, done: bool) -> None:
            now = time.perf_counter()
            timing[marks["stage"]] = timing.get(marks["stage"], 0.0) + now - marks["t"]
            marks["t"], marks["stage"] = now, stage_name
            if not done:
                bar.set_postfix_str(f"{stage_name} (compiling on first use)" if stage_name != "maps" else stage_name)
                return
            if stage_name == "search" and bar.n >= bar.total - (1 if args.no_maps else 2):
                bar.total += 1  # BFGS once more, from the grid's best cell
            bar.set_postfix_str(stage_name)
            bar.update(1)

        # The BFGS program compiles on a second thread while the landscape runs; the maps' module
        # (matplotlib, 0.35 s) is imported there after it, while BFGS runs (compiled code, the GIL free).
        with ThreadPoolExecutor(max_workers=1) as pool:
            compiled = pool.submit(compile_minimiser, rig, floor)
            if not args.no_maps:
                pool.submit(importlib.import_module, "runtime.layout.plots")
            result = search(rig, floor, progress, minimiser=compiled.result)
        seconds = time.perf_counter() - t0
        maps = []
        if not args.no_maps:
            from runtime.layout.plots import floor_figure, landscape_figure

            bar.set_postfix_str("plots")
            for quantities, name in ((["face_px"], "face_px_map.png"), (["variance"], "variance_map.png"),
                                     (["var_sin_pan", "var_tan_tilt"], "pan_tilt_map.png")):
                floor_figure(floor, rig, result, quantities, stage / name)
                maps.append(name)
            landscape_figure(result, rig, stage / "landscape.png")
            maps.append("landscape.png")
            timing["plots"] = time.perf_counter() - marks["t"]
            bar.update(1)
        report = layout_report(result, rig, seconds, timing, str(args.config))
        report["maps"] = maps
        report["compile_cache"] = cache
        report["versions"] = {"python": platform.python_version(), "jax": jax.__version__}
        (stage / "layout.json").write_text(dumps(report) + "\n")

    unit = report["units"]
    where = ", ".join(f"{k} {v:.3f}" for k, v in (("D_c", report["D_c_m"]), ("H_f", report["H_f_m"])))
    print(f"{spec.objective} {spec.statistic}: {report['objective_start']:.6g} {unit} at the configured layout -> "
          f"{report['objective']:.6g} {unit} at {where} m"
          + (f", theta_c {report['theta_c_deg']:.1f} deg" if "theta_c" in spec.vary else "")
          + (f", H_o {report['H_o_m']:.3f} m" if "H_o" in spec.vary else ""))
    print(f"grid best {report['grid_best']['objective']:.6g} {unit} (optimiser better by "
          f"{100 * report['vs_grid_rel']:+.3f} %); on a bound: {report['on_bound'] or 'none'}; "
          f"{report['optimiser']['iterations']} BFGS iterations; {seconds:.1f} s")
    print(f"wrote {args.out}/layout.json" + (" and maps" if maps else ""))
    return 0


#: Candidate values per search variable of the k-camera grid check, unless --landscape says.
CAMERA_CELLS = 7


def check_cameras_flags(args: argparse.Namespace) -> None:
    """``--cameras`` and the flags that go with it, checked before any work (one line naming the flag)."""
    from omnijax.config import LANDSCAPE_MAX, MAX_PTZS
    from runtime.errors import UsageError

    if args.cameras is None:
        return
    if not 1 <= args.cameras <= MAX_PTZS:
        raise UsageError(f"--cameras: expected 1 to {MAX_PTZS} PTZ cameras, got {args.cameras}")
    if args.vary is not None:
        raise UsageError("--vary: not with --cameras (every camera's D_c, H_f and theta_c are searched)")
    cells = args.landscape or CAMERA_CELLS
    if args.landscape is not None and not 3 <= cells or cells**3 > LANDSCAPE_MAX:
        raise UsageError(f"--landscape: with --cameras, expected 3 to {int(LANDSCAPE_MAX ** (1 / 3))} candidate "
                         f"values per variable (their cube is the candidate placements), got {cells}")


def camera_keys(layouts: dict, i: int) -> dict:
    """Camera ``i``'s placement as ``layout.json`` writes it."""
    return _json_values(("D_c", "H_f", "theta_c"), (layouts[n][i] for n in ("D_c", "H_f", "theta_c")))


def cameras_report(results: list, rig, seconds: float, config: str, cells: int, floor) -> dict:
    """``layout.json`` for ``--cameras K`` (docs/design.md section 7: ``cameras``, ``objective``, ``grid_best``,
    ``marginal_gain``; and the one-camera keys of the first camera)."""
    from optimise import SENSE, SHARPNESS

    spec = rig.layout
    sense = SENSE[spec.objective]
    res = results[-1]
    gains = []
    for i, r in enumerate(results):
        prev = results[i - 1].objective if i else None
        gains.append({
            "k": r.k, "objective": r.objective, "gain": None if prev is None else sense * (prev - r.objective),
            "gain_rel": None if prev is None else sense * (prev - r.objective) / abs(prev),
            "framing": r.summary["framing"], "grid_objective": r.grid_objective,
            "cameras": [camera_keys(r.layouts, j) for j in range(r.k)], "seconds": sum(r.seconds.values()),
        })
    cameras = [{**camera_keys(res.layouts, j), "on_bound": res.on_bound[j]} for j in range(res.k)]
    return {
        "config": config,
        **camera_keys(res.layouts, 0),
        "cameras": cameras,
        "objective": res.objective,
        "objective_start": res.start_objective,
        "objective_name": spec.objective,
        "statistic": spec.statistic,
        "sense": "max" if sense < 0 else "min",
        "units": "px" if spec.objective == "face_px" else "rad^2",
        "framing": res.summary["framing"],
        "grid_best": {"objective": res.grid_objective, "method": res.grid_method,
                      "cameras": [camera_keys(res.grid_layouts, j) for j in range(res.k)],
                      "candidates": cells**3, "cells_per_variable": cells},
        "vs_grid_rel": sense * (res.grid_objective - res.objective) / abs(res.grid_objective),
        "marginal_gain": gains,
        "values": {"start": res.start_summary, "optimum": res.summary},
        "optimiser": {
            "method": "optimistix.BFGS (reverse mode) on every camera's (reach, H_f, theta_c) at once; "
                      "the best camera as a power mean over cameras of order " + ", then ".join(map(str, SHARPNESS)),
            "iterations": sum(s.steps for s in res.starts),
            "polished_from_grid": res.polished_from_grid,
            "starts": [{"objective": s.objective, "iterations": s.steps, "converged": s.converged,
                        "from": [dict(zip(("reach", "H_f_m", "theta_c_deg"), (x[0], x[1], math.degrees(x[2]))))
                                 for x in s.start]} for s in res.starts],
        },
        "bounds": {"D_c_m": [float(rig.layout.lower[0]), "the wall along each camera's azimuth"],
                   "H_f_m": [float(rig.layout.lower[1]), float(rig.layout.upper[1])],
                   "theta_c_deg": [math.degrees(float(rig.layout.lower[2])), math.degrees(float(rig.layout.upper[2]))]},
        "floor": {"grid_step_m": spec.grid_step, "points": floor.size, "near_radius_m": float(spec.near_radius),
                  "face_target_px": float(spec.face_target_px)},
        "zoom_rule": rig.zoom_rule,
        "p_contain": float(rig.p_contain),
        "seconds": seconds,
        "timing_s": {f"k{r.k}": r.seconds for r in results},
        "objective_key": f"{spec.objective}_{spec.statistic}",
    }


def run_cameras(args: argparse.Namespace, rig, floor, t0: float, cache) -> int:
    """``omnijax optimise --cameras K``: k = 1 .. K cameras searched in turn (their BFGS programs compile
    on a second thread meanwhile), layout.json and the maps."""
    import platform

    import jax
    from tqdm import tqdm

    from optimise import Cameras, stack
    from runtime.errors import UsageError
    from runtime.output import dumps, staged_output

    K, spec = args.cameras, rig.layout
    cells = args.landscape or CAMERA_CELLS
    cams = Cameras(rig, floor, cells=cells)
    try:
        stack(cams.rigs(K))
    except ValueError as exc:
        raise UsageError(f"{args.config}: foveal: {exc}") from None
    steps = len(cams.slots) + K * (spec.starts + 1) + (0 if args.no_maps else 1)
    with staged_output(args.out) as stage, tqdm(total=steps, desc=f"optimise {K} cameras", unit="step") as bar, \
            ThreadPoolExecutor(max_workers=1) as pool:
        compiled = {k: pool.submit(cams.minimiser, k) for k in range(1, K + 1)}

        def progress(stage_name: str, done: bool) -> None:
            bar.set_postfix_str(stage_name + ("" if done else " (compiling on first use)"))
            if done:
                bar.update(1)

        results = []
        for k in range(1, K + 1):
            bar.set_description(f"optimise k = {k} of {K}")
            results.append(cams.search(k, progress, minimiser=compiled[k].result))
            bar.total += 1 if len(results[-1].starts) > spec.starts else 0
        seconds = time.perf_counter() - t0
        report = cameras_report(results, rig, seconds, str(args.config), cells, floor)
        maps = []
        if not args.no_maps:
            from runtime.layout.plots import cameras_figure, marginal_gain_figure

            bar.set_postfix_str("plots")
            cameras_figure(floor, rig, results[-1], stage / "cameras_map.png")
            marginal_gain_figure(report["marginal_gain"], rig, report["units"], stage / "marginal_gain.png")
            maps = ["cameras_map.png", "marginal_gain.png"]
            bar.update(1)
        report["maps"] = maps
        report["compile_cache"] = cache
        report["versions"] = {"python": platform.python_version(), "jax": jax.__version__}
        (stage / "layout.json").write_text(dumps(report) + "\n")

    unit = report["units"]
    print(f"{spec.objective} {spec.statistic} of the best camera, by number of PTZs:")
    print(f"  {'k':>2}  {'objective':>12}  {'gain':>8}  {'framing':>8}  {'grid best':>12}  seconds")
    for row in report["marginal_gain"]:
        gain = "" if row["gain_rel"] is None else f"{100 * row['gain_rel']:+.2f} %"
        print(f"  {row['k']:>2}  {row['objective']:>9.5g} {unit:<2}  {gain:>8}  {100 * row['framing']:>6.1f} %  "
              f"{row['grid_objective']:>12.5g}  {row['seconds']:.1f}")
    for i, cam in enumerate(report["cameras"]):
        print(f"camera {i + 1}: D_c {cam['D_c_m']:.3f} m, H_f {cam['H_f_m']:.3f} m, "
              f"theta_c {cam['theta_c_deg']:.1f} deg")
    print(f"grid best {report['grid_best']['objective']:.6g} {unit} (optimiser better by "
          f"{100 * report['vs_grid_rel']:+.3f} %); {seconds:.1f} s")
    print(f"wrote {args.out}/layout.json" + (" and maps" if maps else ""))
    return 0
