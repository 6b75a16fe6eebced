"""``omnijax ptz-emulator``: VISCA or Pelco-D on a pty, VISCA over IP on UDP, or ONVIF on HTTP (docs/ptz.md)."""

from __future__ import annotations

import argparse
import os
import signal
import sys
import threading
import time
from pathlib import Path

from runtime.errors import UsageError

HELP = "a VISCA or Pelco-D camera on a pty, VISCA over IP on UDP, or ONVIF on HTTP, for tests, demos and set-ups"
DESCRIPTION = """\
Open a pseudo-terminal (visca, pelco-d) or a UDP socket (visca-ip: VISCA over IP,
Sony's 8-byte header, bound to --listen HOST:PORT, default 127.0.0.1 and a free
port), print its address as the first line on stdout (the pty's path, or
udp://HOST:PORT; the driver's URL is then visca-udp://HOST:PORT), and
behave like a PTZ camera on it until killed (SIGTERM or Ctrl-C exit cleanly):
slew-rate-limited motion from the device profile, position inquiries, ACK and
completion replies, and error replies to bad packets (VISCA: message length,
syntax, buffer full, cancelled, no socket, not executable; Pelco-D ignores and
counts bad packets; an unknown VISCA command gets a syntax error 90 60 02 FF).
Over IP it also answers RESET (sequence number reset), a sequence number that
goes backwards with a sequence error (control reply 0F 01), a malformed datagram
with a message error (0F 02), and a repeated sequence number (a retry) with the
replies already given, without executing it twice. --latency-ms delays every
packet before the camera sees it (a camera's command latency, for `omnijax ptz
calibrate` to measure).

onvif: an ONVIF PTZ camera over HTTP on --listen (default 127.0.0.1 and a free
port); prints http://HOST:PORT/onvif/device_service (the driver's URL is then
onvif://HOST:PORT, or onvif://U:P@HOST:PORT). SOAP 1.2: device GetCapabilities,
GetServices, GetSystemDateAndTime; media GetProfiles (profile token profile_1);
PTZ GetConfigurationOptions, AbsoluteMove, RelativeMove, ContinuousMove, Stop,
GetStatus (position in the generic spaces, MoveStatus IDLE/MOVING),
GotoHomePosition. Without --user no WS-Security is required; with --user U
--password P every request but GetSystemDateAndTime needs a valid UsernameToken
(PasswordDigest or PasswordText). An unknown operation, a malformed body or a
wrong password gets a SOAP fault. --quirks imitates firmware faults:
no-move-status, always-moving, relative-only, continuous-only, no-position.

--state-file F keeps F updated (atomically) with a JSON object: pan_deg,
tilt_deg (the device's own angles), zoom (magnification), commands, errors,
and more (units, moving, geometry {pan_deg, tilt_deg} in omnijax's frame).
--link PATH keeps a symlink PATH pointing at the pty, so that a client can
reopen the same path after the emulator is restarted.
"""


