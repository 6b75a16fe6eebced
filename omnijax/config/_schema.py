"""What every file schema shares: the strict section base, common field types, the one-line error.

Rig files, scenario files, PTZ device profiles and calibration observations are all
validated by pydantic models built on :class:`Section` (unknown keys are errors,
values are not coerced, ``inf`` and ``nan`` are refused, a parsed section cannot
change), and every validation failure becomes one line,
``SOURCE: dotted.key: what was expected (got VALUE)``, through :func:`one_line_error`
(or :func:`validate`, which raises it).

The field types below bound what a file may say in each unit (docs/design.md
section 7.5): a length is at most :data:`MAX_LENGTH_M`, an image side at most
:data:`MAX_IMAGE_SIDE_PX`, a pixel radius at most :data:`MAX_PIXELS`, an angle
within one turn either way. Beyond them a number is not a room, a camera or a
direction, and squares and products of it (variances) would overflow or lose
every digit; the rig's cross-checks (``omnijax.config``) say what is impossible
in the geometry itself.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Annotated, Any, TypeVar

import pydantic
from pydantic import AfterValidator, BaseModel, ConfigDict, Field


class ConfigError(ValueError):
    """A rig or scenario file that does not describe a usable set-up (one-line message)."""


class Section(BaseModel):
    """Base of every schema section: unknown keys are errors, no coercion, only finite numbers
    (``inf`` and ``nan`` are refused everywhere), immutable once parsed."""

    model_config = ConfigDict(extra="forbid", frozen=True, strict=True, allow_inf_nan=False)


#: A number > 0, and a number >= 0 (finite, like every number of a :class:`Section`).
Pos = Annotated[float, Field(gt=0)]
NonNeg = Annotated[float, Field(ge=0)]

#: Largest length (m) a file may give: more than any building a rig stands in.
MAX_LENGTH_M = 1000.0
#: Largest side of an image (px): more than any camera sensor.
MAX_IMAGE_SIDE_PX = 32768
#: Largest image radius or pixel sigma (px): beyond the diagonal of the largest image.
MAX_PIXELS = 100_000.0


def within(low: float | int, high: float | int, unit: str, *, open_low: bool = False, why: str = "") -> AfterValidator:
    """A bound as a field's validator: ``low <= x <= high`` (``low < x`` if ``open_low``), failing
    with ``expected UNIT in [low, high] (WHY), got X``."""
    bracket = "(" if open_low else "["
    note = f" ({why})" if why else ""

    def check(x: float | int) -> float | int:
        if not ((x > low) if open_low else (x >= low)) or not x <= high:
            raise ValueError(f"expected {unit} in {bracket}{low:g}, {high:g}]{note}, got {x:g}")
        return x

    return AfterValidator(check)


_INDOOR = "an indoor rig"
#: Lengths (m) and their sigmas: >= 0, or > 0; and a floor coordinate (m).
Metres = Annotated[float, within(0.0, MAX_LENGTH_M, "metres", why=_INDOOR)]
PosMetres = Annotated[float, within(0.0, MAX_LENGTH_M, "metres", open_low=True, why=_INDOOR)]
Coordinate = Annotated[float, within(-MAX_LENGTH_M, MAX_LENGTH_M, "metres", why=_INDOOR)]
#: Image radii and pixel sigmas: > 0, or >= 0.
Pixels = Annotated[float, within(0.0, MAX_PIXELS, "pixels", open_low=True, why="beyond any image")]
NonNegPixels = Annotated[float, within(0.0, MAX_PIXELS, "pixels", why="beyond any image")]
#: An image side in pixels.
Side = Annotated[int, within(1, MAX_IMAGE_SIDE_PX, "pixels", why="larger than any camera sensor")]
#: An angle (deg) within one turn either way, and an angle's sigma (deg): above 180 it says nothing.
Degrees = Annotated[float, within(-360.0, 360.0, "degrees", why="one turn either way")]
SigmaDegrees = Annotated[float, within(0.0, 180.0, "degrees", why="a sigma above 180 deg says nothing of a direction")]
PosSigmaDegrees = Annotated[float, within(0.0, 180.0, "degrees", open_low=True,
                                          why="a sigma above 180 deg says nothing of a direction")]

_HIDDEN_INPUT = ("missing", "extra_forbidden", "value_error")


def _structure(value: Any) -> bool:
    """A table, or a list of tables: too big to echo in a one-line message."""
    return isinstance(value, dict) or (isinstance(value, list) and any(isinstance(v, dict) for v in value))


def one_line_error(exc: pydantic.ValidationError, source: str, rename: Mapping[str, str] | None = None) -> str:
    """The first error of ``exc`` as one line: ``SOURCE: dotted.key: what was expected (got VALUE)``.

    The offending value is shown where it helps (a wrong number or type), not for a
    missing or unknown key, a validator's own sentence, or a whole table. ``rename`` names a
    top-level key as the file spells it (``{"foveal": "foveal.1"}``: the second ``[[foveal]]`` table).
    """
    err = exc.errors()[0]
    parts = [str(p) for p in err["loc"]]
    if parts and rename and parts[0] in rename:
        parts[0] = rename[parts[0]]
    loc = ".".join(parts)
    msg = {"missing": "missing key", "extra_forbidden": "unknown key"}.get(
        err["type"], err["msg"].removeprefix("Value error, ")
    )
    value = err.get("input")
    shown = err["type"] not in _HIDDEN_INPUT and not _structure(value)
    if not loc and err["type"] == "value_error":  # a check across sections: its sentence names the keys
        return f"{source}: {msg}"
    return f"{source}: {loc or '(top level)'}: {msg}" + (f" (got {value!r})" if shown else "")


M = TypeVar("M", bound=BaseModel)


def validate(model: type[M], data: Any, source: str, error: type[Exception] = ConfigError,
             context: Mapping[str, Any] | None = None, rename: Mapping[str, str] | None = None) -> M:
    """``model`` validated from ``data`` (a parsed file); failing, raises ``error`` with the one line.

    ``context`` is pydantic's validation context (validators that name keys read it); ``rename`` as in
    :func:`one_line_error`."""
    try:
        return model.model_validate(dict(data) if isinstance(data, Mapping) else data, context=context)
    except pydantic.ValidationError as exc:
        raise error(one_line_error(exc, source, rename)) from None
