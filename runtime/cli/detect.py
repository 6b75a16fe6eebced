"""``omnijax detect``: find people in a video or image folder and write detections and overlays."""

from __future__ import annotations

import argparse
import json
import time

HELP = "detect people (feet, sectors, sigmas) in a video file or a folder of images"
DESCRIPTION = """\
Learns the background from frames spread over the first seconds (--background-frames
over --background-seconds, the rig's [detection] defaults: 30 over 10 s; robustly:
people may walk through, or stand for less than half of it), then runs the jitted
detector on every later frame: chromaticity and d^2 (eq 5-7), radial sums and
hysteresis sectors (eq 8-10), the windowed profile at every line of them and the
people it holds one at a time with the Bayes foot estimate (eq 11-12), and the
tracker; the background keeps itself right (the background's life: ghosts of people
who left re-learnt, what stays at rest outside every trusted person absorbed after [detection]
absorb_s (90 s), a person who stops kept, the rest drifting; docs/detection.md). This is the
same pipeline `run` and `demo` use.

Writes DIR/detections.jsonl (one line per frame: each person's r_f, theta_f, their
sigmas under the sigma rule (the detector's own as detector_sigma_*, and detector_bound_* for a
foot it could not see, under the camera or past the image's edge: see the rig's [detection]
sigma_gain_* / sigma_extra_*), contrast, sector edges, foot and head pixels), DIR/overlay_NNNNN.png every
--overlay-every frames (sectors red, centre lines green, the person's extent yellow,
foot cyan, head white) and DIR/summary.json (frames, the learning: which frames and how
much of the floor it settled, the background's life: ghost detections repaired).

--change-only is for footage from ordinary (perspective) cameras, where the omni
geometry does not apply: it writes per-pixel change masks and compares them with
OpenCV's MOG2 after both have learnt the scene (no --config needed).
"""


