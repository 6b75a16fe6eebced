"""``omnijax ptz``: send one target to a PTZ camera, or ask where it is (for installers)."""

from __future__ import annotations

import argparse
import math
import sys

HELP = "send one pan/tilt/zoom to a PTZ camera, or ask where it is"
DESCRIPTION = """\
Connect to a PTZ camera, over a pyserial URL (/dev/ttyUSB0, socket://host:port,
or the path printed by `omnijax ptz-emulator`) or VISCA over IP
(visca-udp://HOST[:PORT], port 52381 by default) or ONVIF
(onvif://[USER:PASSWORD@]HOST[:PORT], port 80 by default), optionally send one target in
omnijax's frame (pan from the direction of the omni camera's axis, tilt up
positive, degrees; zoom factor) through the device profile's mounting and
limits, wait until the camera reports it reached it, and print where it is:
in omnijax's frame and in the device's own degrees and units. Use it to check
a profile's [mounting] section: `--pan-deg 0 --tilt-deg 0` must point the
camera at the omni camera's axis, level.

A target beyond the device's limits (or the lens's zoom range) is clamped onto
them, and the output says which axes were clamped. Pan must be within a turn
either way, tilt within [-90, 90] deg and zoom positive.

Exit codes: 0 done (and reached, if a target was sent), 1 no camera answered or
target not reached in time, 2 bad arguments or profile, or a port that cannot
be opened (a malformed URL, no such device, an ONVIF camera refusing the user
name or password).

Two actions for installers (see their --help):
  omnijax ptz probe --ptz URL [--json]       what the camera offers, and a verdict
  omnijax ptz calibrate --ptz URL --out P.toml   measure latency and speeds, write a profile
"""

PROBE_HELP = "what a PTZ camera offers (move modes, status, position read-back, zoom, limits) and a verdict"
PROBE_DESCRIPTION = """Connect to the camera and report what it offers: the move modes and how the end
of a move is known (from the driver and the device profile), and, checked live,
position read-back (a few inquiries and their round trip) and a test move (pan by
--step-deg and back, so the camera moves slightly). Ends with a verdict: whether
omnijax can drive it, and how. --json prints one JSON object {capabilities,
checks, link, verdict {drivable, how, why}}.

Exit codes: 0 drivable, 1 not drivable or no answer, 2 bad arguments or URL.
"""

CALIBRATE_HELP = "measure a PTZ camera's command latency and pan/tilt/zoom speeds; write a device profile"
CALIBRATE_DESCRIPTION = """Time --moves moves per axis over --span of its range (pan, tilt, then zoom; the
camera sweeps most of its range), polling the position throughout; fit a line
(least squares) to the samples inside each move: its slope is the speed, its
crossing of the start is when the motion began, and that minus when the command
went on the wire is the command latency. Write --out: the device profile with
pan/tilt max_speed_deg_s (scaled from the speed code sent to the top code), zoom
seconds_full_range and link command_latency_s replaced (comments kept); the
real-time loop adds the latency to the slew time when it predicts where a head
will be when the PTZ gets there. Prints the fitted figures (or --json).

Exit codes: 0 written, 1 no answer or a move not completed, 2 bad arguments.
"""


def add_parser(sub: argparse._SubParsersAction) -> None:
    from runtime.cli._options import PROTOCOLS, add_ptz_profile_option, deprecated_alias
    from runtime.settings import finite_float

    p = sub.add_parser("ptz", help=HELP, description=DESCRIPTION,
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    deprecated_alias(p, "--port", p.add_argument("--ptz", metavar="URL",
                                                   help="the camera: a pyserial URL of its serial line, "
                                                        "visca-udp://HOST[:PORT] or "
                                                        "onvif://[USER:PASSWORD@]HOST[:PORT] (required)"))
    add_ptz_profile_option(p, "device profile: a TOML file or a name in configs/devices (default: per --protocol)")
    p.add_argument("--protocol", choices=PROTOCOLS, metavar="NAME",
                   help="%(choices)s: the shipped profile to use when --ptz-profile is not given (default visca); "
                        "with --ptz-profile, the protocol it must have")
    p.add_argument("--pan-deg", type=finite_float, metavar="DEG", help="target pan, omnijax frame (deg)")
    p.add_argument("--tilt-deg", type=finite_float, metavar="DEG", help="target tilt, omnijax frame (deg, up positive)")
    p.add_argument("--zoom", type=finite_float, metavar="Z", help="target zoom factor")
    p.add_argument("--wait", type=finite_float, default=15.0, metavar="S",
                   help="seconds to wait for the camera to reach the target (default 15)")
    p.add_argument("--timeout", type=finite_float, metavar="S",
                   help="seconds to wait for the camera to answer when connecting (default 5; 30 for onvif://, "
                        "whose client first parses the ONVIF WSDLs: seconds on a busy or small machine)")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=run)
    actions = p.add_subparsers(dest="action", metavar="ACTION", title="actions (optional)")
    probe = actions.add_parser("probe", help=PROBE_HELP, description=PROBE_DESCRIPTION,
                               formatter_class=argparse.RawDescriptionHelpFormatter)
    cal = actions.add_parser("calibrate", help=CALIBRATE_HELP, description=CALIBRATE_DESCRIPTION,
                             formatter_class=argparse.RawDescriptionHelpFormatter)
    for q in (probe, cal):
        q.add_argument("--ptz", metavar="URL", help="the camera: a pyserial URL, visca-udp://HOST[:PORT] or "
                                                    "onvif://[USER:PASSWORD@]HOST[:PORT] (required)")
        add_ptz_profile_option(q, "device profile: a TOML file or a name in configs/devices (default: per --protocol)",
                               alias=False)
        q.add_argument("--protocol", choices=PROTOCOLS, metavar="NAME",
                       help="%(choices)s: the shipped profile to use when --ptz-profile is not given")
        q.add_argument("--timeout", type=finite_float, metavar="S",
                       help="seconds to wait for the camera to answer when connecting (default 5; 30 for onvif://)")
        q.add_argument("--json", action="store_true", help="print one JSON object")
    probe.add_argument("--step-deg", type=finite_float, default=1.0, metavar="DEG",
                       help="pan of the test move, device degrees (default 1)")
    probe.set_defaults(func=run_probe)
    cal.add_argument("--out", required=True, metavar="PROFILE.toml", help="the calibrated device profile to write")
    cal.add_argument("--moves", type=int, default=2, metavar="N", help="timed moves per axis (default 2)")
    cal.add_argument("--span", type=finite_float, default=0.8, metavar="F",
                     help="fraction of each axis's range a move covers (default 0.8)")
    cal.set_defaults(func=run_calibrate)


