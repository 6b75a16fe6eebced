"""Typed rig configuration: the TOML schema, validated once at the edge, and the PyTrees kernels take.

``Section``, ``validate`` and ``one_line_error`` are the schema kit every file format of
omnijax uses (rig, scenario, PTZ profile, calibration observations), with the bounded field
types (``Metres``, ``Coordinate``, ``Degrees``, ``within`` ...) that say what a number can be.
"""

from ._config import (
    INPUT_NAMES as INPUT_NAMES,
    INPUT_UNITS as INPUT_UNITS,
    LANDSCAPE_MAX as LANDSCAPE_MAX,
    LAYOUT_NAMES as LAYOUT_NAMES,
    MAX_PTZS as MAX_PTZS,
    PTZ as PTZ,
    Detection as Detection,
    Foveal as Foveal,
    LayoutSearch as LayoutSearch,
    Lens as Lens,
    Person as Person,
    Rig as Rig,
    Room as Room,
    Sigmas as Sigmas,
    parse_rig as parse_rig,
    stack_ptzs as stack_ptzs,
    with_ptz_count as with_ptz_count,
)
from ._schema import (
    MAX_LENGTH_M as MAX_LENGTH_M,
    ConfigError as ConfigError,
    Coordinate as Coordinate,
    Degrees as Degrees,
    Metres as Metres,
    NonNeg as NonNeg,
    Pos as Pos,
    PosMetres as PosMetres,
    Section as Section,
    one_line_error as one_line_error,
    validate as validate,
    within as within,
)
from ._zones import (
    ZONE_KINDS as ZONE_KINDS,
    Zone as Zone,
    parse_zones as parse_zones,
    polygon_contains as polygon_contains,
    zone_mask as zone_mask,
)
