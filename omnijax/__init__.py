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

from ._lazy import lazy_exports

# each public name, by the subpackage that defines it: imported when first read (omnijax._lazy)
__getattr__, __dir__, __all__ = lazy_exports(__name__, {
    "aiming": ("Aim", "aim", "aim_at_floor", "aim_detection", "aim_from_image", "aim_with_covariance",
        "detection_sigmas", "floor_from_detections", "height_coupling"),
    "calibration": ("GLOBAL_NAMES", "PARAM_NAMES", "PARAM_UNITS", "RIM_NAMES", "CalibrationProblem",
        "Observations", "RigFit", "RimEdges", "RimFit", "RimPrior", "SimulationSettings",
        "draw_calibration_truth", "fit_circle", "fit_rig", "fit_rim", "rim_edges", "simulate_calibration",
        "with_mounting_sigma"),
    "camera": ("PROFILES", "Equidistant", "Equisolid", "OCamCalib", "OCamCalibFile", "OmniCamera",
        "Paraboloid", "RadialProfile", "parse_ocamcalib"),
    "config": ("INPUT_NAMES", "INPUT_UNITS", "LAYOUT_NAMES", "MAX_PTZS", "PTZ", "ConfigError", "Detection",
        "Foveal", "LayoutSearch", "Lens", "Person", "Rig", "Room", "Sigmas", "parse_rig"),
    "detection": ("MEASURES", "Background", "Detections", "DetectionTrace", "Detector", "FootSigmaTable",
        "LineBackground", "PolarIndex", "Sectors", "Thresholds", "adapt_background", "build_detector",
        "build_polar_index", "change_image", "change_measure", "chromaticity", "chromaticity_covariance",
        "detect", "estimate_sensor_noise", "foot_scores", "foot_sigma_mc", "grey_change_measure",
        "hysteresis_sectors", "learn_background", "line_background", "live_step", "polar_range", "start_life"),
    "geometry": ("D_P_MIN", "PHI_FLOOR_MAX", "Pointing", "floor_radius", "foveal_offsets", "head_image_radius",
        "image_to_floor", "person_image_extent", "point_image_radius", "pointing", "world_to_image"),
    "uncertainty": ("METHODS", "OUTPUT_NAMES", "MonteCarloCovariance", "PointingCovariance",
        "gum_second_order", "pointing_covariance", "pointing_covariance_full", "pointing_covariance_mc",
        "pointing_outputs"),
    "zoom": ("ZOOM_RULES", "ZoomChoice", "choose_zoom", "containment_probability", "face_pixels",
        "head_half_size", "paper_fov", "rectangle_probability"),
})
