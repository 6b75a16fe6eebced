"""Options several commands share, each written once, and old flag spellings kept as hidden aliases.

- the real-time loop's settings (:class:`runtime.realtime.config.LoopConfig`, turned into
  flags by :mod:`runtime.settings`) and the session's (faults, video, recording, cache), for
  ``run`` and ``demo``;
- the PTZ device profile (``--ptz-profile``) and its one loading path;
- :func:`deprecated_alias`: a flag renamed in this release still works, hidden from
  ``--help``, and says once on stderr what it is called now.

Nothing here imports JAX: building the parser stays quick.
"""

from __future__ import annotations

import argparse
import contextlib
import math
import sys

from runtime.errors import UsageError
from runtime.settings import Names

#: ``--pace``: frames at the source's rate (late ones dropped), or every frame as fast as possible.
PACES: tuple[str, ...] = ("live", "all")
#: Most frames of a synthetic scenario (``--frames`` of render, demo): 11 hours at 25 fps, the walks of
#: all frames being simulated up front.
MAX_FRAMES = 1_000_000
#: The PTZ protocols (``--protocol``) of the device profiles.
PROTOCOLS = Names("runtime.ptz.profile:PROTOCOLS")
#: The emulated cameras (``--protocol`` of ptz-emulator and demo): the profile protocols and the network ones.
EMULATED = Names("runtime.ptz.transports:EMULATED")


class _Deprecated(argparse.Action):
    """Stores like the option it stands for, after one line on stderr naming the new spelling."""

    def __init__(self, option_strings, dest, new: str, note: str = "", **kwargs):
        super().__init__(option_strings, dest, **kwargs)
        self.new, self.note = new, note

    def __call__(self, parser, namespace, values, option_string=None):
        print(f"{parser.prog}: {option_string} is deprecated, use {self.new}{self.note}", file=sys.stderr)
        setattr(namespace, self.dest, values)


def deprecated_alias(parser: argparse.ArgumentParser, old: str, new: argparse.Action, *,
                     dest: str | None = None, type=None, note: str = "") -> None:
    """Keep ``old`` working for one release as a hidden spelling of the option ``new``.

    ``dest`` and ``type`` replace the new option's where the old one meant something else
    (another unit); ``note`` is added to the deprecation line.
    """
    parser.add_argument(old, action=_Deprecated, new=new.option_strings[0], note=note, dest=dest or new.dest,
                        type=type or new.type, nargs=new.nargs, metavar=new.metavar, choices=new.choices,
                        default=argparse.SUPPRESS, help=argparse.SUPPRESS)


def scenario_file(spec: str):
    """``--scenario``: a scenario file or the name of one in configs/scenarios (one line naming the flag)."""
    from omnijax.config import ConfigError
    from runtime.files import scenario_path

    try:
        return scenario_path(spec)
    except ConfigError as exc:
        raise UsageError(f"--scenario: {exc}") from None


# --------------------------------------------------------------------------------------
# PTZ device profile
# --------------------------------------------------------------------------------------


def add_ptz_profile_option(parser: argparse.ArgumentParser, help: str, alias: bool = True) -> None:
    """``--ptz-profile P`` (a TOML file or a name in configs/devices), and ``--profile`` as its old spelling."""
    action = parser.add_argument("--ptz-profile", metavar="P", help=help)
    if alias:
        deprecated_alias(parser, "--profile", action)


def load_ptz_profile(name: str | None, protocol: str | None = None):
    """The device profile ``name`` (``--ptz-profile``), else the shipped one for ``protocol`` (visca if
    ``None``); a profile of another protocol than one asked for is refused. One line naming the flag."""
    from runtime.ptz import ProfileError, default_profile, load_profile

    try:
        profile = load_profile(name) if name else default_profile(protocol or "visca")
    except ProfileError as exc:
        raise UsageError(f"--ptz-profile: {exc}") from None
    if protocol is not None and profile.protocol != protocol:
        raise UsageError(f"--ptz-profile: {name} is a {profile.protocol} profile, not {protocol}")
    return profile


# --------------------------------------------------------------------------------------
# The real-time loop (run, demo) and the compilation cache (run, demo, optimise)
# --------------------------------------------------------------------------------------


def add_cache_options(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--cache-dir", metavar="DIR", default=None,
                        help="JAX compilation cache (default: $JAX_COMPILATION_CACHE_DIR if set, else "
                             "$XDG_CACHE_HOME/omnijax/xla or ~/.cache/omnijax/xla)")
    parser.add_argument("--no-cache", action="store_true", help="compile everything afresh, cache nothing")


