"""Layout optimisation: where to put the PTZ camera (and the omni camera's height) for a room.

Objectives over the room's floor (``variance``: the pan and tilt variance of the
paper; ``face_px``: face pixels under the zoom rule), their optimistix search in
an unconstrained map of the configured box, the vmapped landscape grid that
checks it, and per-point arrays for the maps. Imports ``omnijax`` only.
"""

from ._floor import PAD_TO, FloorGrid, floor_grid
from ._objective import (
    OBJECTIVES,
    SENSE,
    STATISTICS,
    FloorValues,
    Layout,
    configured_layout,
    floor_statistic,
    floor_values,
    layout_objective,
    place,
    summarise,
)
from ._search import (
    BATCH,
    BOUND_TOL,
    SHARPNESS,
    Box,
    Evaluator,
    Landscape,
    SearchResult,
    StartResult,
    compile_minimiser,
    landscape_layouts,
    search,
    search_box,
    start_points,
)

__all__ = [n for n in dir() if not n.startswith("_")]
