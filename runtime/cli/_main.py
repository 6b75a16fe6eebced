"""The ``omnijax`` command line: one subcommand per job, each a module of ``runtime/cli/``.

Exit codes: 0 success, 2 bad input (one line on stderr naming what was wrong and
what was expected), 130 interrupted.
"""

from __future__ import annotations

import argparse
import importlib
import os
import sys

from runtime.errors import UsageError

#: Subcommands, in the order ``--help`` lists them; each is ``runtime.cli.<name>``.
COMMANDS: tuple[str, ...] = (
    "demo", "run", "variance", "validate", "render", "detect", "bench", "optimise", "calibrate", "ptz", "ptz-emulator",
)

DESCRIPTION = """\
Dual-camera surveillance (Greiffenhagen et al., CVPR 2000) in JAX: an
omnidirectional camera finds people, a PTZ camera is steered onto each head,
and every uncertainty is propagated so that the zoom is the largest that still
keeps the head in frame with probability p_contain.

Rig files are TOML (see configs/paper.toml for every key, with units).
"""


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="omnijax", description=DESCRIPTION, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for name in COMMANDS:
        importlib.import_module(f"runtime.cli.{name.replace('-', '_')}").add_parser(sub)
    return parser


def _is_input_error(exc: Exception) -> bool:
    """UsageError or omnijax.ConfigError; omnijax (and jax) is not imported for commands that never load it."""
    config = sys.modules.get("omnijax.config")
    return isinstance(exc, UsageError) or (config is not None and isinstance(exc, config.ConfigError))


def enable_float64() -> None:
    """JAX in float64 from here on (see :func:`main`)."""
    if "jax" in sys.modules:
        sys.modules["jax"].config.update("jax_enable_x64", True)
    else:
        os.environ["JAX_ENABLE_X64"] = "1"


def main(argv: list[str] | None = None) -> int:
    """Run one ``omnijax`` command; returns its exit code.

    Switches JAX to float64 first (geometry, uncertainty and Monte Carlo are meant to run in it;
    per-pixel kernels ask for float32 explicitly): the one place the command sets it. Through the
    environment while JAX is not imported yet, so that commands that never use it stay quick.
    """
    enable_float64()
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except Exception as exc:
        if not _is_input_error(exc):
            raise
        print(f"omnijax {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"omnijax {args.command}: interrupted", file=sys.stderr)
        return 130

