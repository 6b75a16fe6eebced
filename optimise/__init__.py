"""Layout optimisation: where to put the PTZ camera (and the omni camera's height) for a room.

Objectives over the room's floor (``variance``: the pan and tilt variance of the
paper; ``face_px``: face pixels under the zoom rule), their optimistix search in
an unconstrained map of the configured box, the vmapped landscape grid that
checks it, and per-point arrays for the maps; for several PTZs, the objective over the floor of
the best camera and its multi-start search (``_cameras``). Imports ``omnijax`` only.
"""

from ._cameras import (
    CAMERA_VARIABLES as CAMERA_VARIABLES,
    EXHAUSTIVE_MAX as EXHAUSTIVE_MAX,
    CameraBox as CameraBox,
    Cameras as Cameras,
    CamerasResult as CamerasResult,
    CameraStart as CameraStart,
    best_camera as best_camera,
    camera_box as camera_box,
    camera_values as camera_values,
    cameras_objective as cameras_objective,
    framed as framed,
    kernel_rig as kernel_rig,
    stack as stack,
    summarise_cameras as summarise_cameras,
    wall_reach as wall_reach,
)
from ._floor import (
    PAD_TO as PAD_TO,
    FloorGrid as FloorGrid,
    floor_grid as floor_grid,
)
from ._objective import (
    OBJECTIVES as OBJECTIVES,
    SENSE as SENSE,
    STATISTICS as STATISTICS,
    FloorValues as FloorValues,
    Layout as Layout,
    configured_layout as configured_layout,
    floor_statistic as floor_statistic,
    floor_values as floor_values,
    layout_objective as layout_objective,
    place as place,
    power_mean as power_mean,
    summarise as summarise,
)
from ._search import (
    BATCH as BATCH,
    BOUND_TOL as BOUND_TOL,
    SHARPNESS as SHARPNESS,
    Box as Box,
    Evaluator as Evaluator,
    Landscape as Landscape,
    SearchResult as SearchResult,
    StartResult as StartResult,
    compile_minimiser as compile_minimiser,
    landscape_layouts as landscape_layouts,
    search as search,
    search_box as search_box,
    start_points as start_points,
)