def add_parser(sub: argparse._SubParsersAction) -> None:
    from runtime.cli._options import EMULATED, add_ptz_profile_option

    p = sub.add_parser("ptz-emulator", help=HELP, description=DESCRIPTION,
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--protocol", required=True, choices=EMULATED, metavar="NAME", help="%(choices)s")
    p.add_argument("--listen", metavar="HOST:PORT",
                   help="visca-ip, onvif: address to bind (default 127.0.0.1:0, a free port)")
    p.add_argument("--user", metavar="U", help="onvif: require a WS-Security UsernameToken of user U (with --password)")
    p.add_argument("--password", metavar="P", help="onvif: the password of --user")
    p.add_argument("--quirks", default="", metavar="LIST",
                   help="onvif: imitate firmware faults, comma-separated: no-move-status, always-moving, "
                        "relative-only, continuous-only, no-position")
    p.add_argument("--latency-ms", type=float, default=0.0, metavar="MS",
                   help="delay every received packet by MS before the camera sees it (default 0)")
    p.add_argument("--address", type=int, metavar="N",
                   help="camera address (VISCA: place on the chain, 1-7; Pelco-D: 1-255); default: the profile's")
    add_ptz_profile_option(p, "device profile: a TOML file or a name in configs/devices "
                              "(default: sony_evi_d70 for visca and visca-ip, pelco_d_dome for pelco-d, "
                              "onvif_ptz for onvif)")
    p.add_argument("--state-file", metavar="F", help="keep F updated with the camera's state (JSON)")
    p.add_argument("--link", metavar="PATH", help="keep a symlink PATH pointing at the pty (pty protocols)")
    p.add_argument("--faults", default="", metavar="SPEC",
                   help="inject faults per reply, e.g. 'garble=0.05,drop=0.01,noise=0.05,buffer_full=0.1'")
    p.add_argument("--seed", type=int, default=0, help="seed of the injected faults (default 0)")
    p.add_argument("--parent-pid", type=int, metavar="PID",
                   help="stop when process PID ends (the demo and the tests pass their own, so that an emulator "
                        "never outlives them)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from runtime.cli._options import load_ptz_profile
    from runtime.output import check_output_file
    from runtime.ptz import Faults, PtyEmulator, UdpEmulator
    from runtime.ptz.transports import EMULATED, NETWORK_EMULATED

    network = args.protocol in NETWORK_EMULATED
    onvif = args.protocol == "onvif"
    profile = load_ptz_profile(args.ptz_profile, EMULATED[args.protocol])
    parent_alive = _watch(args.parent_pid) if args.parent_pid is not None else None
    if args.listen is not None and not network:
        raise UsageError(f"--listen: only for --protocol visca-ip or onvif (a {args.protocol} emulator is on a pty)")
    if args.link is not None and network:
        raise UsageError(f"--link: only for the pty protocols (visca, pelco-d); {args.protocol} listens on --listen")
    if not onvif and (args.user is not None or args.password is not None or args.quirks):
        raise UsageError("--user, --password, --quirks: only for --protocol onvif")
    if onvif and (args.user is None) != (args.password is None):
        raise UsageError("--user, --password: give both (a camera with a user), or neither (no WS-Security)")
    if onvif and args.user is not None and (not args.user or ":" in args.user or "@" in args.user):
        raise UsageError(f"--user: expected a non-empty name without ':' or '@', got {args.user!r}")
    if onvif and (args.faults or args.address is not None):
        raise UsageError("--faults, --address: not for --protocol onvif (use --quirks for firmware faults)")
    if not (0 <= args.latency_ms <= 10_000):
        raise UsageError(f"--latency-ms: expected 0-10000 ms, got {args.latency_ms:g}")
    listen = _listen(args.listen) if network else None
    top = 7 if profile.protocol == "visca" else 255
    if args.address is not None and not 1 <= args.address <= top:
        raise UsageError(f"--address: expected 1-{top} for {args.protocol}, got {args.address}")
    try:
        faults = Faults.parse(args.faults)
    except ValueError as exc:
        raise UsageError(f"--faults: {exc}") from None
    for flag, value in (("--state-file", args.state_file), ("--link", args.link)):
        if value is not None:
            check_output_file(value, flag)
    if args.link is not None and Path(args.link).exists() and not Path(args.link).is_symlink():
        raise UsageError(f"--link: {args.link} exists and is not a symlink; expected a new path or an old link")

    if onvif:
        from runtime.ptz.onvif_emulator import OnvifEmulator, parse_quirks

        try:
            quirks = parse_quirks(args.quirks)
        except ValueError as exc:
            raise UsageError(f"--quirks: {exc}") from None
        try:
            emulator = OnvifEmulator(profile, *listen, user=args.user, password=args.password, quirks=quirks,
                                     state_file=args.state_file, latency_s=args.latency_ms / 1e3)
        except OSError as exc:
            raise UsageError(f"--listen: cannot bind {listen[0]}:{listen[1]} ({exc.strerror or exc})") from None
        where = emulator.url
    elif network:
        if args.address is not None and args.address != 1:
            raise UsageError(f"--address: VISCA over IP cameras answer as address 1, got {args.address}")
        try:
            emulator = UdpEmulator(profile, listen, state_file=args.state_file, faults=faults, seed=args.seed,
                                   latency_s=args.latency_ms / 1e3)
        except OSError as exc:
            raise UsageError(f"--listen: cannot bind {listen[0]}:{listen[1]} ({exc.strerror or exc})") from None
        where = emulator.url
    else:
        emulator = PtyEmulator(profile, args.address, state_file=args.state_file, link=args.link,
                               faults=faults, seed=args.seed, latency_s=args.latency_ms / 1e3)
        where = emulator.path
    try:
        for sig in (signal.SIGTERM, signal.SIGINT):
            signal.signal(sig, lambda *_: emulator.stop())
        if parent_alive is not None:
            _stop_when_gone(emulator, parent_alive)
        print(where, flush=True)
        print(f"omnijax ptz-emulator: {profile.name} ({args.protocol}, address {emulator.camera.address}) on "
              f"{where}" + (f", linked from {args.link}" if args.link else ""), file=sys.stderr, flush=True)
        emulator.serve()
    finally:
        emulator.close()
    return 0


def _listen(spec: str | None) -> tuple[str, int]:
    """``--listen HOST:PORT`` (``[v6]:PORT`` too); one line naming the flag if malformed."""
    if spec is None:
        return ("127.0.0.1", 0)
    host, sep, port = spec.rpartition(":")
    host = host.strip("[]")
    if not sep or not host or not port.isdigit() or not 0 <= int(port) <= 65535:
        raise UsageError(f"--listen: expected HOST:PORT with a port 0-65535, got {spec!r}")
    return host, int(port)


def _watch(pid: int):
    """A function telling whether process ``pid`` is still there (one-line error if it is not now).

    If ``pid`` is this process's parent, its end is seen as this process being re-parented
    (exact even while the dead parent is not yet reaped); otherwise as ``pid`` vanishing.
    Polling this works however the parent ended (SIGKILL included) and whichever of its
    threads started this process, where PR_SET_PDEATHSIG would follow the starting thread.
    """
    is_parent = os.getppid() == pid

    def alive() -> bool:
        if is_parent:
            return os.getppid() == pid
        try:
            os.kill(pid, 0)
        except ProcessLookupError:
            return False
        except PermissionError:
            pass
        return True

    if pid < 1 or not alive():
        raise UsageError(f"--parent-pid: no process {pid}")
    return alive


def _stop_when_gone(emulator, alive, every_s: float = 0.2) -> None:
    """Stop ``emulator`` (a watcher thread) as soon as ``alive()`` is false."""

    def watch() -> None:
        while not emulator.stopped:
            if not alive():
                emulator.stop()
                return
            time.sleep(every_s)

    threading.Thread(target=watch, name="parent-watch", daemon=True).start()
