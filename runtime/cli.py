"""The ``omnijax`` command line: one subcommand per job, each in ``runtime/commands/``.

Exit codes: 0 success, 2 bad input (one line on stderr naming what was wrong and
what was expected), 130 interrupted.
"""

from __future__ import annotations

import argparse
import importlib
import sys

#: Subcommands, in the order ``--help`` lists them; each is ``runtime.commands.<name>``.
COMMANDS: tuple[str, ...] = ("demo", "run", "variance", "validate", "render", "detect", "bench", "optimise", "calibrate",
                            "ptz", "ptz-emulator")

DESCRIPTION = """\
Dual-camera surveillance (Greiffenhagen et al., CVPR 2000) in JAX: an
omnidirectional camera finds people, a PTZ camera is steered onto each head,
and every uncertainty is propagated so that the zoom is the largest that still
keeps the head in frame with probability p_contain.

Rig files are TOML (see configs/paper.toml for every key, with units).
"""


class UsageError(ValueError):
    """Bad command-line input that argparse cannot catch (one-line message, exit 2)."""


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="omnijax", description=DESCRIPTION, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for name in COMMANDS:
        importlib.import_module(f"runtime.commands.{name.replace('-', '_')}").add_parser(sub)
    return parser


def _is_input_error(exc: Exception) -> bool:
    """UsageError or omnijax.ConfigError; omnijax (and jax) is not imported for commands that never load it."""
    config = sys.modules.get("omnijax._config")
    return isinstance(exc, UsageError) or (config is not None and isinstance(exc, config.ConfigError))


def main(argv: list[str] | None = None) -> int:
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


if __name__ == "__main__":
    # `python -m runtime.cli` runs this file as __main__: use the package's module, so that
    # runtime.cli.UsageError raised by the commands is the class main() catches.
    from runtime.cli import main as _main

    sys.exit(_main())
