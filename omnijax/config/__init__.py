"""Typed rig configuration: the TOML schema, validated once at the edge, and the PyTrees kernels take."""

from ._config import (
    INPUT_NAMES as INPUT_NAMES,
    INPUT_UNITS as INPUT_UNITS,
    LAYOUT_NAMES as LAYOUT_NAMES,
    ConfigError as ConfigError,
    Detection as Detection,
    Foveal as Foveal,
    LayoutSearch as LayoutSearch,
    Lens as Lens,
    Person as Person,
    Rig as Rig,
    Room as Room,
    Sigmas as Sigmas,
    parse_rig as parse_rig,
)
