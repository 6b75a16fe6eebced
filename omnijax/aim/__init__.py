"""The one aim pipeline: detections with their sigmas -> floor -> pointing -> covariance -> zoom."""

from ._aim import (
    Aim as Aim,
    aim as aim,
    aim_with_covariance as aim_with_covariance,
)
