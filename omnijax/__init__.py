"""omnijax: jitted JAX kernels of the dual-camera surveillance system (Greiffenhagen et al., CVPR 2000).

Pure functions of arrays and config PyTrees: camera models, chromaticity, the
pointing geometry, its uncertainty, the zoom, calibration (rim fit, rig fit), change
detection, and the synthetic world that renders omni and foveal frames with ground
truth. ``optimise`` and ``runtime``
import this package, never the reverse.

Importing omnijax enables JAX's float64 (geometry, uncertainty and Monte Carlo
compare at 1e-9); per-pixel kernels ask for float32 explicitly.
"""

import jax as _jax

_jax.config.update("jax_enable_x64", True)

from ._aim import Aim, aim, aim_with_covariance  # noqa: E402
from ._calibration import (  # noqa: E402
    GLOBAL_NAMES,
    PARAM_NAMES,
    PARAM_UNITS,
    RIM_NAMES,
    CalibrationProblem,
    Observations,
    RigFit,
    RimPrior,
    SimulationSettings,
    draw_calibration_truth,
    fit_rig,
    simulate_calibration,
    with_mounting_sigma,
)
from ._camera import (  # noqa: E402
    PROFILES,
    Equidistant,
    Equisolid,
    OCamCalib,
    OCamCalibFile,
    OmniCamera,
    Paraboloid,
    RadialProfile,
    parse_ocamcalib,
)
from ._change import (  # noqa: E402
    MEASURES,
    Background,
    adapt_background,
    change_image,
    change_measure,
    grey_change_measure,
    learn_background,
    sensor_noise,
)
from ._chroma import chromaticity, chromaticity_covariance  # noqa: E402
from ._config import (  # noqa: E402
    INPUT_NAMES,
    INPUT_UNITS,
    LAYOUT_NAMES,
    ConfigError,
    Detection,
    Foveal,
    LayoutSearch,
    Lens,
    Person,
    Rig,
    Room,
    Sigmas,
    parse_rig,
)
from ._detector import (  # noqa: E402
    DetectionTrace,
    Detections,
    Detector,
    LineBackground,
    build_detector,
    detect,
    line_background,
    sector_mask,
)
from ._foot import FootSigmaTable, foot_estimate, foot_scores, foot_sigma_mc  # noqa: E402
from ._geometry import (  # noqa: E402
    D_P_MIN,
    PHI_FLOOR_MAX,
    Pointing,
    floor_radius,
    foveal_offsets,
    head_image_radius,
    image_to_floor,
    person_image_extent,
    world_to_image,
    point_image_radius,
    pointing,
)
from ._indexing import Sectors, Thresholds, hysteresis_sectors, window_profile  # noqa: E402
from ._polar import PolarIndex, build_polar_index, polar_range  # noqa: E402
from ._rim import RimEdges, RimFit, fit_circle, fit_rim, rim_edges  # noqa: E402
from ._uncertainty import (  # noqa: E402
    METHODS,
    OUTPUT_NAMES,
    MonteCarloCovariance,
    PointingCovariance,
    gum_second_order,
    pointing_covariance,
    pointing_covariance_full,
    pointing_covariance_mc,
    pointing_outputs,
)
from ._foveal import HeadView, PTZView, foveal_head, head_in_view, ptz_view, render_foveal  # noqa: E402
from ._jpeg import jpeg  # noqa: E402
from ._noise import gaussian, key_from_seed  # noqa: E402
from ._people import People, Paths, draw_people, walk, walkable  # noqa: E402
from ._render import OmniBackground, omni_rays  # noqa: E402
from ._scenario import Scenario, parse_scenario, read_scenario_header  # noqa: E402
from ._sensor import effective_sigma, expose, quantise  # noqa: E402
from ._world import (  # noqa: E402
    Frame,
    FrameState,
    Scene,
    Truth,
    World,
    build_world,
    draw_true_rig,
    render_frame,
    render_frames,
    render_state,
)
from ._zoom import (  # noqa: E402
    ZoomChoice,
    choose_zoom,
    containment_probability,
    face_pixels,
    head_half_size,
    paper_fov,
    rectangle_probability,
)

__all__ = [n for n in dir() if not n.startswith("_")]
