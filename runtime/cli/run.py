"""``omnijax run``: the real-time loop on a camera, a network stream, a video file or an image folder,
steering a PTZ."""

from __future__ import annotations

import argparse
import contextlib
import sys
from pathlib import Path

HELP = ("track people with the omni camera (device, stream, video or image folder) and steer the PTZ onto "
        "their heads")
DESCRIPTION = """\
SOURCE is a camera index (0, 1, ...), a network stream (rtsp://..., http://... MJPEG,
read through OpenCV's FFmpeg; when it drops, it is reopened with back-off, 0.1 s
doubling to 1 s, for up to 60 s, and the reconnects are counted in summary.json
stream {reconnects, drops, failed_opens, outage_s: the time without frames}), a video
file or a folder of images. A capture thread keeps only the newest frame (late frames
are dropped and counted); a camera or a stream is drained from the moment it is opened,
also while the loop starts up, so that the loop always acts on the newest frame, never
on a backlog: summary.json frame_age_ms {p50, p99} (from a frame's arrival to its PTZ
bytes) and log.jsonl wait_ms, age_ms per frame show it. The
background is learnt from frames spread over the first seconds (--background-frames over
--background-seconds: people standing through less than half of them are not learnt) and
keeps itself right while running (ghosts of people who left are re-learnt, what stays
still outside every person is absorbed after [detection] absorb_s, a person who stops
stays); then, per frame: detection (jitted),
tracking (Kalman with optimal assignment, or the paper's nearest neighbour), the
target (round-robin with a dwell time, people whose face was not yet captured
first; or a single person), the head predicted to when the PTZ will get there,
pan/tilt/zoom with the propagated uncertainty (tracking and latency included),
and the command written to the PTZ unless it is inside the dead zone.

--ptz is a pyserial URL (/dev/ttyUSB0, socket://host:port, or the path printed by
`omnijax ptz-emulator`), visca-udp://HOST[:PORT] (VISCA over IP) or
onvif://[USER:PASSWORD@]HOST[:PORT] (ONVIF; the password is never printed or
logged); without it commands are computed and logged only.
Ctrl-C or SIGTERM once the loop runs: the loop ends, the PTZ goes home and everything is
written (exit 0; the last line says so if the PTZ did not report its home position). A
second one while the outputs are written cuts that short (no more drawing, no wait for
the PTZ) and keeps what was recorded: summary.json and log.jsonl (written line by line)
are in DIR (exit 130). During the start-up they interrupt at once: nothing written (130).

Writes DIR/summary.json (docs/design.md section 7.3), DIR/log.jsonl (one line per frame),
DIR/events.jsonl (person appeared, face captured, left; faces in DIR/faces/ with
--ptz-video) and DIR/annotated.mp4 (the operator's view; --no-video to skip it).

--serve HOST:PORT serves the operator's console: the live view, the status, the
controls (choose the target, point the PTZ, pause, home), zones saved into the
--config file, events and a calibration assistant (docs/console.md); it prints
"serving http://HOST:PORT/?token=TOKEN" on stderr at start, and only requests
with that token change anything. --mqtt URL publishes the events to a broker.
"""