def redact(url: str) -> str:
    """``url`` as it may be printed: an ``onvif://`` password replaced by ``***``."""
    from runtime.ptz.onvif import redact as _redact

    return _redact(url)


def connect_timeout(url: str) -> float:
    """Default seconds to wait for a camera's first answer: 30 for ONVIF (its client parses the ONVIF
    WSDLs first, seconds on a busy or small machine), 5 otherwise."""
    return 30.0 if url.lower().startswith("onvif://") else 5.0


def _connect(args, profile=None):
    """The connected driver for ``--ptz`` with ``profile`` (default: ``--ptz-profile`` or the URL's
    protocol's) (one line, exit 2 for bad input; ``None`` after printing why no camera answered)."""
    from runtime.cli._options import load_ptz_profile
    from runtime.errors import UsageError
    from runtime.ptz import PtzError, PtzPortError, make_driver
    from runtime.ptz.transports import required_protocol

    if args.ptz is None:
        raise UsageError("--ptz: expected the camera's URL (/dev/ttyUSB0, socket://host:port, visca-udp://host, ...)")
    if args.timeout is None:
        args.timeout = connect_timeout(args.ptz)
    if not args.timeout > 0:
        raise UsageError(f"--timeout: expected a positive number of seconds, got {args.timeout}")
    if profile is None:
        profile = load_ptz_profile(args.ptz_profile, args.protocol or required_protocol(args.ptz))
    try:
        driver = make_driver(args.ptz, profile)
        driver.connect(timeout=args.timeout)
    except PtzPortError as exc:
        raise UsageError(f"--ptz: {exc}") from None
    except PtzError as exc:
        print(f"omnijax ptz: {exc}", file=sys.stderr)
        return None
    return driver


def run_probe(args: argparse.Namespace) -> int:
    from runtime.errors import UsageError
    from runtime.output import dumps
    from runtime.ptz.probe import probe, probe_table

    if not 0 < abs(args.step_deg) <= 10:
        raise UsageError(f"--step-deg: expected 0 < |DEG| <= 10, got {args.step_deg:g}")
    driver = _connect(args)
    if driver is None:
        return 1
    try:
        report = probe(driver, step_deg=args.step_deg)
    finally:
        driver.disconnect()
    report = {"port": redact(args.ptz), "profile": driver.profile.name, **report}
    print(dumps(report) if args.json else probe_table(report, redact(args.ptz)))
    return 0 if report["verdict"]["drivable"] else 1