def enable_cache(args) -> str | None:
    """Turn on JAX's persistent compilation cache (``--cache-dir``, unless ``--no-cache``); its path."""
    import os
    from pathlib import Path

    from runtime.compile_cache import use_cache

    if args.no_cache:
        return None
    base = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache")
    path = Path(args.cache_dir or os.environ.get("JAX_COMPILATION_CACHE_DIR") or base / "omnijax" / "xla")
    if args.cache_dir:  # a folder the user names must be usable; the default one is best effort (JAX warns)
        from runtime.errors import UsageError

        try:
            path.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise UsageError(f"--cache-dir: cannot create {path} ({exc.strerror}); expected a folder that can "
                             "be written, or --no-cache") from None
        if not os.access(path, os.W_OK | os.X_OK):
            raise UsageError(f"--cache-dir: {path} cannot be written; expected a writable folder, or --no-cache")
    use_cache(str(path))
    return str(path)


def add_background_options(parser: argparse.ArgumentParser) -> None:
    """The one learning rule's two settings (``detect``, ``run``, ``demo``): how many frames, over how long."""
    parser.add_argument("--background-frames", type=int, metavar="N",
                        help="frames the background is learnt from (default: the rig's [detection] "
                             "background_frames, 30)")
    parser.add_argument("--background-seconds", type=float, metavar="S",
                        help="spread over this many seconds of the source (default: the rig's [detection] "
                             "background_seconds, 10; 0 takes consecutive frames). Spread out, people who "
                             "stand still for less than half of it are not learnt")


def background_settings(args, rig) -> tuple[int, float]:
    """``(frames, seconds)`` of the learning from ``--background-frames`` / ``--background-seconds`` and
    the rig's defaults; exit 2 on values that cannot be."""
    n = args.background_frames if args.background_frames is not None else rig.detection.background_frames
    seconds = args.background_seconds if args.background_seconds is not None else rig.detection.background_seconds
    if n < 3:
        raise UsageError(f"--background-frames: expected at least 3, got {n}")
    if not (seconds >= 0 and math.isfinite(seconds)):
        raise UsageError(f"--background-seconds: expected seconds >= 0, got {seconds}")
    return n, float(seconds)


def add_loop_options(parser: argparse.ArgumentParser) -> None:
    """The loop's settings (every :func:`~runtime.settings.setting` of ``LoopConfig``) and the session's."""
    from runtime.realtime.config import LoopConfig
    from runtime.settings import add_options

    deprecated_alias(parser, "--dead-zone", add_options(parser, LoopConfig)["dead_zone_sd"])
    parser.add_argument("--faults", default="", metavar="SPEC",
                        help="inject faults, e.g. 'broken@300,wrong-size@350,end@900' (see --help of demo)")
    parser.add_argument("--no-video", action="store_true", help="do not draw or write the annotated video")
    parser.add_argument("--record", action="store_true",
                        help="also write the omni frames as processed to DIR/omni.avi (to replay with `omnijax run`)")
    parser.add_argument("--serve", metavar="HOST:PORT",
                        help="serve the operator's console (live view, controls, zones, events, calibration) on "
                             "HOST:PORT, e.g. 127.0.0.1:8080 (port 0: any free one); prints its address with the "
                             "token that changes need (docs/console.md)")
    parser.add_argument("--mqtt", metavar="URL",
                        help="also publish the events (person appeared, left, face captured) to an MQTT broker: "
                             "mqtt://[USER:PASSWORD@]HOST[:PORT][/PREFIX] (docs/console.md)")
    add_cache_options(parser)


def loop_config(args):
    """The :class:`LoopConfig` of the parsed flags (one line naming a flag out of bounds), after turning on
    the compilation cache (later starts compile less)."""
    from runtime.realtime.config import LoopConfig
    from runtime.settings import from_args

    config = from_args(LoopConfig, args)
    enable_cache(args)
    return config


def parse_faults(text: str, ptz_unplug: bool = True):
    """``--faults`` as a :class:`~runtime.realtime.faults.FaultPlan` (``ptz-unplug`` only with an emulated PTZ)."""
    from runtime.realtime.faults import FaultPlan

    try:
        plan = FaultPlan.parse(text)
    except ValueError as exc:
        raise UsageError(f"--faults: {exc}") from None
    if plan.ptz_unplug and not ptz_unplug:
        raise UsageError("--faults: ptz-unplug needs the emulated PTZ of `omnijax demo` (unplug a real one by hand)")
    return plan


@contextlib.contextmanager
def console_and_events(args, rig_path, profile_spec: str | None = None):
    """``--serve`` and ``--mqtt``: the operator's console (bound now, so that a bad address or a port in use
    is one line before any work; serving until the block ends) and the MQTT publisher (connecting in the
    background). Yields ``(console or None, publisher or None)``."""
    from runtime.events import MqttPublisher, parse_mqtt_url

    if args.mqtt:
        try:
            parse_mqtt_url(args.mqtt)
        except ValueError as exc:
            raise UsageError(f"--mqtt: {exc}") from None
    console = None
    if args.serve:
        from runtime.console import Console

        console = Console(args.serve, rig_path, profile_spec)
    with console if console is not None else contextlib.nullcontext():
        mqtt = MqttPublisher(args.mqtt).start() if args.mqtt else None
        try:
            yield console, mqtt
        finally:
            if mqtt is not None:
                mqtt.close()
