"""Uncertainty of the PTZ pointing by four methods over the same inputs (eq 13-14, GUM)."""

from ._uncertainty import (
    METHODS as METHODS,
    OUTPUT_NAMES as OUTPUT_NAMES,
    PROPAGATION_METHODS as PROPAGATION_METHODS,
    MonteCarloCovariance as MonteCarloCovariance,
    PointingCovariance as PointingCovariance,
    gum_second_order as gum_second_order,
    pointing_covariance as pointing_covariance,
    pointing_covariance_full as pointing_covariance_full,
    pointing_covariance_mc as pointing_covariance_mc,
    pointing_outputs as pointing_outputs,
)
