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
"""


def add_parser(sub: argparse._SubParsersAction) -> None:
    from runtime.cli._options import PROTOCOLS, add_ptz_profile_option, deprecated_alias
    from runtime.settings import finite_float

    p = sub.add_parser("ptz", help=HELP, description=DESCRIPTION,
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    deprecated_alias(p, "--port", p.add_argument("--ptz", metavar="URL",
                                                   help="the camera: a pyserial URL of its serial line, or "
                                                        "visca-udp://HOST[:PORT] (required)"))
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


def run(args: argparse.Namespace) -> int:
    from runtime.cli._options import load_ptz_profile
    from runtime.errors import UsageError
    from runtime.output import dumps
    from runtime.ptz import PtzError, PtzPortError, make_driver
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
    if args.timeout is None:
        args.timeout = 30.0 if args.ptz.lower().startswith("onvif://") else 5.0
    for flag, value in (("--wait", args.wait), ("--timeout", args.timeout)):
        if not value > 0:
            raise UsageError(f"{flag}: expected a positive number of seconds, got {value}")

    from runtime.ptz.onvif import redact

    shown = redact(args.ptz)  # a password in an onvif:// URL is never printed
    report: dict = {"port": shown, "profile": profile.name, "protocol": profile.protocol}
    try:
        driver = make_driver(args.ptz, profile)
        driver.connect(timeout=args.timeout)
    except PtzPortError as exc:
        raise UsageError(f"--ptz: {exc}") from None
    except PtzError as exc:
        print(f"omnijax ptz: {exc}", file=sys.stderr)
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
