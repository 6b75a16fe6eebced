"""Errors the command line turns into one line on stderr: bad input (exit 2) and interruption (exit 130).

:class:`UsageError` is bad command-line input that argparse cannot catch; a bad rig, scenario,
profile or observations file raises :class:`omnijax.config.ConfigError` (or a subclass).

:class:`Interrupted` is Ctrl-C or SIGTERM. The command line installs :func:`interrupt_handlers`
before anything else, so that either signal, whenever it comes, unwinds the command like an
exception: staged outputs are removed, child processes are stopped by their context managers,
and the command exits with 130 and one line saying what was interrupted. The real-time loop
replaces these handlers from when it runs until its outputs are staged: a signal then ends the loop
and everything is written (exit 0); a second one cuts the writing short but keeps what was recorded
(exit 130, ``Interrupted.kept``).
"""

from __future__ import annotations

import contextlib
import gc
import os
import signal
import threading
from collections.abc import Iterator

#: The signals that interrupt a command.
SIGNALS = (signal.SIGINT, signal.SIGTERM)


class UsageError(ValueError):
    """Bad command-line input that argparse cannot catch (one-line message, exit 2)."""


class Interrupted(KeyboardInterrupt):
    """Ctrl-C or SIGTERM arrived (exit 130). ``during`` says what was going on ("during start-up"),
    ``unwritten`` the output folder that was not written, ``written`` that the outputs were complete,
    ``kept`` the output folder that holds what was recorded though writing it was cut short (a real-time
    run's second signal); the code unwinding through it fills them in."""

    def __init__(self, signame: str = "SIGINT"):
        super().__init__(signame)
        self.signame = signame
        self.during: str | None = None
        self.unwritten: str | None = None
        self.written = False  # it arrived while outputs were moved into place, which was finished first
        self.kept: str | None = None

    def describe(self) -> str:
        """``interrupted by SIGTERM during start-up; nothing written to DIR``."""
        text = f"interrupted by {self.signame}" + (f" {self.during}" if self.during else "")
        if self.kept:
            return text + f"; what was recorded is in {self.kept}, the rest cut short (summary.json finish_cut_short)"
        return text + (f"; nothing written to {self.unwritten}" if self.unwritten else "")


_held: list[str] | None = None


def _interrupt(signum: int, frame) -> None:
    name = signal.Signals(signum).name
    if _held is not None:
        _held.append(name)
        return
    if _swallows(frame):
        # an exception raised here would be printed and dropped ("Exception ignored in ...") and the
        # command would run on: the signal comes again in a moment, in code that unwinds
        threading.Timer(0.05, os.kill, (os.getpid(), signum)).start()
        return
    raise Interrupted(name)


#: True while the garbage collector runs (between its "start" and "stop" callbacks), while
#: :func:`interrupt_handlers` are in place: whatever Python code it runs meanwhile (a weakref's
#: callback, a finaliser) drops exceptions.
_collecting = False


def _collector_phase(phase: str, info) -> None:
    global _collecting
    _collecting = phase == "start"


def _swallows(frame) -> bool:
    """Whether the code ``frame`` runs in drops exceptions: anything the garbage collector runs (its
    callbacks, JAX has one: a SIGTERM that landed in it let ``omnijax render`` run to the end and write
    its outputs; the weakref callbacks of the garbage it frees: a WeakKeyDictionary's removal dropped
    one in the test suite) or a ``__del__``."""
    if _collecting:
        return True
    callbacks = {getattr(cb, "__code__", None) for cb in gc.callbacks}
    while frame is not None:
        if frame.f_code in callbacks or frame.f_code.co_name == "__del__":
            return True
        frame = frame.f_back
    return False


@contextlib.contextmanager
def interrupt_handlers() -> Iterator[None]:
    """Ctrl-C and SIGTERM raise :class:`Interrupted` in the main thread while the block runs (then the
    previous handlers are back). Elsewhere than in the main thread, nothing changes."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    old = {sig: signal.signal(sig, _interrupt) for sig in SIGNALS}
    ours = _collector_phase not in gc.callbacks  # an enclosing block's stays until that block ends
    if ours:
        gc.callbacks.insert(0, _collector_phase)  # first: "start" is seen before any other callback runs
    try:
        yield
    finally:
        for sig, handler in old.items():
            signal.signal(sig, handler)
        if ours:
            gc.callbacks.remove(_collector_phase)


@contextlib.contextmanager
def interrupted_during(what: str) -> Iterator[None]:
    """An :class:`Interrupted` raised in the block says it came ``what`` ("during start-up"), unless
    code inside said more precisely."""
    try:
        yield
    except Interrupted as exc:
        exc.during = exc.during or what
        raise


@contextlib.contextmanager
def interrupts_held() -> Iterator[None]:
    """Hold Ctrl-C and SIGTERM while the block runs (files being moved into place): one that arrives
    meanwhile raises :class:`Interrupted` when the block has finished. Only where
    :func:`interrupt_handlers` are in place; otherwise nothing changes."""
    global _held
    ours = threading.current_thread() is threading.main_thread() and signal.getsignal(signal.SIGTERM) is _interrupt
    if not ours or _held is not None:
        yield
        return
    _held = []
    try:
        yield
    finally:
        got, _held = _held, None
    if got:
        raise Interrupted(got[0])
