"""omnijax: the jitted JAX kernels of the dual-camera surveillance system (Greiffenhagen et al., CVPR 2000).

Pure functions of arrays and config PyTrees, one concept per subpackage:

- ``omnijax.config``: the rig's TOML schema and the :class:`Rig` PyTree every kernel takes;
- ``omnijax.camera``: omnidirectional camera models (paraboloid, fisheyes, OCamCalib), r <-> phi;
- ``omnijax.geometry``: eq 1-4, image radius -> floor -> pan/tilt, and floor <-> image conversions;
- ``omnijax.detection``: chromaticity, change measure, background and its life, polar indexing, the
  people and their feet (eq 5-12);
- ``omnijax.uncertainty``: the pointing covariance by four methods (eq 13-14, GUM);
- ``omnijax.zoom``: eq 15 and the calibrated zoom rule;
- ``omnijax.aiming``: the one aim pipeline, from detections to pan/tilt/zoom;
- ``omnijax.calibration``: the rim fit and the rig fit;
- ``omnijax.world``: the synthetic world (ground truth), imported by nothing else in ``omnijax``.

``optimise`` and ``runtime`` import this package, never the reverse.

Precision: geometry, uncertainty and Monte Carlo are meant to run in float64 (the tests compare at
1e-9); per-pixel kernels ask for float32 explicitly. Importing omnijax does not change JAX's global
configuration: the ``omnijax`` command, the benchmarks and the tests switch float64 on at their
start (``jax.config.update("jax_enable_x64", True)``); a program of your own should too
(docs/design.md section 3.3).
"""

from .aiming import (
    Aim as Aim,
    aim as aim,
    aim_at_floor as aim_at_floor,
    aim_detection as aim_detection,
    aim_from_image as aim_from_image,
    aim_with_covariance as aim_with_covariance,
    detection_sigmas as detection_sigmas,
    floor_from_detections as floor_from_detections,
)
from .calibration import (
    GLOBAL_NAMES as GLOBAL_NAMES,
    PARAM_NAMES as PARAM_NAMES,
    PARAM_UNITS as PARAM_UNITS,
    RIM_NAMES as RIM_NAMES,
    CalibrationProblem as CalibrationProblem,
    Observations as Observations,
    RigFit as RigFit,
    RimEdges as RimEdges,
    RimFit as RimFit,
    RimPrior as RimPrior,
    SimulationSettings as SimulationSettings,
    draw_calibration_truth as draw_calibration_truth,
    fit_circle as fit_circle,
    fit_rig as fit_rig,
    fit_rim as fit_rim,
    rim_edges as rim_edges,
    simulate_calibration as simulate_calibration,
    with_mounting_sigma as with_mounting_sigma,
)
from .camera import (
    PROFILES as PROFILES,
    Equidistant as Equidistant,
    Equisolid as Equisolid,
    OCamCalib as OCamCalib,
    OCamCalibFile as OCamCalibFile,
    OmniCamera as OmniCamera,
    Paraboloid as Paraboloid,
    RadialProfile as RadialProfile,
    parse_ocamcalib as parse_ocamcalib,
)
from .config import (
    INPUT_NAMES as INPUT_NAMES,
    INPUT_UNITS as INPUT_UNITS,
    LAYOUT_NAMES as LAYOUT_NAMES,
    MAX_PTZS as MAX_PTZS,
    PTZ as PTZ,
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
from .detection import (
    MEASURES as MEASURES,
    Background as Background,
    Detections as Detections,
    DetectionTrace as DetectionTrace,
    Detector as Detector,
    FootSigmaTable as FootSigmaTable,
    LineBackground as LineBackground,
    PolarIndex as PolarIndex,
    Sectors as Sectors,
    Thresholds as Thresholds,
    adapt_background as adapt_background,
    build_detector as build_detector,
    build_polar_index as build_polar_index,
    change_image as change_image,
    change_measure as change_measure,
    chromaticity as chromaticity,
    chromaticity_covariance as chromaticity_covariance,
    detect as detect,
    estimate_sensor_noise as estimate_sensor_noise,
    foot_scores as foot_scores,
    foot_sigma_mc as foot_sigma_mc,
    grey_change_measure as grey_change_measure,
    hysteresis_sectors as hysteresis_sectors,
    learn_background as learn_background,
    line_background as line_background,
    live_step as live_step,
    polar_range as polar_range,
    start_life as start_life,
)
from .geometry import (
    D_P_MIN as D_P_MIN,
    PHI_FLOOR_MAX as PHI_FLOOR_MAX,
    Pointing as Pointing,
    floor_radius as floor_radius,
    foveal_offsets as foveal_offsets,
    head_image_radius as head_image_radius,
    image_to_floor as image_to_floor,
    person_image_extent as person_image_extent,
    point_image_radius as point_image_radius,
    pointing as pointing,
    world_to_image as world_to_image,
)
from .uncertainty import (
    METHODS as METHODS,
    OUTPUT_NAMES as OUTPUT_NAMES,
    MonteCarloCovariance as MonteCarloCovariance,
    PointingCovariance as PointingCovariance,
    gum_second_order as gum_second_order,
    pointing_covariance as pointing_covariance,
    pointing_covariance_full as pointing_covariance_full,
    pointing_covariance_mc as pointing_covariance_mc,
    pointing_outputs as pointing_outputs,
)
from .zoom import (
    ZOOM_RULES as ZOOM_RULES,
    ZoomChoice as ZoomChoice,
    choose_zoom as choose_zoom,
    containment_probability as containment_probability,
    face_pixels as face_pixels,
    head_half_size as head_half_size,
    paper_fov as paper_fov,
    rectangle_probability as rectangle_probability,
)