def run_calibrate(args: argparse.Namespace) -> int:
    import tomllib

    from runtime.errors import UsageError
    from runtime.output import check_output_file, dumps
    from runtime.ptz import PtzError, parse_profile
    from runtime.ptz.probe import calibrate, calibrated_profile_text
    from runtime.ptz.profile import DEFAULT_PROFILES, resolve_profile_path

    if not 1 <= args.moves <= 20:
        raise UsageError(f"--moves: expected 1-20 timed moves per axis, got {args.moves}")
    if not 0.1 <= args.span <= 1:
        raise UsageError(f"--span: expected a fraction of the range in [0.1, 1], got {args.span:g}")
    out = check_output_file(args.out, "--out")
    driver = _connect(args)
    if driver is None:
        return 1
    try:
        fitted = calibrate(driver, moves=args.moves, span=args.span)
    except (PtzError, TimeoutError, ValueError) as exc:
        print(f"omnijax ptz calibrate: {redact(args.ptz)}: {exc or 'no answer'}", file=sys.stderr)
        return 1
    finally:
        driver.disconnect()
    profile = driver.profile
    source = resolve_profile_path(args.ptz_profile or DEFAULT_PROFILES[profile.protocol])
    header = (f"Calibrated by `omnijax ptz calibrate --ptz {redact(args.ptz)}` from {source.name}: "
              f"{args.moves} timed moves per axis over {args.span:g} of its range.")
    text = calibrated_profile_text(source.read_text(), fitted["profile"], header)
    parse_profile(tomllib.loads(text), source=str(out))  # what is written must load
    tmp = out.with_name(f".{out.name}.tmp")
    tmp.write_text(text)
    tmp.replace(out)
    report = {"port": redact(args.ptz), "profile": profile.name, "out": str(out), **fitted}
    if args.json:
        print(dumps(report))
    else:
        print(f"{profile.name} on {redact(args.ptz)}: command latency {1e3 * fitted['command_latency_s']:.1f} ms")
        for axis, unit in (("pan", "deg/s"), ("tilt", "deg/s"), ("zoom", "positions/s")):
            f = fitted[axis]
            print(f"  {axis:4s} {f['speed']:9.2f} {unit} at the sent speed code (moves: "
                  + ", ".join(f"{v:.2f}" for v in f["speeds"]) + f"), latency {1e3 * f['latency_s']:.1f} ms")
        for key, value in fitted["profile"].items():
            print(f"  {key} = {value:.4g}")
        print(f"wrote {out}")
    return 0


def run(args: argparse.Namespace) -> int:
    from runtime.cli._options import load_ptz_profile
    from runtime.errors import UsageError
    from runtime.output import dumps
    from runtime.ptz import PtzError
    from runtime.ptz.transports import required_protocol

    if args.ptz is None:
        raise UsageError("--ptz: expected the camera's URL (/dev/ttyUSB0, socket://host:port, visca-udp://host, ...)")
    profile = load_ptz_profile(args.ptz_profile, args.protocol or required_protocol(args.ptz))
    given = [v is not None for v in (args.pan_deg, args.tilt_deg, args.zoom)]
    if any(given) and not all(given):
        raise UsageError("--pan-deg, --tilt-deg, --zoom: give all three, or none to only ask the position")
    if all(given):
        # beyond these a value is no direction (more than a turn of pan, tilt past straight up or down)
        if not -360 <= args.pan_deg <= 360:
            raise UsageError(f"--pan-deg: expected degrees in [-360, 360] (one turn either way), got {args.pan_deg:g}")
        if not -90 <= args.tilt_deg <= 90:
            raise UsageError(f"--tilt-deg: expected degrees in [-90, 90] (straight down to straight up), "
                             f"got {args.tilt_deg:g}")
        if not args.zoom > 0:
            raise UsageError(f"--zoom: expected a zoom factor > 0, got {args.zoom:g}")
    if not args.wait > 0:
        raise UsageError(f"--wait: expected a positive number of seconds, got {args.wait}")

    shown = redact(args.ptz)  # a password in an onvif:// URL is never printed
    report: dict = {"port": shown, "profile": profile.name, "protocol": profile.protocol}
    driver = _connect(args, profile)
    if driver is None:
        return 1
    try:
        reached = True
        if all(given):
            t = driver.set_target(math.radians(args.pan_deg), math.radians(args.tilt_deg), args.zoom)
            reached = driver.wait_reached(args.wait)
            report["target"] = {"pan_deg": args.pan_deg, "tilt_deg": args.tilt_deg, "zoom": args.zoom,
                                "units": {"pan": t.pan, "tilt": t.tilt, "zoom": t.zoom}, "clamped": list(t.clamped)}
            report["reached"] = reached
        pos = driver.query_position()
    except (PtzError, TimeoutError) as exc:
        print(f"omnijax ptz: {shown}: {exc or 'no answer'}", file=sys.stderr)
        return 1
    finally:
        driver.disconnect()
    pan_u, tilt_u, zoom_u = pos.units
    report["position"] = {
        "pan_deg": pos.pan_deg, "tilt_deg": pos.tilt_deg, "zoom": pos.zoom,
        "device": {"pan_deg": pan_u / profile.pan.units_per_deg, "tilt_deg": tilt_u / profile.tilt.units_per_deg},
        "units": {"pan": pan_u, "tilt": tilt_u, "zoom": zoom_u},
    }
    report["ptz"] = driver.counters
    if args.json:
        print(dumps(report))
    else:
        p = report["position"]
        print(f"{profile.name} on {shown}: pan {p['pan_deg']:.2f} deg, tilt {p['tilt_deg']:.2f} deg, "
              f"zoom {p['zoom']:.2f}x (device: pan {p['device']['pan_deg']:.2f} deg, "
              f"tilt {p['device']['tilt_deg']:.2f} deg, units {pan_u} {tilt_u} {zoom_u})")
        if "target" in report:
            clamped = f", clamped to the device's limits on {', '.join(t.clamped)}" if t.clamped else ""
            print(f"target {'reached' if reached else 'NOT reached'} within {args.wait:g} s{clamped}")
    return 0 if reached else 1
