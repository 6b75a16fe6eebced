"""``omnijax render``: render a synthetic scenario's omni video with its ground truth."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

HELP = "render a synthetic scenario: omni video, truth.jsonl, world.json"
DESCRIPTION = """\
Render N frames of a scenario (configs/scenarios/*.toml) through its rig's omni
camera and write to DIR:

  omni.avi (or omni.mp4)  the frames; codec ffv1 (lossless, the default), mjpg or mp4v
  truth.jsonl             one line per frame: frame, time_s, lamps_on, illumination,
                          persons [{id, foot_m [x, y], head_m [x, y, z] (head centre),
                          r_f (px), theta_f (rad) of the true foot, pixel, r_inner,
                          r_head, H_p_m, R_h_m, in_image, foot_visible, area_px, moving}]
  world.json              the true rig drawn from the configured one (docs/design.md section 5),
                          the people (sizes, colours, contrast against the floor), the sensor,
                          the lamps (with their spectra), the furniture that moves (both
                          footprint centres, the time)
  frames/NNNNNN.png       every K-th frame with --png-every K
  foveal/NNNNNN_pI.png    with --foveal-every K: the PTZ aimed exactly at each person's
                          true head (true rig, eq 1-4) at --foveal-zoom

The same seed gives the same frames, bit for bit.
"""

CODECS = {"ffv1": ("FFV1", "omni.avi"), "mjpg": ("MJPG", "omni.avi"), "mp4v": ("mp4v", "omni.mp4")}


def add_parser(sub: argparse._SubParsersAction) -> None:
    from runtime.settings import finite_float
    p = sub.add_parser("render", help=HELP, description=DESCRIPTION,
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--scenario", required=True, metavar="S", help="scenario TOML, or a name in configs/scenarios")
    p.add_argument("--frames", required=True, type=int, metavar="N", help="number of frames to render")
    p.add_argument("--out", required=True, metavar="DIR", help="output folder (created)")
    p.add_argument("--seed", type=int, help="override the scenario's seed")
    p.add_argument("--codec", choices=sorted(CODECS), default="ffv1",
                   help="video codec: ffv1 (lossless, default), mjpg, mp4v (lossy: adds its own artefacts)")
    p.add_argument("--png-every", type=int, default=0, metavar="K", help="also save every K-th frame as PNG")
    p.add_argument("--foveal-every", type=int, default=0, metavar="K",
                   help="every K-th frame, render the foveal view of each visible person")
    p.add_argument("--foveal-zoom", type=finite_float, default=4.0, metavar="Z", help="zoom of those views (default 4)")
    p.set_defaults(func=run)


def _check(args) -> None:
    from runtime.cli._options import MAX_FRAMES
    from runtime.errors import UsageError

    if not 1 <= args.frames <= MAX_FRAMES:
        raise UsageError(f"--frames: expected a number of frames in 1 .. {MAX_FRAMES}, got {args.frames}")
    for flag, value in (("--png-every", args.png_every), ("--foveal-every", args.foveal_every)):
        if value < 0:
            raise UsageError(f"{flag}: expected K >= 0 (0: none), got {value}")
    if args.seed is not None and args.seed < 0:
        raise UsageError(f"--seed: expected an integer >= 0, got {args.seed}")
    if not args.foveal_zoom > 0:
        raise UsageError(f"--foveal-zoom: expected a zoom factor > 0, got {args.foveal_zoom}")


def _write_png(path: Path, rgb) -> None:
    import cv2
    import numpy as np

    path.parent.mkdir(parents=True, exist_ok=True)
    if not cv2.imwrite(str(path), np.asarray(rgb)[..., ::-1]):
        raise OSError(f"cannot write {path}")


def _foveal_views(world, t: int, truth, zoom: float, stage: Path) -> int:
    """Aim the true PTZ at each visible person's true head and save the view; returns how many."""
    from omnijax.world import render_foveal
    from runtime.validation.truth import true_aim

    zoom = float(world.true_rig.foveal.lens.clamp(zoom))
    count = 0
    for i, person in enumerate(truth["persons"]):
        if not person["in_image"]:
            continue
        aim = true_aim(world, person)
        if not bool(aim.valid):
            continue
        _write_png(stage / "foveal" / f"{t:06d}_p{i}.png", render_foveal(world, t, aim.pan, aim.tilt, zoom))
        count += 1
    return count


def run(args: argparse.Namespace) -> int:
    import cv2
    import numpy as np
    from tqdm import tqdm

    from omnijax import ConfigError
    from omnijax.world import build_world
    from runtime.cli._options import scenario_file
    from runtime.errors import UsageError
    from runtime.files import load_scenario
    from runtime.output import dumps, staged_output
    from runtime.validation.truth import truth_line, world_summary

    _check(args)
    rig, scenario = load_scenario(scenario_file(args.scenario))
    try:
        world = build_world(rig, scenario, seed=args.seed, n_frames=args.frames)
    except ValueError as exc:
        raise ConfigError(f"{args.scenario}: {exc}") from None
    fourcc, name = CODECS[args.codec]
    width, height = world.true_rig.omni.image_size
    foveal = 0
    with staged_output(args.out) as stage:
        writer = cv2.VideoWriter(str(stage / name), cv2.VideoWriter_fourcc(*fourcc), scenario.fps, (width, height))
        if not writer.isOpened():
            raise UsageError(f"--codec {args.codec}: this OpenCV build cannot write {fourcc} video")
        summary = world_summary(world)
        summary.update(video=name, codec=args.codec, scenario_file=str(args.scenario))
        (stage / "world.json").write_text(dumps(summary) + "\n")
        try:
            with (stage / "truth.jsonl").open("w") as lines:
                for t in tqdm(range(args.frames), desc=f"render {scenario.name}", unit="frame"):
                    frame = world.frame(t)
                    image = np.asarray(frame.image)
                    writer.write(np.ascontiguousarray(image[..., ::-1]))
                    truth = truth_line(frame.truth)
                    lines.write(json.dumps(truth) + "\n")
                    if args.png_every and t % args.png_every == 0:
                        _write_png(stage / "frames" / f"{t:06d}.png", image)
                    if args.foveal_every and t % args.foveal_every == 0:
                        foveal += _foveal_views(world, t, truth, args.foveal_zoom, stage)
        finally:
            writer.release()
    print(f"wrote {args.frames} frames of {scenario.name!r} ({width}x{height}, {world.true_rig.omni.model}) to "
          f"{args.out}/{name}, truth.jsonl, world.json" + (f", {foveal} foveal views" if foveal else ""))
    return 0
