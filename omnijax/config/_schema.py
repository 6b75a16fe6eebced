"""What every file schema shares: the strict section base, common field types, the one-line error.

Rig files, scenario files, PTZ device profiles and calibration observations are all
validated by pydantic models built on :class:`Section` (unknown keys are errors,
values are not coerced, a parsed section cannot change), and every validation
failure becomes one line, ``SOURCE: dotted.key: what was expected (got VALUE)``,
through :func:`one_line_error` (or :func:`validate`, which raises it).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Annotated, Any, TypeVar

import pydantic
from pydantic import BaseModel, ConfigDict, Field


class ConfigError(ValueError):
    """A rig or scenario file that does not describe a usable set-up (one-line message)."""


class Section(BaseModel):
    """Base of every schema section: unknown keys are errors, no coercion, immutable once parsed."""

    model_config = ConfigDict(extra="forbid", frozen=True, strict=True)


#: A number > 0, and a number >= 0.
Pos = Annotated[float, Field(gt=0)]
NonNeg = Annotated[float, Field(ge=0)]

_HIDDEN_INPUT = ("missing", "extra_forbidden", "value_error")


def _structure(value: Any) -> bool:
    """A table, or a list of tables: too big to echo in a one-line message."""
    return isinstance(value, dict) or (isinstance(value, list) and any(isinstance(v, dict) for v in value))


def one_line_error(exc: pydantic.ValidationError, source: str) -> str:
    """The first error of ``exc`` as one line: ``SOURCE: dotted.key: what was expected (got VALUE)``.

    The offending value is shown where it helps (a wrong number or type), not for a
    missing or unknown key, a validator's own sentence, or a whole table.
    """
    err = exc.errors()[0]
    loc = ".".join(str(p) for p in err["loc"])
    msg = {"missing": "missing key", "extra_forbidden": "unknown key"}.get(
        err["type"], err["msg"].removeprefix("Value error, ")
    )
    value = err.get("input")
    shown = err["type"] not in _HIDDEN_INPUT and not _structure(value)
    return f"{source}: {loc or '(top level)'}: {msg}" + (f" (got {value!r})" if shown else "")


M = TypeVar("M", bound=BaseModel)


def validate(model: type[M], data: Any, source: str, error: type[Exception] = ConfigError) -> M:
    """``model`` validated from ``data`` (a parsed file); failing, raises ``error`` with the one line."""
    try:
        return model.model_validate(dict(data) if isinstance(data, Mapping) else data)
    except pydantic.ValidationError as exc:
        raise error(one_line_error(exc, source)) from None