def add_parser(sub: argparse._SubParsersAction) -> None:
    from runtime.cli._options import add_background_options, deprecated_alias
    from runtime.settings import finite_float

    p = sub.add_parser("detect", help=HELP, description=DESCRIPTION,
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("source", metavar="SOURCE", help="video file or folder of images")
    p.add_argument("--config", metavar="FILE", help="rig TOML file (required unless --change-only)")
    p.add_argument("--out", required=True, metavar="DIR", help="output folder (created)")
    add_background_options(p)
    p.add_argument("--overlay-every", type=int, default=25, metavar="K", help="overlay PNG every K frames (25)")
    deprecated_alias(p, "--limit", p.add_argument(
        "--frames", type=int, metavar="N", help="read at most N frames of SOURCE, background learning included"))
    p.add_argument("--change-only", action="store_true",
                   help="per-pixel change masks only, compared with MOG2 (perspective footage)")
    p.add_argument("--pixel-fa", type=finite_float, default=1e-3, metavar="P",
                   help="--change-only: per-pixel false-alarm probability of the mask (default 1e-3)")
    p.add_argument("--sigma-floor", type=finite_float, metavar="GREY",
                   help="lowest sensor noise assumed per pixel, grey levels (default 0.5; --change-only: 2.0, "
                        "MOG2's own minimum, for compressed video)")
    p.add_argument("--adapt-rate", type=finite_float, metavar="A",
                   help="background adaptation rate where nothing changed (default: [detection] adapt_rate; "
                        "--change-only: 0.02)")
    p.set_defaults(func=run)


def _check_args(args) -> None:
    from runtime.errors import UsageError

    if not args.change_only and not args.config:
        raise UsageError("--config is required (or use --change-only for non-omnidirectional footage)")
    for name in ("overlay_every", "frames"):
        v = getattr(args, name)
        if v is not None and v < 1:
            raise UsageError(f"--{name.replace('_', '-')}: expected a positive count, got {v}")
    if not 0 < args.pixel_fa < 1:
        raise UsageError(f"--pixel-fa: expected a probability in (0, 1), got {args.pixel_fa}")
    if args.sigma_floor is not None and not args.sigma_floor > 0:
        raise UsageError(f"--sigma-floor: expected grey levels > 0, got {args.sigma_floor}")
    if args.adapt_rate is not None and not 0 <= args.adapt_rate < 1:
        raise UsageError(f"--adapt-rate: expected a number in [0, 1), got {args.adapt_rate}")


def run(args: argparse.Namespace) -> int:
    _check_args(args)
    if args.change_only:
        return _run_change_only(args)
    return _run_detector(args)


def _learn(frames_iter, n: int, what: str):
    """``--change-only``: the first ``n`` frames, stacked."""
    import numpy as np

    from runtime.errors import UsageError

    frames = []
    for f in frames_iter:
        frames.append(f)
        if len(frames) == n:
            break
    if len(frames) < n:
        raise UsageError(f"{what}: only {len(frames)} frames, expected at least {n} to learn the background "
                         "(--background-frames)")
    return np.stack(frames)


def _run_detector(args) -> int:
    import cv2
    import numpy as np
    from tqdm import tqdm

    from omnijax.detection import polar_range
    from runtime.cli._options import background_settings
    from runtime.errors import UsageError
    from runtime.files import load_rig
    from runtime.frames import SourceError, frames_fps, read_frames
    from runtime.output import dumps, staged_output
    from runtime.realtime.overlay import draw_detections, foot_and_head_pixels
    from runtime.realtime.perception import detect_frames

    rig = load_rig(args.config)
    n_bg, seconds = background_settings(args, rig)
    W, H = rig.omni.image_size
    try:
        frames = read_frames(args.source, args.frames)
        fps = frames_fps(args.source)
        with staged_output(args.out) as stage, (stage / "detections.jsonl").open("w") as log:
            t_build = time.perf_counter()
            run_ = detect_frames(rig, _sized(frames, (H, W), args), fps=fps, samples=n_bg, seconds=seconds,
                                 what=str(args.source))
            build_s = time.perf_counter() - t_build
            r_range = polar_range(rig)
            counts, n, t0 = [], 0, time.perf_counter()
            bar = tqdm(run_, desc="detect", unit="frame", initial=run_.read, disable=None, leave=False)
            for item in bar:
                for person in item.people:
                    foot, head = foot_and_head_pixels(rig, person["r_f"], person["theta_f"])
                    person["foot_px"], person["head_px"] = list(foot), list(head)
                log.write(json.dumps({"frame": item.index, "people": item.people}) + "\n")
                counts.append(len(item.people))
                if n % args.overlay_every == 0:
                    img = draw_detections(item.image, rig, item.dets, r_range,
                                          f"frame {item.index}: {len(item.people)} people")
                    cv2.imwrite(str(stage / f"overlay_{item.index:05d}.png"), cv2.cvtColor(img, cv2.COLOR_RGB2BGR))
                n += 1
            th = run_.perception.detector.thresholds
            keeper = run_.perception.keeper
            summary = {
                "source": str(args.source), "config": str(args.config), "frames": n,
                "background_frames": n_bg, "learning": {"frames": n_bg, "seconds": seconds, "step": run_.step_frames,
                                                        "frame_indices": run_.learning_frames},
                "learning_frames": run_.learning_frames, "background": keeper.summary(),
                # the sensor's noise as measured; d^2 is taken against it times noise_margin
                "sensor_sigma_median": float(np.median(np.asarray(keeper.lines.sigma))
                                             / float(run_.perception.detector.noise_margin)),
                "noise_margin": float(run_.perception.detector.noise_margin),
                "people_per_frame": float(np.mean(counts)) if counts else 0.0,
                "frame_ms_mean": 1e3 * (time.perf_counter() - t0) / max(n, 1), "build_s": build_s,
                "thresholds": {"feasible": bool(th.feasible), "seed_false_alarm_per_frame": float(th.seed_false_alarm),
                               "lower_mean": float(th.lower.mean()), "upper_mean": float(th.upper.mean())},
            }
            (stage / "summary.json").write_text(dumps(summary) + "\n")
    except SourceError as exc:
        raise UsageError(str(exc)) from None
    print(f"{n} frames, {summary['people_per_frame']:.2f} people per frame, "
          f"{summary['frame_ms_mean']:.2f} ms per frame (mean: detection, tracking and the background's life, "
          f"with I/O); background sure of {summary['background']['learned_share_end']:.2f} of the floor "
          f"({summary['background']['settled_share']:.3f} taken from the learning's minority: someone stood there); "
          f"wrote {args.out}")
    return 0


def _sized(frames, shape, args):
    """``frames``, refusing the first of another size than the rig's (exit 2, naming both)."""
    from runtime.errors import UsageError

    for f in frames:
        if f is not None and f.shape[:2] != shape:
            raise UsageError(f"{args.source}: frames are {f.shape[1]}x{f.shape[0]}, expected {shape[1]}x{shape[0]} "
                             f"(omni.image_size of {args.config})")
        yield f


def _run_change_only(args) -> int:
    import cv2
    import jax
    import jax.numpy as jnp
    import numpy as np
    from scipy.stats import chi2
    from tqdm import tqdm

    from omnijax import adapt_background, change_image, learn_background
    from runtime.errors import UsageError
    from runtime.frames import SourceError, read_frames
    from runtime.output import dumps, staged_output

    n_bg = args.background_frames or 60
    if n_bg < 3:
        raise UsageError(f"--background-frames: expected at least 3, got {n_bg}")
    rate = 0.02 if args.adapt_rate is None else args.adapt_rate
    threshold = float(chi2.ppf(1 - args.pixel_fa, 2))
    step = jax.jit(lambda f, bg: change_image(f, bg) > threshold)
    adapt = jax.jit(adapt_background)
    cv2.setNumThreads(1)
    mog2 = cv2.createBackgroundSubtractorMOG2(history=500, detectShadows=True)
    try:
        frames = read_frames(args.source, args.frames)
        training = _learn(frames, n_bg, args.source)
        for f in training:
            mog2.apply(cv2.cvtColor(f, cv2.COLOR_RGB2BGR))
        floor = 2.0 if args.sigma_floor is None else args.sigma_floor
        bg = learn_background(training, floor=floor)
        inter = union = ours_px = mog_px = agree = total = 0
        per_frame = []
        with staged_output(args.out) as stage:
            bar = tqdm(frames, desc="change", unit="frame", initial=n_bg, disable=None, leave=False)
            for n, frame in enumerate(bar):
                x = jnp.asarray(frame)
                ours = np.asarray(step(x, bg))
                theirs = mog2.apply(cv2.cvtColor(frame, cv2.COLOR_RGB2BGR)) == 255  # 127 = MOG2's shadow
                i, u = int((ours & theirs).sum()), int((ours | theirs).sum())
                inter, union = inter + i, union + u
                ours_px, mog_px = ours_px + int(ours.sum()), mog_px + int(theirs.sum())
                agree, total = agree + int((ours == theirs).sum()), total + ours.size
                per_frame.append(i / u if u else 1.0)
                if n % args.overlay_every == 0:
                    _write_mask_overlay(stage / f"overlay_{n_bg + n:05d}.png", frame, ours, theirs)
                bg = adapt(bg, x, jnp.asarray(~ours), rate)
            summary = {
                "source": str(args.source), "frames": len(per_frame), "background_frames": n_bg,
                "sensor_sigma_median": float(jnp.median(bg.sigma)), "sigma_floor": floor,
                "pixel_false_alarm": args.pixel_fa,
                "d2_threshold": threshold,
                "mog2": {
                    "iou": inter / union if union else 1.0,
                    "iou_per_frame_median": float(np.median(per_frame)) if per_frame else None,
                    "f1": 2 * inter / (ours_px + mog_px) if ours_px + mog_px else 1.0,
                    "pixel_agreement": agree / total if total else None,
                    "ours_foreground_fraction": ours_px / total if total else None,
                    "mog2_foreground_fraction": mog_px / total if total else None,
                },
            }
            (stage / "summary.json").write_text(dumps(summary) + "\n")
    except SourceError as exc:
        raise UsageError(str(exc)) from None
    m = summary["mog2"]
    print(f"{summary['frames']} frames after {n_bg} learning: agreement with MOG2 IoU {m['iou']:.3f}, "
          f"F1 {m['f1']:.3f}, pixels {m['pixel_agreement']:.4f}; wrote {args.out}")
    return 0


def _write_mask_overlay(path, frame, ours, theirs) -> None:
    """Frame | ours (chromaticity d^2) | MOG2, side by side, masks tinted over the frame."""
    import cv2
    import numpy as np

    def tint(mask, colour):
        img = frame.astype(np.float32).copy()
        img[mask] = 0.45 * img[mask] + 0.55 * np.asarray(colour, np.float32)
        return img.astype(np.uint8)

    panel = np.concatenate([frame, tint(ours, (255, 0, 255)), tint(theirs, (0, 200, 255))], axis=1)
    for x, text in ((8, "frame"), (frame.shape[1] + 8, "omnijax d2 (chromaticity)"),
                    (2 * frame.shape[1] + 8, "OpenCV MOG2")):
        cv2.putText(panel, text, (x, 18), cv2.FONT_HERSHEY_SIMPLEX, 0.5, (255, 255, 255), 1, cv2.LINE_AA)
    cv2.imwrite(str(path), cv2.cvtColor(panel, cv2.COLOR_RGB2BGR))
