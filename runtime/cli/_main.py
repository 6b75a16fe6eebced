"""The ``omnijax`` command line: one subcommand per job, each a module of ``runtime/cli/``.

Exit codes: 0 success (a real-time run stopped by Ctrl-C or SIGTERM included), 2 bad
input (one line on stderr naming what was wrong and what was expected), 130 interrupted
(Ctrl-C or SIGTERM; one line), 141 the reader of stdout went away (quietly).
"""

from __future__ import annotations

import argparse
import contextlib
import importlib
import logging
import os
import sys
from collections.abc import Iterator

from runtime.errors import Interrupted, UsageError, interrupt_handlers

#: Subcommands, in the order ``--help`` lists them; each is ``runtime.cli.<name>``.
COMMANDS: tuple[str, ...] = (
    "demo", "run", "variance", "validate", "render", "detect", "bench", "optimise", "plan", "calibrate", "ptz",
    "ptz-emulator",
)

DESCRIPTION = """\
Dual-camera surveillance (Greiffenhagen et al., CVPR 2000) in JAX: an
omnidirectional camera finds people, a PTZ camera is steered onto each head,
and every uncertainty is propagated so that the zoom is the largest that still
keeps the head in frame with probability p_contain.

Rig files are TOML (see configs/paper.toml for every key, with units).

Exit codes: 0 done; 2 bad input (a config, file, flag or port), with one line on
stderr naming what was wrong, found before any work and leaving nothing behind;
130 interrupted (Ctrl-C or SIGTERM, at any moment; nothing half-written), except
that a running `run` or `demo` is stopped by them: the PTZ goes home, everything
is written, exit 0 (a second one while it writes keeps what was recorded, 130);
141 the reader of stdout went away (omnijax ... | head -1: ends quietly).
"""


class _Parser(argparse.ArgumentParser):
    """argparse's parser, whose errors are one line like every other bad input (not the usage block)."""

    def error(self, message: str):
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(
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


class _Lines(logging.Handler):
    """Log records as one line like the command's other messages, ``omnijax run: warning: ...``, on stderr."""

    def __init__(self, command: str) -> None:
        super().__init__(logging.WARNING)
        self.command = command

    def emit(self, record: logging.LogRecord) -> None:
        try:
            sys.stderr.write(f"{self.command}: {record.levelname.lower()}: {record.getMessage()}\n")
        except Exception:
            self.handleError(record)


@contextlib.contextmanager
def log_lines(command: str) -> Iterator[None]:
    """Warnings of omnijax and of the libraries under it are printed as ``COMMAND: warning: ...`` while the
    block runs: the root logger gets this handler (where nothing else configured it, i.e. not under a host
    such as pytest), so that a library's own ``logging.basicConfig`` (onvif-zeep-async calls it on import)
    adds no raw ``WARNING:name:`` handler."""
    root = logging.getLogger()
    if root.handlers:
        yield
        return
    handler, level = _Lines(command), root.level
    root.addHandler(handler)
    root.setLevel(logging.WARNING)
    try:
        yield
    finally:
        root.removeHandler(handler)
        root.setLevel(level)


def enable_float64() -> None:
    """JAX in float64 from here on (see :func:`main`)."""
    if "jax" in sys.modules:
        sys.modules["jax"].config.update("jax_enable_x64", True)
    else:
        os.environ["JAX_ENABLE_X64"] = "1"


def main(argv: list[str] | None = None) -> int:
    """Run one ``omnijax`` command; returns its exit code.

    Ctrl-C and SIGTERM interrupt the command from the first moment (:func:`runtime.errors.interrupt_handlers`;
    exit code 130, one line). The output folder (``--out``) is checked before any work
    (:func:`runtime.output.check_output`), so that a job never runs to find it cannot write.

    Switches JAX to float64 first (geometry, uncertainty and Monte Carlo are meant to run in it;
    per-pixel kernels ask for float32 explicitly): the one place the command sets it. Through the
    environment while JAX is not imported yet, so that commands that never use it stay quick.
    """
    with interrupt_handlers():
        command, args = "omnijax", None
        try:
            enable_float64()
            try:
                args = build_parser().parse_args(argv)
            except SystemExit as exc:  # --help (0) or a flag argparse refused (2, one line printed)
                return exc.code if isinstance(exc.code, int) else 2
            command = f"omnijax {args.command}"
            if getattr(args, "out", None) is not None:
                from runtime.output import check_output

                check_output(args.out)
            with log_lines(command):
                return int(args.func(args) or 0)
        except Exception as exc:
            if not _is_input_error(exc):
                raise
            print(f"{command}: error: {exc}", file=sys.stderr)
            return 2
        except KeyboardInterrupt as exc:
            if (isinstance(exc, Interrupted) and exc.unwritten is None and not exc.written and exc.kept is None
                    and args is not None):
                exc.unwritten = getattr(args, "out", None)  # interrupted before its outputs were staged
            what = exc.describe() if isinstance(exc, Interrupted) else "interrupted"
            print(f"{command}: {what}", file=sys.stderr)
            return 130


#: Exit code when the reader of stdout went away (a closed pipe): 128 + SIGPIPE, as the shell reports it.
EXIT_PIPE = 141


def console() -> None:
    """The ``omnijax`` executable (and ``python -m runtime.cli``): :func:`main`, then exit with its code.

    A reader that goes away (``omnijax variance ... --json | head -1``) ends the command quietly, with
    :data:`EXIT_PIPE` and no traceback.

    After Ctrl-C or SIGTERM (exit code 130) the process ends at once, once :func:`main` has cleaned
    up (staged outputs removed, child processes stopped): JAX may still be compiling on its own
    threads, and the interpreter's normal shutdown underneath them can crash (SIGSEGV).
    """
    try:
        code = main()
        sys.stdout.flush()
    except BrokenPipeError:  # the reader went away (omnijax ... | head -1): end quietly, as SIGPIPE would
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())  # nothing left for the exit's flush
        code = EXIT_PIPE
    if code == 130:
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(130)
    sys.exit(code)
