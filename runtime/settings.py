"""Settings written once, as dataclass fields, and turned into command-line options (as lerobot does).

A field made by :func:`setting` carries what a flag needs: its help, the unit (the
noun used in help and messages, "seconds"), a metavar, the allowed names, bounds.
:func:`add_options` adds one option per such field (``--max-seconds`` for
``max_seconds``, or the field's ``flag``), :func:`from_args` builds the dataclass
from parsed options and :func:`check` checks any instance against the same
metadata, so that a bound is written in one place and its message names the flag
on the command line (``--dwell: expected seconds >= 0, got -1``) and the field in code.

Allowed names are given where they are defined, as :class:`Names` ("module:NAME"),
and imported only when an option is used or its help is printed: building the
parser stays free of JAX.
"""

from __future__ import annotations

import argparse
import dataclasses
import importlib
import math
import typing
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

from runtime.errors import UsageError


class Names(Sequence[str]):
    """The names defined at ``ref`` ("package.module:NAME", a tuple of str), imported on first use."""

    def __init__(self, ref: str):
        self.ref = ref
        self._names: tuple[str, ...] | None = None

    def _resolve(self) -> tuple[str, ...]:
        if self._names is None:
            module, name = self.ref.split(":")
            self._names = tuple(getattr(importlib.import_module(module), name))
        return self._names

    def __getitem__(self, i):
        return self._resolve()[i]

    def __len__(self) -> int:
        return len(self._resolve())

    def __repr__(self) -> str:
        return repr(self._resolve())


@dataclass(frozen=True)
class Option:
    """What turns a dataclass field into a command-line option (see :func:`setting`)."""

    help: str
    unit: str | None = None
    metavar: str | None = None
    choices: Sequence[str] | None = None
    ge: float | None = None
    gt: float | None = None
    flag: str | None = None


def finite_float(text: str) -> float:
    """The argparse type of every number flag: a finite float (``nan``, ``inf`` and non-numbers are
    refused with ``argument --FLAG: expected a finite number, got 'nan'``, exit code 2)."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"expected a finite number, got {text!r}")
    return value


def setting(default: Any, help: str, *, unit: str | None = None, metavar: str | None = None,
            choices: Sequence[str] | None = None, ge: float | None = None, gt: float | None = None,
            flag: str | None = None) -> Any:
    """A dataclass field that is also a command-line option.

    ``unit`` names the value in help and messages ("seconds"); ``ge``/``gt`` bound it
    (``None`` is always allowed: "not set"); ``choices`` are the allowed names (``help``
    may show them as ``%(choices)s``); ``flag`` replaces the flag made from the field's name.
    """
    option = Option(help=help, unit=unit, metavar=metavar, choices=choices, ge=ge, gt=gt, flag=flag)
    return dataclasses.field(default=default, metadata={"option": option})


def _options(cls) -> list[tuple[dataclasses.Field, Option, type]]:
    hints = typing.get_type_hints(cls)
    out = []
    for f in dataclasses.fields(cls):
        option = f.metadata.get("option")
        if option is not None:
            kinds = [t for t in typing.get_args(hints[f.name]) if t is not type(None)] or [hints[f.name]]
            out.append((f, option, kinds[0]))
    return out


def flag_of(f: dataclasses.Field) -> str:
    """The command-line flag of a setting field."""
    return f.metadata["option"].flag or "--" + f.name.replace("_", "-")


def add_options(parser: argparse.ArgumentParser, cls) -> dict[str, argparse.Action]:
    """One option per :func:`setting` field of dataclass ``cls``, its default the field's; the
    options by field name."""
    actions = {}
    for f, opt, kind in _options(cls):
        if kind is bool:
            actions[f.name] = parser.add_argument(flag_of(f), dest=f.name, action="store_true", help=opt.help)
            continue
        text = opt.help
        if f.default is not None:
            text += f" (default {f.default:g})" if isinstance(f.default, float) else f" (default {f.default})"
        actions[f.name] = parser.add_argument(flag_of(f), dest=f.name, type=finite_float if kind is float else kind,
                                              default=f.default,
                                              choices=opt.choices, metavar=opt.metavar or f.name.upper(), help=text)
    return actions


def _problem(f: dataclasses.Field, opt: Option, value: Any) -> str | None:
    """What is wrong with ``value`` for the field, or ``None``."""
    if value is None or isinstance(value, bool):
        return None
    unit = opt.unit or "a number"
    if opt.choices is not None and value not in opt.choices:
        return f"expected one of {', '.join(opt.choices)}, got {value!r}"
    if opt.ge is not None and not value >= opt.ge:
        return f"expected {unit} >= {opt.ge:g}, got {value}"
    if opt.gt is not None and not value > opt.gt:
        return f"expected {unit} > {opt.gt:g}, got {value}"
    return None


def check(settings) -> None:
    """Raise ``ValueError`` naming the first field of ``settings`` outside its bounds or names."""
    for f, opt, _ in _options(type(settings)):
        problem = _problem(f, opt, getattr(settings, f.name))
        if problem:
            raise ValueError(f"{f.name}: {problem}")


def from_args(cls, args: argparse.Namespace, **other: Any):
    """``cls`` from the parsed options (and ``other`` fields); a value out of bounds is a
    :class:`UsageError` naming its flag."""
    values = {}
    for f, opt, _ in _options(cls):
        value = getattr(args, f.name)
        problem = _problem(f, opt, value)
        if problem:
            raise UsageError(f"{flag_of(f)}: {problem}")
        values[f.name] = value
    return cls(**values, **other)
