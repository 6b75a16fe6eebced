"""Typed rig configuration: the TOML schema, validated once at the edge, and the PyTrees kernels take.

``Section``, ``validate`` and ``one_line_error`` are the schema kit every file format of
omnijax uses (rig, scenario, PTZ profile, calibration observations), with the bounded field
types (``Metres``, ``Coordinate``, ``Degrees``, ``within`` ...) that say what a number can be.
"""

from .._lazy import lazy_exports

# each public name, by the subpackage that defines it: imported when first read (omnijax._lazy)
__getattr__, __dir__, __all__ = lazy_exports(__name__, {
    "_config": ("INPUT_NAMES", "INPUT_UNITS", "LANDSCAPE_MAX", "LAYOUT_NAMES", "MAX_PTZS", "PTZ", "Detection",
        "Foveal", "LayoutSearch", "Lens", "Person", "Rig", "Room", "Sigmas", "parse_rig", "stack_ptzs",
        "with_ptz_count"),
    "_schema": ("MAX_LENGTH_M", "ConfigError", "Coordinate", "Degrees", "Metres", "NonNeg", "Pos", "PosMetres",
        "Section", "one_line_error", "validate", "within"),
    "_zones": ("ZONE_KINDS", "Zone", "parse_zones", "polygon_contains", "zone_mask"),
})
