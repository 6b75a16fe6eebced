"""``omnijax bench``: speed of the detector (steps 1-6) against OpenCV's MOG2, on one core."""

from __future__ import annotations

import argparse
import json

HELP = "time the jitted detector against OpenCV MOG2 on rendered frames (one core)"
DESCRIPTION = """\
Renders a scenario at each frame size (the rig's omni image scaled, people and
lighting unchanged), learns the background, then times after compilation:

  detect_ms    steps 1-6 for every person in the frame (chromaticity, d^2,
               radial sums, hysteresis sectors, windowed profiles, Bayes foot
               estimate and sigmas), one jitted call per frame, frames handed
               over as NumPy arrays like the runtime does;
  stages       the same steps split into three jitted calls (lines: steps 1-3,
               sectors: step 4, foot: steps 5-6), each timed on its own;
  mog2_ms      OpenCV's BackgroundSubtractorMOG2.apply on the same frames in the
               same process (the peer), after it learnt the same background frames;
  compiles     XLA compilations during the timed frames (0 is the only right answer).

Then, at the scenario's own frame size (640x480 for the built-in scenarios), the
whole control path of the real-time loop, frame by frame as its control thread
runs it (the one compiled call: detection, floor positions, tracker, aims; the
tracker's bookkeeping, the target choice, the dead-zone test, the command handed
to the PTZ link, the background's life; no drawing, video or log):

  cameras_per_core   the frame period (1 / the scenario's fps) over the mean wall
                     time per frame on the pinned core: how many such cameras one
                     core keeps up with; "control" holds the details (per-frame
                     wall and CPU ms mean/p50/p90/p99, the same by the p90, the
                     stages' medians; life_ms: the background's life step, which
                     runs on after its dispatch (the "adapt" stage), waited for
                     on the frames it steps). --no-control skips it.

The process is pinned to one core (and XLA to one thread) before JAX loads.
--json prints one JSON object keyed by frame size, e.g. "640x480", plus
"cores", "scenario", "cameras_per_core" and "control".
"""

DEFAULT_SIZES = ("640x480", "1920x1920")


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("bench", help=HELP, description=DESCRIPTION,
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--scenario", default="three_people", metavar="S",
                   help="scenario TOML, or a name in configs/scenarios, whose rig is scaled to each size "
                        "(default: %(default)s)")
    p.add_argument("--sizes", nargs="+", default=list(DEFAULT_SIZES), metavar="WxH",
                   help="frame sizes to measure (default: %(default)s)")
    p.add_argument("--frames", type=int, default=200, metavar="N",
                   help="timed calls per measurement, cycling over the rendered frames (default: 200)")
    p.add_argument("--core", type=int, default=0, metavar="K", help="CPU core to pin to (default: 0)")
    p.add_argument("--no-control", action="store_true",
                   help="skip the control path's cameras_per_core (the detector only)")
    p.add_argument("--json", action="store_true", help="print one JSON object instead of a table")
    p.set_defaults(func=run)


def _parse_size(text: str) -> tuple[int, int]:
    from runtime.errors import UsageError

    try:
        w, h = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise UsageError(f"--sizes: expected WIDTHxHEIGHT like 640x480, got {text!r}") from None
    if not (64 <= w <= 8192 and 64 <= h <= 8192):
        raise UsageError(f"--sizes: expected 64..8192 pixels per side, got {text!r}")
    return w, h


def run(args: argparse.Namespace) -> int:
    import os

    from runtime.cli._options import scenario_file
    from runtime.errors import UsageError

    sizes = [_parse_size(s) for s in args.sizes]
    if args.frames < 10:
        raise UsageError(f"--frames: expected at least 10 timed calls, got {args.frames}")
    if hasattr(os, "sched_getaffinity") and args.core not in os.sched_getaffinity(0):
        raise UsageError(f"--core: core {args.core} is not available to this process")

    from runtime.bench.timing import pin_to_one_core

    pin_to_one_core(args.core)  # before anything imports JAX (reading the scenario does)
    scenario = str(scenario_file(args.scenario))
    from runtime.bench.detector import bench_size

    report = {"cores": 1, "scenario": scenario}
    for w, h in sizes:
        report[f"{w}x{h}"] = bench_size(scenario, (w, h), args.frames, progress=not args.json)
    if not args.no_control:
        from runtime.bench.control import bench_control

        report["control"] = bench_control(scenario, args.frames, progress=not args.json)
        report["cameras_per_core"] = report["control"]["cameras_per_core"]["mean"]
    if args.json:
        print(json.dumps(report, indent=2))
    else:
        _print_table(report, sizes)
    return 0


def _print_table(report: dict, sizes) -> None:
    row = "{:<11} {:>9} {:>9} {:>9} {:>10} {:>9} {:>9}"
    print(row.format("size", "p50 ms", "p90 ms", "p99 ms", "MOG2 p50", "ratio", "compiles"))
    for w, h in sizes:
        r = report[f"{w}x{h}"]
        d, m = r["detect_ms"], r["mog2_ms"]
        print(row.format(f"{w}x{h}", f"{d['p50']:.3f}", f"{d['p90']:.3f}", f"{d['p99']:.3f}",
                         f"{m['p50']:.3f}", f"{r['mog2_over_detect']:.1f}x", r["compiles"]))
        stages = ", ".join(f"{k} {v['p50']:.3f}" for k, v in r["stages_ms"].items())
        print(f"{'':<11} stages p50 ms: {stages}; {r['people']:.1f} people per frame on average")
    if "control" in report:
        c = report["control"]
        f, u = c["frame_ms"], c["cpu_ms"]
        print(f"control path at {c['size']} ({c['frames']} frames): per frame p50 {f['p50']:.2f} ms, "
              f"p90 {f['p90']:.2f}, mean {f['mean']:.2f} (CPU mean {u['mean']:.2f}): "
              f"cameras_per_core {report['cameras_per_core']:.1f} "
              f"at {c['fps']:g} fps ({c['cameras_per_core']['p90']:.1f} by the p90)")
