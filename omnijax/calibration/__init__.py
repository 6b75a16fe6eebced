"""Calibration kernels: the omni image's rim, and the rig (heights, distances, PTZ zeros) by least squares."""

from ._rig_fit import (
    GLOBAL_NAMES as GLOBAL_NAMES,
    PARAM_NAMES as PARAM_NAMES,
    PARAM_UNITS as PARAM_UNITS,
    RIM_NAMES as RIM_NAMES,
    CalibrationProblem as CalibrationProblem,
    Observations as Observations,
    RigFit as RigFit,
    RimPrior as RimPrior,
    SimulationSettings as SimulationSettings,
    draw_calibration_truth as draw_calibration_truth,
    fit_rig as fit_rig,
    simulate_calibration as simulate_calibration,
    with_mounting_sigma as with_mounting_sigma,
)
from ._rim import (
    RimEdges as RimEdges,
    RimFit as RimFit,
    fit_circle as fit_circle,
    fit_rim as fit_rim,
    rim_edges as rim_edges,
)
