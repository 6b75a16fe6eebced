"""The one aim pipeline: detections with their sigmas -> floor -> pointing -> covariance -> zoom."""

from ._aim import (
    Aim as Aim,
    aim as aim,
    aim_at_floor as aim_at_floor,
    aim_detection as aim_detection,
    aim_from_image as aim_from_image,
    aim_with_covariance as aim_with_covariance,
    detection_sigmas as detection_sigmas,
    floor_from_detections as floor_from_detections,
    height_coupling as height_coupling,
    input_covariance as input_covariance,
)
