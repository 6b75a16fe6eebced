"""``omnijax optimise``: where to put the PTZ camera for a room, with proof (a grid) and maps."""

from __future__ import annotations

import argparse
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

        # The BFGS program compiles on a second thread while the landscape runs.
        with ThreadPoolExecutor(max_workers=1) as pool:
            compiled = pool.submit(compile_minimiser, rig, floor)
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
