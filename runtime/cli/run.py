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
at rest outside every trusted person is absorbed after [detection] absorb_s (90 s), a person who stops
stays); then, per frame: detection (jitted),
tracking (Kalman with optimal assignment, or the paper's nearest neighbour), the
target (round-robin with a dwell time, people whose face was not yet captured
first; or a single person), the head predicted to when the PTZ will get there,
pan/tilt/zoom with the propagated uncertainty (tracking and latency included),
and the command written to the PTZ unless it is inside the dead zone.

--ptz is a pyserial URL (/dev/ttyUSB0, socket://host:port, or the path printed by
`omnijax ptz-emulator`), visca-udp://HOST[:PORT] (VISCA over IP) or
onvif://[USER:PASSWORD@]HOST[:PORT] (ONVIF; the password is never printed or
logged); without it commands are computed and logged only. A rig with several
PTZs ([[foveal]] tables) takes one --ptz per PTZ, in the rig's order; each PTZ's
device profile is its table's `profile`, else --ptz-profile, else the shipped
one of its protocol. Every frame the trusted people some PTZ can frame are
assigned to the PTZs exactly (face size and containment probability per PTZ
and person, slew time, how long each person has gone uncaptured; hysteresis;
hand-offs; a spare PTZ gives the weakest-framed person a second view:
docs/site.md).
Ctrl-C or SIGTERM once the loop runs: the loop ends, the PTZs go home and everything is
written (exit 0; the last line says so if a PTZ did not report its home position). A
second one while the outputs are written cuts that short (no more drawing, no wait for
the PTZs) and keeps what was recorded: summary.json and log.jsonl (written line by line)
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
    p.add_argument("--ptz", metavar="URL", action="append",
                   help="PTZ camera: pyserial URL, visca-udp://HOST[:PORT] or onvif://[USER:PASSWORD@]HOST[:PORT]; "
                        "once per PTZ of the rig, in its order; none: commands are only logged")
    add_ptz_profile_option(p, "PTZ device profile: TOML file or a name in configs/devices, for the PTZs whose "
                              "[[foveal]] table names none (default sony_evi_d70; onvif_ptz for onvif://)")
    p.add_argument("--out", required=True, metavar="DIR", help="output folder (created)")
    p.add_argument("--pace", choices=PACES,
                   help="live: frames at the source's rate, late ones dropped; all: every frame as fast as "
                        "possible (default: live for cameras and videos, all for image folders)")
    p.add_argument("--fps", type=finite_float, metavar="F", help="frame rate of an image folder")
    p.add_argument("--ptz-video", metavar="SOURCE", action="append",
                   help="the PTZ camera's own video (stream URL, camera index or file): shown in the operator's view "
                        "and the console, and saved as the face when one is captured (default: none); with several "
                        "PTZs, once per PTZ in the rig's order (or fewer: the first ones)")
    add_background_options(p)
    add_loop_options(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from runtime.cli._options import (
        background_settings,
        console_and_events,
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
    urls, videos = args.ptz or [], args.ptz_video or []
    if urls and len(urls) != rig.ptz_count:
        raise UsageError(f"--ptz: {args.config} has {rig.ptz_count} PTZ{'s' if rig.ptz_count > 1 else ''}; expected "
                         f"one --ptz URL for each, in the rig's order, got {len(urls)}")
    if len(videos) > rig.ptz_count:
        raise UsageError(f"--ptz-video: expected at most one per PTZ ({rig.ptz_count}), got {len(videos)}")
    profiles = [ptz_profile(args, rig, k, required_protocol(urls[k]) if urls else None) for k in range(rig.ptz_count)]
    profile = profiles[0]
    with console_and_events(args, Path(args.config), args.ptz_profile or DEFAULT_PROFILES[profile.protocol]) as (
            console, mqtt):
        try:
            source = open_source(args.source, args.fps)
        except SourceError as exc:
            raise UsageError(str(exc)) from None
        if not plan.empty:
            source = FaultySource(source, plan)
        pace = args.pace or ("all" if isinstance(source, FolderSource) and args.fps is None else "live")
        summary = _run(args, rig, source, profiles, config, plan, pace, console, mqtt)
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


def ptz_profile(args, rig, k: int, protocol: str | None):
    """PTZ ``k``'s device profile: its ``[[foveal]]`` table's ``profile`` (a file relative to the rig, or a
    shipped name), else ``--ptz-profile``, else the shipped one of ``protocol``."""
    from runtime.cli._options import load_ptz_profile
    from runtime.errors import UsageError
    from runtime.ptz import ProfileError, load_profile

    named = rig.ptz_profiles[k] if k < len(rig.ptz_profiles) else None
    if named is None:
        return load_ptz_profile(args.ptz_profile, protocol)
    beside = Path(args.config).parent / named
    try:
        profile = load_profile(beside if beside.is_file() else named)
    except ProfileError as exc:
        raise UsageError(f"{args.config}: foveal.{k}.profile: {exc}") from None
    if protocol is not None and profile.protocol != protocol:
        raise UsageError(f"{args.config}: foveal.{k}.profile: {named} is a {profile.protocol} profile, but its "
                         f"--ptz URL speaks {protocol}")
    return profile


def _run(args, rig, source, profiles, config, plan, pace, console, mqtt) -> dict:
    """Connect the PTZs and run the session (the console, if any, serving meanwhile); its summary."""
    from runtime.errors import UsageError
    from runtime.frames import SourceError, open_source
    from runtime.ptz import PtzError, make_driver
    from runtime.ptz.onvif import redact
    from runtime.realtime.ptz_link import PtzLink
    from runtime.realtime.session import run_session
    from runtime.realtime.sources import LatestImage

    urls = args.ptz or []
    with contextlib.ExitStack() as stack:
        drivers, fovea = [None] * rig.ptz_count, []
        try:
            for k, url in enumerate(urls):
                try:
                    drivers[k] = make_driver(url, profiles[k])
                    stack.callback(drivers[k].disconnect)
                    drivers[k].connect(timeout=30 if url.lower().startswith("onvif://") else 5)  # ONVIF: WSDLs first
                except PtzError as exc:
                    which = f" ({k + 1} of {len(urls)})" if len(urls) > 1 else ""
                    raise UsageError(f"--ptz{which}: {exc}") from None
            for k, video in enumerate(args.ptz_video or []):
                label = "PTZ camera" if rig.ptz_count == 1 else f"PTZ {k} camera"
                try:
                    fovea.append(stack.enter_context(LatestImage(open_source(video), label)))
                except SourceError as exc:
                    raise UsageError(f"--ptz-video: {exc}") from None
        except UsageError:
            source.close()  # the session closes it otherwise
            raise
        try:
            return run_session(rig, source, Path(args.out),
                               links=[PtzLink(k, d, p) for k, (d, p) in enumerate(zip(drivers, profiles))],
                               config=config, paced=pace == "live", background_frames=args.background_frames,
                               background_seconds=args.background_seconds, video=not args.no_video,
                               record=args.record, title=f"OMNI  {Path(str(args.source)).name}", fovea=fovea,
                               extra={"config_file": str(args.config),
                                      "ptz_url": redact(urls[0]) if urls else None,
                                      "ptz_urls": [redact(u) for u in urls], "pace": pace,
                                      "faults_injected": plan.describe()}, console=console, mqtt=mqtt)
        except SourceError as exc:
            raise UsageError(str(exc)) from None