def add_parser(sub: argparse._SubParsersAction) -> None:
    from runtime.cli._options import PACES, add_background_options, add_loop_options, add_ptz_profile_option
    from runtime.settings import finite_float

    p = sub.add_parser("run", help=HELP, description=DESCRIPTION,
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("source", metavar="SOURCE", help="camera index, stream URL, video file or folder of images")
    p.add_argument("--config", required=True, metavar="FILE", help="rig TOML file")
    p.add_argument("--ptz", metavar="URL",
                   help="PTZ camera: pyserial URL, visca-udp://HOST[:PORT] or onvif://[USER:PASSWORD@]HOST[:PORT]; "
                        "none: commands are only logged")
    add_ptz_profile_option(p, "PTZ device profile: TOML file or a name in configs/devices "
                              "(default sony_evi_d70; onvif_ptz for onvif://)")
    p.add_argument("--out", required=True, metavar="DIR", help="output folder (created)")
    p.add_argument("--pace", choices=PACES,
                   help="live: frames at the source's rate, late ones dropped; all: every frame as fast as "
                        "possible (default: live for cameras and videos, all for image folders)")
    p.add_argument("--fps", type=finite_float, metavar="F", help="frame rate of an image folder")
    p.add_argument("--ptz-video", metavar="SOURCE",
                   help="the PTZ camera's own video (stream URL, camera index or file): shown in the operator's view "
                        "and the console, and saved as the face when one is captured (default: none)")
    add_background_options(p)
    add_loop_options(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from runtime.cli._options import (
        background_settings,
        console_and_events,
        load_ptz_profile,
        loop_config,
        parse_faults,
    )
    from runtime.errors import UsageError

    config = loop_config(args)
    plan = parse_faults(args.faults, ptz_unplug=False)
    if args.fps is not None and not args.fps > 0:
        raise UsageError(f"--fps: expected frames per second > 0, got {args.fps}")

    from runtime.files import load_rig
    from runtime.frames import FolderSource, SourceError, open_source
    from runtime.ptz.profile import DEFAULT_PROFILES
    from runtime.ptz.transports import required_protocol
    from runtime.realtime.sources import FaultySource

    rig = load_rig(args.config)
    args.background_frames, args.background_seconds = background_settings(args, rig)
    profile = load_ptz_profile(args.ptz_profile, required_protocol(args.ptz) if args.ptz else None)
    with console_and_events(args, Path(args.config), args.ptz_profile or DEFAULT_PROFILES[profile.protocol]) as (
            console, mqtt):
        try:
            source = open_source(args.source, args.fps)
        except SourceError as exc:
            raise UsageError(str(exc)) from None
        if not plan.empty:
            source = FaultySource(source, plan)
        pace = args.pace or ("all" if isinstance(source, FolderSource) and args.fps is None else "live")
        summary = _run(args, rig, source, profile, config, plan, pace, console, mqtt)
    report(summary, args.out)
    return 0


def report(summary: dict, out) -> None:
    """What ``run`` prints at the end: one line on stdout; when the PTZ did not get home, a last line on stderr
    that says so."""
    from runtime.realtime.session import home_warning

    lat, age, p = summary["latency_ms"], summary["frame_age_ms"], summary["ptz"]
    nan = float("nan")
    print(f"{summary['frames']} frames at {summary['fps']:.1f} fps ({summary['stop_reason']}); latency p50 "
          f"{lat['p50'] or nan:.2f} ms, p99 {lat['p99'] or nan:.2f} ms; frame age p50 {age['p50'] or nan:.2f} ms, "
          f"p99 {age['p99'] or nan:.2f} ms; PTZ {p['commands']} commands, "
          f"{p['errors']} errors, {p['reconnects']} reconnects; "
          + (f"stream {summary['stream']['reconnects']} reconnects; " if "stream" in summary else "")
          + f"wrote {out}", file=sys.stdout, flush=True)
    if (warning := home_warning(summary)) is not None:
        print(f"omnijax run: {warning}", file=sys.stderr, flush=True)


def _run(args, rig, source, profile, config, plan, pace, console, mqtt) -> dict:
    """Connect the PTZ and run the session (the console, if any, serving meanwhile); its summary."""
    from runtime.errors import UsageError
    from runtime.frames import SourceError, open_source
    from runtime.ptz import PtzError, make_driver
    from runtime.ptz.onvif import redact
    from runtime.realtime.session import run_session
    from runtime.realtime.sources import LatestImage

    driver = None
    if args.ptz:
        try:
            driver = make_driver(args.ptz, profile)
            driver.connect(timeout=30 if args.ptz.lower().startswith("onvif://") else 5)  # ONVIF: WSDLs parsed first
        except PtzError as exc:
            source.close()
            raise UsageError(f"--ptz: {exc}") from None
    ptz_view = contextlib.nullcontext()
    if args.ptz_video:
        try:
            ptz_view = LatestImage(open_source(args.ptz_video))
        except SourceError as exc:
            source.close()
            if driver is not None:
                driver.disconnect()
            raise UsageError(f"--ptz-video: {exc}") from None
    try:
        with ptz_view as foveal:
            return run_session(rig, source, Path(args.out), driver=driver, profile=profile, config=config,
                               paced=pace == "live", background_frames=args.background_frames,
                               background_seconds=args.background_seconds, video=not args.no_video,
                               record=args.record,
                               title=f"OMNI  {Path(str(args.source)).name}", foveal=foveal,
                               extra={"config_file": str(args.config),
                                      "ptz_url": redact(args.ptz) if args.ptz else None, "pace": pace,
                                      "faults_injected": plan.describe()}, console=console, mqtt=mqtt)
    except SourceError as exc:
        raise UsageError(str(exc)) from None
    finally:
        if driver is not None:
            driver.disconnect()
